//! The incremental regime as a type: [`Incremental`], the state that exists only while the
//! broadphase is in the regime ([`BroadPhase`]'s "The passes and the incremental regime"),
//! and the entry into it and the exit from it.

use super::gapped::Gapped;
use super::patch::{Hints, Patch};
use super::store::Kind;
use super::{BroadPhase, Shape};
use crate::geom::SimdBox;
use crate::radix::{grow_slots, try_grow_to};

/// What the broadphase keeps while it is in the incremental regime, and only then:
/// `BroadPhase::regime` is `Some` exactly while the structures hold fat boxes and the
/// candidates are complete.
///
/// Where a proxy's exact box (its shape grown by `Config::margin`) is kept follows from the
/// type. In the regime, [`Incremental::exact`] holds every live proxy's. Outside it a sphere's
/// is its octree record (the octree holds the exact box there) and a body's is
/// `Store::exact` (the apply reads the box it replaces without a walk into the BVH). The
/// array moves between the two homes without a copy: on entry the store's array becomes
/// `exact` and the spheres' entries are filled from their shapes; on exit it goes back, its
/// bodies' entries current (the regime's apply keeps them so).
///
/// A regime left keeps its buffers for the next entry (`BroadPhase::spare`), so a world that
/// enters and leaves again and again allocates nothing for it once its lists have grown.
#[derive(Clone, Debug, Default)]
pub(super) struct Incremental {
    /// Every live proxy's exact box, by slot (for a stale slot, the last applied one). 32
    /// bytes per slot.
    pub(super) exact: Vec<SimdBox>,
    /// The fat box its structure (octree or BVH) holds, around the exact box. 32 bytes per
    /// slot.
    pub(super) held: Vec<SimdBox>,
    /// The exact box when its candidates were last tested (see the incremental pass,
    /// `slack`). 32 bytes per slot.
    pub(super) anchor: Vec<SimdBox>,
    /// The least slack of its candidates, from the anchors (metres, rounded down). 4 bytes
    /// per slot.
    pub(super) slack: Vec<f32>,
    /// Candidate pairs (packed slot pairs, `HIT` set if their exact boxes overlapped at the
    /// last step), sorted.
    pub(super) cand: Gapped<u64>,
    /// The candidates' reverse index: `(higher slot, lower slot)` of each, sorted, so that a
    /// proxy's lower partners are found without a scan. Kept only while the incremental pass
    /// finds the loud proxies' candidates through it (see `rev_stale`).
    pub(super) rev: Gapped<u64>,
    /// True while `rev` is not the candidates' reverse index: a step that scans the
    /// candidates instead of looking them up leaves it, and the next lookup builds it again.
    pub(super) rev_stale: bool,
    /// Where each proxy's candidates were last found in `cand` and `rev`: the lookups start
    /// there.
    pub(super) hints: Hints,
    /// The incremental pass's list patches.
    pub(super) patch: Patch,
}

impl Incremental {
    /// Grows the per-slot arrays to `slots` entries (`exact` by an eighth at a time, see
    /// [`grow_slots`], as the store grows it outside the regime); a new entry is empty until
    /// its slot is placed.
    #[inline]
    pub(super) fn fit(&mut self, slots: usize) {
        if self.exact.len() < slots {
            grow_slots(&mut self.exact, slots);
            self.exact.resize(slots, SimdBox::EMPTY);
        }
        fit(&mut self.held, slots, SimdBox::EMPTY);
        fit(&mut self.anchor, slots, SimdBox::EMPTY);
        fit(&mut self.slack, slots, 0.0);
    }

    /// Reserves room, exactly, for `want` slots in the per-slot arrays (a hint, like
    /// `Store::reserve`).
    pub(super) fn reserve(&mut self, want: usize) {
        try_grow_to(&mut self.exact, want);
        try_grow_to(&mut self.held, want);
        try_grow_to(&mut self.anchor, want);
        try_grow_to(&mut self.slack, want);
    }

    /// Heap bytes held (capacities).
    pub(super) fn heap_bytes(&self) -> usize {
        (self.exact.capacity() + self.held.capacity() + self.anchor.capacity()) * 32
            + self.slack.capacity() * 4
            + (self.cand.capacity() + self.rev.capacity()) * 8
            + self.hints.heap_bytes()
            + self.patch.heap_bytes()
    }
}

/// Grows the per-slot array `v` to `slots` entries of `empty`.
#[inline]
fn fit<T: Clone>(v: &mut Vec<T>, slots: usize, empty: T) {
    if v.len() < slots {
        v.resize(slots, empty);
    }
}

impl BroadPhase {
    /// Enters the incremental regime, before a full pass over fat boxes gives every proxy
    /// its fat box: the spare buffers become the regime's, the store's array of exact boxes
    /// moves in, and every live proxy's is filled from its shape (every slot is applied; a
    /// body's was current already).
    pub(super) fn enter_regime(&mut self) {
        debug_assert!(self.regime.is_none(), "entering the regime twice");
        let mut r = core::mem::take(&mut self.spare);
        r.exact = core::mem::take(&mut self.store.exact);
        r.fit(self.store.slots());
        let margin = self.config.margin;
        for s in 0..self.store.slots() {
            if self.store.kind[s] != Kind::Free {
                r.exact[s] = super::fat::grown(self.store.shape[s], margin).aabb;
            }
        }
        self.regime = Some(r);
    }

    /// Leaves the incremental regime, before a full pass over exact boxes gives every proxy
    /// its exact box again: the candidates are dropped, the exact boxes go back to the store
    /// (the bodies' are current), and the buffers are kept for the next entry.
    pub(super) fn leave_regime(&mut self) {
        let Some(mut r) = self.regime.take() else {
            return;
        };
        r.cand.clear();
        r.rev.clear();
        r.rev_stale = false;
        self.store.exact = core::mem::take(&mut r.exact);
        self.spare = r;
        self.clear_pending();
    }

    /// Writes `exact`, the exact box of the newly placed live `slot`, where the type says it
    /// is kept (see [`Incremental`]): in the regime's array, or for a body outside the regime
    /// in the store's; a sphere's outside the regime is its octree record.
    pub(super) fn keep_exact(&mut self, slot: u32, exact: SimdBox) {
        let s = slot as usize;
        match (&mut self.regime, &self.store.shape[s]) {
            (Some(r), _) => {
                r.fit(self.store.slots());
                r.exact[s] = exact;
            }
            (None, Shape::Body { .. }) => {
                self.store.grow_exact();
                self.store.exact[s] = exact;
            }
            (None, Shape::Sphere { .. }) => {}
        }
    }

    /// Slot `s`'s exact box where it is kept apart from its structure (see [`Incremental`]):
    /// every live proxy's in the regime, a body's outside it; `None` for a sphere outside the
    /// regime, whose exact box is its octree record.
    pub(super) fn kept_exact(&self, s: usize) -> Option<SimdBox> {
        match (&self.regime, &self.store.shape[s]) {
            (Some(r), _) => Some(r.exact[s]),
            (None, Shape::Body { .. }) => Some(self.store.exact[s]),
            (None, Shape::Sphere { .. }) => None,
        }
    }

    /// The array that keeps exact boxes (see [`Incremental`]): the regime's in it (every
    /// proxy's), the store's outside it (the bodies' only).
    #[inline]
    pub(super) fn kept_exact_mut(&mut self) -> &mut [SimdBox] {
        match &mut self.regime {
            Some(r) => &mut r.exact,
            None => &mut self.store.exact,
        }
    }
}

#[cfg(test)]
mod tests {
    use crate::broadphase::{BroadPhase, Config, Pass, Shape};
    use crate::brute::{self, Proxy};
    use crate::{Aabb, Vec3};

    /// A world that enters and leaves the incremental regime again and again keeps one set of
    /// regime buffers: from the second entry on, every per-slot array is the allocation the
    /// first entry made (the same address and room), and the pairs stay the brute force's.
    #[test]
    fn reentering_the_regime_reuses_the_buffers_of_the_last_stay() {
        let mut bp = BroadPhase::new(Config::default());
        let at = |i: usize| Vec3::new((i % 20) as f32, (i / 20) as f32, 0.0) * 0.9;
        let keys: Vec<_> = (0..400)
            .map(|i| bp.insert_sphere(at(i), 0.5).unwrap())
            .collect();
        let mut seen = None;
        let (mut entries, mut exits) = (0, 0);
        for step in 0..60u32 {
            // At rest for ten steps (the regime), then everyone far away and back (the full
            // pass), and so on.
            let jump = (step / 10) % 2 == 1 && step % 2 == 0;
            for (i, &k) in keys.iter().enumerate() {
                let off = if jump { Vec3::splat(50.0) } else { Vec3::ZERO };
                bp.update_sphere(k, at(i) + off, 0.5).unwrap();
            }
            let was_in = bp.regime.is_some();
            bp.step();
            bp.validate();
            let margin = bp.config().margin;
            let proxies: Vec<Proxy> = bp
                .iter()
                .map(|(k, shape)| match shape {
                    Shape::Sphere { center, radius } => {
                        Proxy::new(k, Aabb::from_center_radius(center, radius + margin))
                    }
                    Shape::Body { .. } => unreachable!("spheres only"),
                })
                .collect();
            assert_eq!(bp.pairs(), brute::pairs(&proxies));
            match (&bp.regime, was_in) {
                (Some(r), false) => {
                    assert_eq!(bp.stats().pass, Pass::FullFat);
                    entries += 1;
                    let room = (r.exact.as_ptr(), r.held.as_ptr(), r.anchor.as_ptr());
                    let caps = (r.exact.capacity(), r.held.capacity(), r.slack.capacity());
                    if let Some(first) = seen {
                        assert_eq!((room, caps), first, "entry {entries} reallocated");
                    }
                    seen = Some((room, caps));
                }
                (None, true) => exits += 1,
                _ => {}
            }
        }
        assert!(
            entries >= 3 && exits >= 2,
            "{entries} entries, {exits} exits"
        );
    }
}
