//! Dense proxy storage: one slot per proxy, structure-of-arrays, with the slotmap-compatible
//! keys made and checked here, at the API boundary, and nowhere else.
//!
//! A slot's version is odd while it is live and even while it is free (slotmap's rule, so a
//! key is `KeyData::from_ffi(version << 32 | slot)`). A slot freed since the last step is
//! quarantined until that step has reported its pairs as removed: the pair lists are kept as
//! packed slot pairs, and a slot reused within the same step would make an old pair and a new
//! one look alike.

use super::{BodyKind, CollisionGroups, Shape};
use crate::geom::SimdBox;
use crate::pair::ProxyKey;
use crate::radix::{grow_slots, try_grow_to};
use slotmap::{Key, KeyData};

/// What a slot holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
pub(super) enum Kind {
    Free,
    Sphere,
    Dynamic,
    Static,
}

/// Per-slot flags of the current step, one byte.
pub(super) mod flag {
    /// Updated since the last step (its exact box must be re-tested against its candidates).
    pub(crate) const MOVED: u8 = 1;
    /// Re-anchored this step: its candidates are re-tested (see `slack`).
    pub(crate) const LOUD: u8 = 2;
    /// Its fat box was replaced since the last step: its candidates are found again.
    pub(crate) const ESCAPED: u8 = 4;
    /// Removed: its candidates are dropped at the next step; the slot is not reused before
    /// the next step.
    pub(crate) const GONE: u8 = 8;
    /// Its candidates' recorded status may differ from the status at the anchors: it is
    /// re-anchored at the next incremental step (see `slack`).
    pub(crate) const PENDING: u8 = 16;
    /// Updated since the last step and not yet applied: its shape is the new one, its exact
    /// box, motion record and its structure's box are still the last step's (see `apply`).
    /// Always set with `MOVED`.
    pub(crate) const STALE: u8 = 32;
    /// Its exact box may have moved from its anchor since it was anchored: its drift is
    /// computed from the two when a re-test needs it (see `slack`). Clear: the two are equal.
    pub(crate) const DRIFTED: u8 = 64;
}

/// The highest slot index: slots are packed two to a `u64` pair with the top bit spare.
pub(super) const MAX_SLOTS: u32 = 1 << 31;

// The per-slot byte counts of `Store`'s fields.
const _: () = assert!(core::mem::size_of::<Shape>() == 28);

/// The proxies, by slot.
#[derive(Clone, Debug, Default)]
pub(super) struct Store {
    /// Odd while live, even while free. 4 bytes per slot.
    pub(super) version: Vec<u32>,
    /// 1 byte per slot.
    pub(super) kind: Vec<Kind>,
    /// `flag::*` bits. 1 byte per slot.
    pub(super) flags: Vec<u8>,
    /// The shape as the user gave it. 28 bytes per slot.
    pub(super) shape: Vec<Shape>,
    /// Outside the incremental regime, a body's exact box (the box pairs are computed on:
    /// its shape's grown by `Config::margin`; for a stale slot, the last applied one); a
    /// sphere's entry means nothing. Inside the regime the array has moved into the regime's
    /// state, which holds every proxy's exact box, and this one is empty. Allocated by the
    /// first body or the first entry into the regime, so a world of spheres that never
    /// enters it keeps none. 32 bytes.
    pub(super) exact: Vec<SimdBox>,
    /// Collision groups, [`CollisionGroups::ALL`] where not set. Allocated (for every slot)
    /// when the first other groups are set, so a world that sets none keeps none: read
    /// through [`Store::group`]. 8 bytes.
    groups: Vec<CollisionGroups>,
    /// Distance the box moved per step, as last measured (metres, largest axis): sizes the skin.
    /// 4 bytes.
    pub(super) speed: Vec<f32>,
    /// The step at which the slot was last updated or got its fat box. 4 bytes.
    pub(super) stamp: Vec<u32>,
    /// Free slots ready for reuse.
    free: Vec<u32>,
    /// Slots freed since the last step: reusable once that step has reported their pairs.
    quarantine: Vec<u32>,
    live: usize,
}

impl Store {
    /// Live proxies.
    pub(super) fn len(&self) -> usize {
        self.live
    }

    /// How many more slots [`Store::alloc`] can give before the next step frees more: the
    /// free ones and those never used.
    pub(super) fn available(&self) -> usize {
        self.free.len() + (MAX_SLOTS as usize).saturating_sub(self.version.len())
    }

    /// Slot count (live and free): the bound of every per-slot array.
    pub(super) fn slots(&self) -> usize {
        self.version.len()
    }

    /// The slot `key` names, if it names a live proxy here.
    #[inline]
    pub(super) fn resolve(&self, key: ProxyKey) -> Option<u32> {
        let ffi = key.data().as_ffi();
        let (slot, version) = (ffi as u32, (ffi >> 32) as u32);
        match self.version.get(slot as usize) {
            Some(&v) if v == version && v & 1 == 1 => Some(slot),
            _ => None,
        }
    }

    /// The key of a live slot, or of the proxy a quarantined slot held last.
    #[inline]
    pub(super) fn key(&self, slot: u32) -> ProxyKey {
        let v = self.version[slot as usize];
        let live = v | 1;
        let version = if v & 1 == 1 { live } else { v - 1 };
        ProxyKey::from(KeyData::from_ffi(
            (u64::from(version) << 32) | u64::from(slot),
        ))
    }

    /// Takes a slot for a new proxy, or `None` when every slot index is in use. Its groups
    /// start at [`CollisionGroups::ALL`]; its exact box is the caller's to keep
    /// (`BroadPhase::keep_exact`).
    pub(super) fn alloc(&mut self, shape: Shape, step: u32) -> Option<u32> {
        let kind = match shape {
            Shape::Sphere { .. } => Kind::Sphere,
            Shape::Body {
                kind: BodyKind::Dynamic,
                ..
            } => Kind::Dynamic,
            Shape::Body {
                kind: BodyKind::Static,
                ..
            } => Kind::Static,
        };
        let slot = match self.free.pop() {
            Some(slot) => slot,
            None => {
                let slot = u32::try_from(self.version.len())
                    .ok()
                    .filter(|&s| s < MAX_SLOTS)?;
                if self.version.len() == self.version.capacity() {
                    self.grow_slots();
                }
                self.version.push(0);
                self.kind.push(Kind::Free);
                self.flags.push(0);
                self.shape.push(shape);
                if !self.groups.is_empty() {
                    self.groups.push(CollisionGroups::ALL);
                }
                self.speed.push(0.0);
                self.stamp.push(step);
                slot
            }
        };
        let s = slot as usize;
        self.version[s] += 1;
        self.kind[s] = kind;
        self.flags[s] = 0;
        self.shape[s] = shape;
        if let Some(g) = self.groups.get_mut(s) {
            *g = CollisionGroups::ALL;
        }
        self.speed[s] = 0.0;
        self.stamp[s] = step;
        self.live += 1;
        Some(slot)
    }

    /// Grows every per-slot array by an eighth ([`grow_slots`]) for the next slot.
    fn grow_slots(&mut self) {
        let len = self.version.len() + 1;
        grow_slots(&mut self.version, len);
        grow_slots(&mut self.kind, len);
        grow_slots(&mut self.flags, len);
        grow_slots(&mut self.shape, len);
        if !self.groups.is_empty() {
            grow_slots(&mut self.groups, len);
        }
        grow_slots(&mut self.speed, len);
        grow_slots(&mut self.stamp, len);
    }

    /// Reserves room, exactly, for `additional` more live slots than the free ones hold (at
    /// most [`MAX_SLOTS`] in all), and returns the slots reserved for. A hint: room the
    /// allocator cannot give is not reserved.
    pub(super) fn reserve(&mut self, additional: usize) -> usize {
        let new = additional.saturating_sub(self.free.len());
        let want = (self.version.len() + new).min(MAX_SLOTS as usize);
        try_grow_to(&mut self.version, want);
        try_grow_to(&mut self.kind, want);
        try_grow_to(&mut self.flags, want);
        try_grow_to(&mut self.shape, want);
        if !self.groups.is_empty() {
            try_grow_to(&mut self.groups, want);
        }
        try_grow_to(&mut self.speed, want);
        try_grow_to(&mut self.stamp, want);
        if !self.exact.is_empty() {
            try_grow_to(&mut self.exact, want);
        }
        want
    }

    /// Frees a live slot; it stays quarantined until [`Store::release_quarantine`].
    pub(super) fn free(&mut self, slot: u32) {
        let s = slot as usize;
        self.version[s] += 1;
        self.kind[s] = Kind::Free;
        self.flags[s] = flag::GONE;
        self.live -= 1;
        self.quarantine.push(slot);
    }

    /// After a step: the slots freed before it become reusable, except those whose version
    /// space is spent (they are retired, as slotmap does).
    pub(super) fn release_quarantine(&mut self) {
        for slot in self.quarantine.drain(..) {
            if self.version[slot as usize] < u32::MAX - 2 {
                self.free.push(slot);
            }
        }
    }

    /// The slots freed since the last step.
    pub(super) fn freed(&self) -> &[u32] {
        &self.quarantine
    }

    /// The free slots in reuse order (the last is taken first), and the quarantined ones in
    /// the order they become free.
    #[cfg(feature = "serde")]
    pub(super) fn free_lists(&self) -> (&[u32], &[u32]) {
        (&self.free, &self.quarantine)
    }

    /// Sets the free and quarantined lists and the live count of a store whose per-slot
    /// arrays were filled directly (a restored snapshot); the caller has checked them
    /// against the versions.
    #[cfg(feature = "serde")]
    pub(super) fn set_free_lists(&mut self, free: Vec<u32>, quarantine: Vec<u32>, live: usize) {
        self.free = free;
        self.quarantine = quarantine;
        self.live = live;
    }

    /// The collision groups of slot `s` ([`CollisionGroups::ALL`] unless set otherwise).
    #[inline]
    pub(super) fn group(&self, s: usize) -> CollisionGroups {
        self.groups.get(s).copied().unwrap_or(CollisionGroups::ALL)
    }

    /// Sets the collision groups of slot `s`, allocating the groups of every slot the first
    /// time they are not [`CollisionGroups::ALL`].
    pub(super) fn set_group(&mut self, s: usize, groups: CollisionGroups) {
        if self.groups.is_empty() {
            if groups == CollisionGroups::ALL {
                return;
            }
            self.groups.resize(self.version.len(), CollisionGroups::ALL);
        }
        self.groups[s] = groups;
    }

    /// Grows `exact` to every slot (see [`Store::exact`]).
    pub(super) fn grow_exact(&mut self) {
        let n = self.version.len();
        grow_slots(&mut self.exact, n);
        self.exact.resize(n, SimdBox::EMPTY);
    }

    /// Heap bytes held (capacity, not length).
    pub(super) fn heap_bytes(&self) -> usize {
        let cap = |n: usize, one: usize| n * one;
        cap(self.version.capacity(), 4)
            + cap(self.kind.capacity(), 1)
            + cap(self.flags.capacity(), 1)
            + cap(self.shape.capacity(), core::mem::size_of::<Shape>())
            + cap(self.exact.capacity(), 32)
            + cap(self.groups.capacity(), 8)
            + cap(self.speed.capacity(), 4)
            + cap(self.stamp.capacity(), 4)
            + cap(self.free.capacity() + self.quarantine.capacity(), 4)
    }
}

/// Marks `slot` updated and not yet applied in `flags`, listing it in `movers` once (the
/// first time it gets `MOVED`, which every stale slot has); true if it was not stale yet.
#[inline]
pub(super) fn mark_stale_in(flags: &mut [u8], movers: &mut Vec<u32>, slot: u32) -> bool {
    let f = &mut flags[slot as usize];
    let old = *f;
    *f = old | flag::MOVED | flag::STALE;
    if old & flag::MOVED == 0 {
        movers.push(slot);
    }
    old & flag::STALE == 0
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Vec3;

    /// A unit sphere at the origin.
    fn unit_sphere() -> Shape {
        Shape::Sphere {
            center: Vec3::ZERO,
            radius: 1.0,
        }
    }

    /// `reserve` sizes every per-slot array to exactly the slots asked for, counting free
    /// slots as room, and the allocations that fill them do not grow them.
    #[test]
    fn reserve_is_exact_and_counts_free_slots() {
        let sphere = unit_sphere();
        let mut st = Store::default();
        st.reserve(100);
        let caps = |st: &Store| {
            [
                st.version.capacity(),
                st.kind.capacity(),
                st.flags.capacity(),
                st.shape.capacity(),
                st.speed.capacity(),
                st.stamp.capacity(),
            ]
        };
        assert_eq!(caps(&st), [100; 6]);
        let slots: Vec<u32> = (0..100).map(|_| st.alloc(sphere, 0).unwrap()).collect();
        assert_eq!(caps(&st), [100; 6]);
        for &s in &slots[..10] {
            st.free(s);
        }
        st.release_quarantine();
        // Ten free slots cover ten of the fifteen asked for.
        st.reserve(15);
        assert_eq!(caps(&st), [105; 6]);
        for _ in 0..15 {
            st.alloc(sphere, 1).unwrap();
        }
        assert_eq!(caps(&st), [105; 6]);
        assert_eq!(st.len(), 105);
    }

    /// Groups are kept only once some slot's differ from `ALL`: until then every slot reads
    /// `ALL` and nothing is allocated; afterwards every slot has its entry, a new slot and a
    /// reused one start at `ALL`.
    #[test]
    fn groups_are_allocated_by_the_first_other_than_all() {
        let sphere = unit_sphere();
        let mut st = Store::default();
        let a = st.alloc(sphere, 0).unwrap();
        let b = st.alloc(sphere, 0).unwrap();
        st.set_group(a as usize, CollisionGroups::ALL);
        assert_eq!(st.groups.capacity(), 0);
        assert_eq!(st.group(b as usize), CollisionGroups::ALL);
        let g = CollisionGroups {
            memberships: 1,
            filter: 2,
        };
        st.set_group(b as usize, g);
        assert_eq!(st.groups.len(), st.slots());
        assert_eq!(
            (st.group(a as usize), st.group(b as usize)),
            (CollisionGroups::ALL, g)
        );
        let c = st.alloc(sphere, 1).unwrap();
        assert_eq!(st.groups.len(), st.slots());
        assert_eq!(st.group(c as usize), CollisionGroups::ALL);
        st.free(b);
        st.release_quarantine();
        let reused = st.alloc(sphere, 2).unwrap();
        assert_eq!(reused, b);
        assert_eq!(st.group(reused as usize), CollisionGroups::ALL);
    }
}
