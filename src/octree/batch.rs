//! The batched update split over tasks (feature `parallel`): the placement lent to the tasks,
//! the records they store into, and the moves they note for the tree to take over.

use super::cell::level_of;
use super::lists::Deferred;
use super::placement::{self, Lattice};
use super::{MAX_DEPTH, NONE, Obj, Octree};
use glam::Vec3;

/// The batched update split over tasks.
impl Octree {
    /// The tree's placement (read-only) beside its spheres' records by id (a slot's id is its
    /// key's slot; the records end at the highest id ever held), for a batched update split
    /// over tasks by id range: each task places its spheres with [`Placer::placement_of`] and
    /// stores the moves with [`Record::store_placed`] (those to another node noted for
    /// [`Octree::take_moves`]); the others (a sphere entering or leaving the region or the
    /// root) go through [`Octree::update_live_deferred`] afterwards, on one thread.
    pub(crate) fn split_for_update(&mut self) -> (Placer<'_>, &mut [Record]) {
        let placer = Placer {
            lattice: &self.lattice,
            memo: placement::LevelMemo::EMPTY,
        };
        (placer, &mut self.objs)
    }
}

/// Places spheres in a tree whose records are lent out ([`Octree::split_for_update`]); each
/// task places with its own copy (which notes the last radius's level).
#[derive(Clone, Copy)]
pub(crate) struct Placer<'a> {
    lattice: &'a Lattice,
    memo: placement::LevelMemo,
}

impl Placer<'_> {
    /// Where a sphere at `center`, `radius` goes in the tree as it is now.
    #[inline(always)]
    pub(crate) fn placement_of(&mut self, center: Vec3, radius: f32) -> Placed {
        Placed(self.lattice.locate_memo(center, radius, &mut self.memo))
    }
}

/// What the tasks of a batched update noted of the spheres they moved to another node (see
/// [`Record::store_placed`]), for [`Octree::take_moves`]: one per task, reused.
#[derive(Clone, Debug, Default)]
pub(crate) struct Moves {
    deferred: Vec<Deferred>,
    per_level: [i32; MAX_DEPTH as usize + 1],
}

impl Moves {
    pub(crate) fn heap_bytes(&self) -> usize {
        self.deferred.capacity() * core::mem::size_of::<Deferred>()
    }
}

impl Octree {
    /// Takes over the moves the tasks of a batched update noted (each task's spheres in id
    /// order, the tasks in id order): their lists catch up like those of
    /// [`Octree::update_live_deferred`], in id order as one serial walk over the slots would
    /// list them, and the level counts follow at once. Leaves every `Moves` empty, its room
    /// kept. Nothing may be deferred before (a step's apply starts with none).
    pub(crate) fn take_moves(&mut self, moves: &mut [Moves]) {
        debug_assert!(self.deferred.is_empty(), "moves taken after a deferral");
        // Every task keeps room for twice the busiest one's moves, grown to that once they
        // fill two thirds of it: a task's share follows its slots, which, numbered by
        // place (a world inserted in one batch), cover one part of the world, and which part
        // is busiest shifts from step to step.
        let most = moves.iter().map(|m| m.deferred.len()).max().unwrap_or(0);
        for m in moves {
            self.deferred.extend_from_slice(&m.deferred);
            for (count, delta) in self.per_level.iter_mut().zip(m.per_level) {
                *count = count.wrapping_add_signed(delta);
            }
            if m.deferred.capacity() < most + most / 2 {
                crate::radix::grow_to(&mut m.deferred, 2 * most);
            }
            m.deferred.clear();
            m.per_level = [0; MAX_DEPTH as usize + 1];
        }
    }

    /// Puts the deferred relinks in id order after the caller deferred some past the tasks'
    /// (see [`Octree::take_moves`]).
    pub(crate) fn order_deferred(&mut self) {
        if !self.deferred.is_sorted_by_key(|d| d.id) {
            self.deferred.sort_unstable_by_key(|d| d.id);
        }
    }
}

/// A sphere's placement from [`Placer::placement_of`], for [`Record::store_in_place`].
#[derive(Clone, Copy, Debug)]
pub(crate) struct Placed(placement::Located);

/// A sphere's record in the tree (opaque outside it), lent out by
/// [`Octree::split_for_update`].
pub(crate) type Record = Obj;

impl Obj {
    /// Stores `center`, `radius` placed at `at` (from `placer`, this record's tree) if the
    /// sphere stays in its node and the update leaves the count of spheres outside the region
    /// as it was: the record is all such a move changes. False, with nothing stored, if the
    /// move needs [`Octree::update_live_deferred`].
    #[inline(always)]
    pub(crate) fn store_in_place(
        &mut self,
        placer: &Placer<'_>,
        center: Vec3,
        radius: f32,
        at: &Placed,
    ) -> bool {
        let at = &at.0;
        // Only a sphere in the root (node 0) can be outside the region.
        let counted = self.node == 0
            && (at.outside()
                || placer
                    .lattice
                    .is_outside(&self.aabb(), self.center, self.radius));
        if self.node != at.node() || self.node == NONE || counted {
            return false;
        }
        (self.center, self.radius) = (center, radius);
        true
    }

    /// [`Record::store_in_place`], and a move to another node too, noted in `moves` (the
    /// record, id `id`, gets its new node and walk key; its lists catch up once the tree takes
    /// the moves, see [`Octree::take_moves`]). False, with nothing stored, if the move enters
    /// or leaves the region, or starts or ends in the root, where the count of spheres
    /// outside it may change: [`Octree::update_live_deferred`] then.
    #[inline(always)]
    pub(crate) fn store_placed(
        &mut self,
        placer: &Placer<'_>,
        id: u32,
        center: Vec3,
        radius: f32,
        at: &Placed,
        moves: &mut Moves,
    ) -> bool {
        let (old, new) = (self.node, at.0.node());
        if old == new || old == 0 || new == 0 || old == NONE {
            return self.store_in_place(placer, center, radius, at);
        }
        (self.center, self.radius) = (center, radius);
        self.set_node(placer.lattice, new);
        moves.per_level[level_of(old) as usize] -= 1;
        moves.per_level[level_of(new) as usize] += 1;
        moves.deferred.push(Deferred { id, old });
        true
    }
}
