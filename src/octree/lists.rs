//! The per-node sphere lists: linking and unlinking a sphere, and the relinks a move defers
//! to the next pass ([`Octree::update_live_deferred`]).

use super::nodes::Nodes;
use super::{Link, NONE, Obj, Octree};
use crate::pair::ProxyKey;
use glam::Vec3;

impl Octree {
    /// [`Octree::update_checked`] of a key its caller knows is live here (the `BroadPhase`,
    /// which holds every live sphere here under its key: no key check), which leaves the
    /// node lists behind: a sphere that changes node gets its node, walk key and level count
    /// at once (all that a pass's walk-order sort reads) and is listed in `deferred`. The
    /// next [`Octree::prepare_pass`] relinks the listed spheres beside its sort, on another
    /// thread when it splits the sort; any other change first relinks them
    /// ([`Octree::flush_relinks`]). The lists end as relinking each sphere here would have
    /// left them. Each id at most once until one of those: the broadphase's apply updates
    /// each stale slot once per step, and its step ends with a flush.
    #[inline(always)]
    pub(crate) fn update_live_deferred(&mut self, key: ProxyKey, center: Vec3, radius: f32) {
        let id = crate::pair::slot(key);
        debug_assert!(self.id_of(key).is_some(), "a key not live here");
        let at = self.lattice.locate_memo(center, radius, &mut self.memo);
        let (old, new) = (self.store_sphere(id, center, radius, &at), at.node());
        if old != new {
            self.count_move(old, new);
            self.objs[id as usize].set_node(&self.lattice, new);
            self.deferred.push(Deferred { id, old });
        }
    }

    /// Relinks, one by one and in the order they were moved, the spheres whose lists
    /// [`Octree::update_live_deferred`] left behind: the lists then are what relinking each
    /// at its move would have made. Nothing (one test) when there are none.
    #[inline]
    pub(crate) fn flush_relinks(&mut self) {
        if !self.deferred.is_empty() {
            self.relink_deferred();
        }
    }

    #[inline(never)]
    fn relink_deferred(&mut self) {
        relink_all(&self.objs, &mut self.links, &mut self.nodes, &self.deferred);
        self.relinked();
    }

    /// Empties `deferred` once its spheres are relinked, keeping room for half again as
    /// many, so that a steady world stops allocating here.
    pub(super) fn relinked(&mut self) {
        crate::radix::ahead(&mut self.deferred);
        self.deferred.clear();
    }
    /// Moves sphere `id` from node `from` to node `to`.
    #[inline(never)]
    pub(super) fn relink(&mut self, id: u32, from: u32, to: u32) {
        self.count_move(from, to);
        self.unlink(id);
        self.link(id, to);
    }

    /// Pushes object `id` at the front of `node`'s list.
    pub(super) fn link(&mut self, id: u32, node: u32) {
        self.objs[id as usize].set_node(&self.lattice, node);
        list_link(&mut self.links, &mut self.nodes, id, node);
    }

    /// Takes object `id` out of its node's list (its `node` field is left as it was).
    pub(super) fn unlink(&mut self, id: u32) {
        let node = self.objs[id as usize].node;
        list_unlink(&mut self.links, &mut self.nodes, id, node);
    }
}

/// A sphere whose move to another node its lists have not caught up with yet (see
/// [`Octree::update_live_deferred`]).
#[derive(Clone, Copy, Debug)]
pub(super) struct Deferred {
    pub(super) id: u32,
    /// The node whose list still holds it (its record names the node it is placed in).
    pub(super) old: u32,
}

/// Moves each deferred sphere from its old node's list to the list of the node its record
/// names, in order.
pub(super) fn relink_all(
    objs: &[Obj],
    links: &mut [Link],
    nodes: &mut Nodes,
    deferred: &[Deferred],
) {
    for d in deferred {
        list_unlink(links, nodes, d.id, d.old);
        list_link(links, nodes, d.id, objs[d.id as usize].node);
    }
}

/// Pushes `id` at the front of `node`'s list, marking the path up occupied if the node
/// was empty.
fn list_link(links: &mut [Link], nodes: &mut Nodes, id: u32, node: u32) {
    let became_occupied = nodes.is_empty(node);
    let head = nodes.head(node);
    links[id as usize] = Link {
        next: head,
        prev: NONE,
    };
    if head != NONE {
        links[head as usize].prev = id;
    }
    nodes.set_head(node, id);
    if became_occupied {
        nodes.mark_occupied(node);
    }
}

/// Takes `id` out of the list of `node`, which holds it, marking the path up empty if the
/// node emptied.
fn list_unlink(links: &mut [Link], nodes: &mut Nodes, id: u32, node: u32) {
    let Link { next, prev } = links[id as usize];
    if prev == NONE {
        nodes.set_head(node, next);
    } else {
        links[prev as usize].next = next;
    }
    if next != NONE {
        links[next as usize].prev = prev;
    }
    if nodes.is_empty(node) {
        nodes.mark_empty(node);
    }
}
