//! The whole-structure invariant check of a [`BroadPhase`].

use super::grid::{DEAD, STATIC_BIT};
use super::step::HIT;
use super::store::{Kind, flag};
use super::{BroadPhase, Pair};
use crate::geom::SimdBox;
use crate::sweep;

impl BroadPhase {
    /// Checks every internal invariant and panics with a message on the first broken one: each
    /// live proxy in exactly one grid entry holding its exact box (or a fat box around it),
    /// the grid's order, the dirty and step lists, and with candidates, that they are exactly
    /// the pairs of overlapping fat boxes and that the pair list is their overlapping part.
    /// For tests: O(n log n + candidates).
    pub fn validate(&self) {
        let st = &self.store;
        let mut live = 0;
        for s in 0..st.slots() {
            let v = st.version[s];
            assert_eq!(
                v & 1 == 1,
                st.kind[s] != Kind::Free,
                "slot {s}: version and kind"
            );
            if st.kind[s] == Kind::Free {
                assert!(st.flags[s] & flag::GONE != 0 || v == 0 || st.flags[s] & !flag::DIRTY == 0);
                continue;
            }
            live += 1;
            assert_eq!(st.flags[s] & flag::GONE, 0, "slot {s}: live but gone");
            assert_eq!(
                st.exact[s],
                self.exact_box(&st.shape[s]),
                "slot {s}: exact box stale"
            );
            let pos = st.pos[s] as usize;
            let word = s as u32
                | if st.kind[s] == Kind::Static {
                    STATIC_BIT
                } else {
                    0
                };
            assert_eq!(
                self.grid.slots.get(pos),
                Some(&word),
                "slot {s}: grid entry"
            );
            let stored = self.grid.boxes[pos];
            if self.cached {
                assert!(
                    stored.contains(&st.exact[s]),
                    "slot {s}: outside its fat box"
                );
            } else {
                assert_eq!(
                    stored, st.exact[s],
                    "slot {s}: grid box is not the exact box"
                );
            }
            if st.flags[s] & flag::MOVED != 0 {
                assert!(
                    self.movers.contains(&(s as u32)),
                    "slot {s}: moved, not listed"
                );
            }
            if st.flags[s] & flag::DIRTY != 0 {
                assert!(
                    self.dirty.contains(&(s as u32)),
                    "slot {s}: dirty, not listed"
                );
            }
        }
        assert_eq!(live, st.len(), "live count");
        let entries = self.grid.slots.iter().filter(|&&w| w != DEAD).count();
        assert_eq!(entries, live, "grid holds unknown entries");
        for i in self.grid.appended() {
            let w = self.grid.slots[i];
            assert!(w == DEAD || st.flags[(w & !STATIC_BIT) as usize] & flag::DIRTY != 0);
        }
        self.grid.validate(|i| {
            let w = self.grid.slots[i];
            w != DEAD && st.flags[(w & !STATIC_BIT) as usize] & flag::DIRTY == 0
        });
        if self.cached && self.movers.is_empty() && self.removals == 0 {
            self.validate_candidates();
        }
        let keys: Vec<Pair> = self
            .packed
            .iter()
            .map(|&p| Pair {
                a: st.key((p >> 32) as u32),
                b: st.key(p as u32),
            })
            .collect();
        assert_eq!(keys, self.pairs, "pair list and packed pairs differ");
    }

    /// With no change pending: the candidates are exactly the pairs of overlapping fat boxes
    /// (never static × static), sorted, and the pairs are the candidates marked overlapping.
    fn validate_candidates(&self) {
        let st = &self.store;
        let mut fat: Vec<(SimdBox, u32)> = (0..st.slots())
            .filter(|&s| st.kind[s] != Kind::Free)
            .map(|s| (self.grid.boxes[st.pos[s] as usize], s as u32))
            .collect();
        fat.sort_by(|p, q| p.0.min.x.total_cmp(&q.0.min.x));
        let boxes: Vec<SimdBox> = fat.iter().map(|p| p.0).collect();
        let mut want = Vec::new();
        sweep::self_pairs::<0>(&boxes, |i, j| {
            let (a, b) = (fat[i].1, fat[j].1);
            let both_static =
                st.kind[a as usize] == Kind::Static && st.kind[b as usize] == Kind::Static;
            if !both_static {
                want.push(super::step::pack(a, b));
            }
        });
        want.sort_unstable();
        let have: Vec<u64> = self.cand.iter().map(|&c| c & !HIT).collect();
        assert_eq!(have, want, "candidates are not the overlapping fat pairs");
        let hits: Vec<u64> = self
            .cand
            .iter()
            .filter(|&&c| c & HIT != 0)
            .map(|&c| c & !HIT)
            .collect();
        assert_eq!(
            hits, self.packed,
            "pairs are not the overlapping candidates"
        );
        for &c in &hits {
            let (a, b) = ((c >> 32) as usize, c as u32 as usize);
            assert!(
                st.exact[a].overlaps(&st.exact[b]),
                "a reported pair does not overlap"
            );
        }
    }
}
