//! The whole-structure invariant check of a [`BroadPhase`].

use super::packed::{HIT, pack, pack_pair, unpack};
use super::regime::Incremental;
use super::slack::{distance, drift, slack};
use super::store::{Kind, flag};
use super::{BodyKind, BroadPhase, Pair, Shape};
use crate::geom::SimdBox;
use crate::sweep;

impl BroadPhase {
    /// Checks every internal invariant and panics with a message on the first broken one: each
    /// live proxy held under its key by exactly its own structure (octree, dynamic or static
    /// BVH) with the box the broadphase recorded for it (its exact box, or a fat box around
    /// it; for a slot updated since the last step, its last applied box), every structure's
    /// own invariants, the step lists, and with candidates, that they
    /// are exactly the allowed pairs of overlapping held boxes and that the pair list is their
    /// overlapping part. For tests: O(n log n + candidates).
    #[doc(hidden)]
    pub fn validate(&self) {
        let st = &self.store;
        let mut live = [0usize; 3];
        let mut stale = 0;
        for s in 0..st.slots() {
            self.validate_slot(s, &mut live, &mut stale);
        }
        assert_eq!(live.iter().sum::<usize>(), st.len(), "live count");
        assert_eq!(stale, self.stale, "stale count");
        assert_eq!(self.octree.len(), live[0], "octree holds unknown spheres");
        assert_eq!(
            self.dynamic.len(),
            live[1],
            "dynamic BVH holds unknown bodies"
        );
        assert_eq!(
            self.statics.len(),
            live[2],
            "static BVH holds unknown bodies"
        );
        self.octree.validate();
        self.dynamic.validate();
        self.statics.validate();
        if let Some(r) = &self.regime
            && self.movers.is_empty()
            && self.removals == 0
        {
            self.validate_candidates(r);
        }
        self.validate_pairs();
    }

    /// Slot `s`, if live: its flags and lists, its box held under its key by its own structure
    /// alone; counted in `live` (by structure) and `stale`.
    fn validate_slot(&self, s: usize, live: &mut [usize; 3], stale: &mut usize) {
        let st = &self.store;
        let v = st.version[s];
        assert_eq!(
            v & 1 == 1,
            st.kind[s] != Kind::Free,
            "slot {s}: version and kind"
        );
        if st.kind[s] == Kind::Free {
            return;
        }
        assert_eq!(st.flags[s] & flag::GONE, 0, "slot {s}: live but gone");
        let is_stale = st.flags[s] & flag::STALE != 0;
        if is_stale {
            *stale += 1;
            assert_ne!(st.flags[s] & flag::MOVED, 0, "slot {s}: stale, not moved");
        } else if let Some(exact) = self.kept_exact(s) {
            assert_eq!(
                exact,
                self.exact_box(&st.shape[s]),
                "slot {s}: exact box stale"
            );
        }
        let key = st.key(s as u32);
        // Outside the incremental regime the structure holds the exact box, which is kept
        // elsewhere only for a body: a stale sphere's, the last applied, is known only to its
        // structure there (and a stale body's is checked above).
        let held = match &self.regime {
            Some(r) => Some(r.held[s]),
            None if is_stale => None,
            None => Some(self.exact_box(&st.shape[s])),
        };
        let (home, held_there) = match st.shape[s] {
            Shape::Sphere { .. } => (0, self.octree.aabb(key)),
            Shape::Body {
                kind: BodyKind::Dynamic,
                ..
            } => (1, self.dynamic.aabb(key)),
            Shape::Body {
                kind: BodyKind::Static,
                ..
            } => (2, self.statics.aabb(key)),
        };
        live[home] += 1;
        assert!(held_there.is_some(), "slot {s}: missing from its structure");
        if let Some(held) = held {
            assert_eq!(
                held_there.map(|a| SimdBox::new(&a)),
                Some(held),
                "slot {s}: its structure does not hold its box"
            );
        }
        let others = [
            self.octree.contains(key),
            self.dynamic.contains(key),
            self.statics.contains(key),
        ];
        assert_eq!(
            others.iter().filter(|&&c| c).count(),
            1,
            "slot {s}: held by more than one structure"
        );
        if let Some(r) = &self.regime {
            assert!(
                r.held[s].contains(&r.exact[s]),
                "slot {s}: outside its fat box"
            );
        }
        if st.flags[s] & flag::MOVED != 0 {
            assert!(
                self.movers.contains(&(s as u32)),
                "slot {s}: moved, not listed"
            );
        }
    }

    /// The pair list is what the next full pass diffs against, reading it packed: each pair
    /// names the keys its slots hold (live, or quarantined since their removal) in canonical
    /// order, and the packed pairs strictly increase.
    fn validate_pairs(&self) {
        let st = &self.store;
        assert!(
            self.pairs.iter().all(|p| p.a < p.b),
            "pair list holds a pair out of order"
        );
        let packed: Vec<u64> = self.pairs.iter().map(pack_pair).collect();
        assert!(
            packed.windows(2).all(|w| w[0] < w[1]),
            "pair list not strictly increasing"
        );
        let keys: Vec<Pair> = packed
            .iter()
            .map(|&p| Pair {
                a: st.key((p >> 32) as u32),
                b: st.key(p as u32),
            })
            .collect();
        assert_eq!(keys, *self.pairs, "pair list and its slots' keys differ");
    }

    /// With no change pending: the candidates are exactly the allowed pairs of overlapping
    /// held boxes (never static × static), sorted, and the pairs are the candidates marked
    /// overlapping.
    fn validate_candidates(&self, r: &Incremental) {
        let st = &self.store;
        let mut fat: Vec<(SimdBox, u32)> = (0..st.slots())
            .filter(|&s| st.kind[s] != Kind::Free)
            .map(|s| (r.held[s], s as u32))
            .collect();
        fat.sort_by(|p, q| p.0.min.x.total_cmp(&q.0.min.x));
        let boxes: Vec<SimdBox> = fat.iter().map(|p| p.0).collect();
        let mut want = Vec::new();
        sweep::self_pairs::<0>(&boxes, |i, j| {
            let (a, b) = (fat[i].1 as usize, fat[j].1 as usize);
            let both_static = st.kind[a] == Kind::Static && st.kind[b] == Kind::Static;
            if !both_static && st.group(a).allows(st.group(b)) {
                want.push(pack(a as u32, b as u32));
            }
        });
        want.sort_unstable();
        let have: Vec<u64> = r.cand.iter().map(|&c| c & !HIT).collect();
        assert_eq!(have, want, "candidates are not the overlapping fat pairs");
        if !r.rev_stale {
            let mut rev: Vec<u64> = have.iter().map(|&c| c.rotate_right(32)).collect();
            rev.sort_unstable();
            assert_eq!(rev, *r.rev, "the reverse index is not the candidates'");
        }
        let hits: Vec<u64> = r
            .cand
            .iter()
            .filter(|&&c| c & HIT != 0)
            .map(|&c| c & !HIT)
            .collect();
        let packed: Vec<u64> = self.pairs.iter().map(pack_pair).collect();
        assert_eq!(hits, packed, "pairs are not the overlapping candidates");
        for &c in &hits {
            let (a, b) = ((c >> 32) as usize, c as u32 as usize);
            assert!(
                r.exact[a].overlaps(&r.exact[b]),
                "a reported pair does not overlap"
            );
        }
        self.validate_slack(r);
    }

    /// With candidates and no change pending, the slack invariants (see `slack`): each live
    /// proxy that moved from its anchor is flagged drifted, and its drift is below half its
    /// slack (or it is pending); each candidate's slack at the anchors bounds both sides' slack, and unless a
    /// side is pending its recorded status is the status at the anchors.
    fn validate_slack(&self, r: &Incremental) {
        let st = &self.store;
        let pending = |s: usize| st.flags[s] & flag::PENDING != 0;
        for s in (0..st.slots()).filter(|&s| st.kind[s] != Kind::Free) {
            let d = drift(&r.exact[s], &r.anchor[s]);
            assert!(
                st.flags[s] & flag::DRIFTED != 0 || distance(&r.exact[s], &r.anchor[s]) == 0.0,
                "slot {s}: moved from its anchor, not flagged drifted"
            );
            assert!(
                pending(s) || d == 0.0 || d + d < r.slack[s],
                "slot {s}: drifted half its slack, not pending"
            );
            assert!(
                pending(s) == self.pending.contains(&(s as u32)),
                "slot {s}: pending flag and list"
            );
        }
        for &c in r.cand.iter() {
            let (a, b) = unpack(c & !HIT);
            let s = slack(&r.anchor[a], &r.anchor[b]);
            assert!(
                r.slack[a] <= s && r.slack[b] <= s,
                "slots {a}, {b}: slack above their candidate's"
            );
            if !pending(a) && !pending(b) {
                assert_eq!(
                    r.anchor[a].overlaps(&r.anchor[b]),
                    c & HIT != 0,
                    "slots {a}, {b}: status at the anchors is not the recorded one"
                );
            }
        }
    }
}
