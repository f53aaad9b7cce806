//! Exact without re-testing what cannot have changed: the *slack* of the incremental pass.
//!
//! A candidate pair's overlap status can only change once its boxes have moved by more than
//! its slack: for an overlapping pair the smallest of its overlap margins (`b.max − a.min` and
//! `a.max − b.min` on each axis), for a separated pair its largest gap. Both are
//! `|min over axes of min(b.max − a.min, a.max − b.min)|` ([`slack`]). Every proxy keeps an
//! *anchor* (its exact box when its candidates were last tested), its *drift* (how far any face
//! of its exact box is from the anchor's, [`drift`]) and its *slack* `m` (the least slack of
//! its candidate pairs, computed from the anchors). A pair whose two proxies have
//! `2·drift < m` needs no test: each side moved less than half the pair's slack, so the
//! status at the anchors, which the candidate records, is the status now.
//!
//! A step (see [`BroadPhase::classify`]) makes *loud* every proxy that escaped its fat box,
//! was inserted, was marked *pending* by the last step, or moved with `2·drift ≥ m`: a loud
//! proxy is re-anchored at its exact box and all its candidates are re-tested (one scan of the
//! candidate list, [`BroadPhase::scan_candidates`]). Each re-tested pair lowers both sides' `m`
//! to its new slack; a quiet side whose drift is no longer below half of it cannot keep the
//! candidate's recorded status equal to the status at the anchors, so it is marked pending: its
//! pairs were tested this step with the exact boxes, and it is re-anchored at the next.
//!
//! Rounding: a drift is rounded up and a slack down by more than half an ulp, so the test
//! `drift + drift < m` in `f32` implies it in the reals; touching boxes have slack 0 and are
//! re-tested whenever either side moves.
//!
//! The scan also keeps the lists exact in place: the candidates (minus those of escaped or
//! removed proxies, plus the escaped proxies' new ones), the sorted pair list and the key pair
//! list are patched by position ([`remove_at`], [`insert_at`]) with the few pairs that started
//! or stopped overlapping, which are the step's `added` and `removed`.

use super::BroadPhase;
use super::step::{HIT, unpack};
use super::store::{Store, flag};
use crate::geom::SimdBox;
use glam::Vec3A;

/// `1 + 2⁻²²`: a product with it rounds a positive normal `f32` up by at least one ulp.
const ROUND_UP: f32 = 1.0 + 1.0 / (1u32 << 22) as f32;
/// `1 − 2⁻²²`: a product with it rounds a positive normal `f32` down by at least one ulp.
const ROUND_DOWN: f32 = 1.0 - 1.0 / (1u32 << 22) as f32;

/// How far any face of `exact` is from the same face of `anchor` (L∞ over the six faces),
/// rounded up: at least the real distance. Differences that round are normal floats, which
/// the product raises by more than their rounding error; subnormal differences are exact.
#[inline]
#[must_use]
pub(super) fn drift(exact: &SimdBox, anchor: &SimdBox) -> f32 {
    let d = face_moves(exact.min, anchor.min).max(face_moves(exact.max, anchor.max));
    d.max_element() * ROUND_UP
}

/// `|a − b|` per lane, 0 where the faces are equal: a face that stays at `±∞` (a box grown
/// past `f32::MAX`) has not moved, where `∞ − ∞` would give NaN.
#[inline]
pub(super) fn face_moves(a: Vec3A, b: Vec3A) -> Vec3A {
    Vec3A::select(a.cmpeq(b), Vec3A::ZERO, (a - b).abs())
}

/// The slack of two boxes: the smallest overlap margin if they overlap (0 if they touch), the
/// largest gap if not, rounded down and at most `f32::MAX`, so that two drifts each below
/// half of it sum to less than the real slack.
#[inline]
#[must_use]
pub(super) fn slack(a: &SimdBox, b: &SimdBox) -> f32 {
    let lo = (b.max - a.min).min(a.max - b.min);
    (lo.min_element().abs() * ROUND_DOWN).min(f32::MAX)
}

/// True if a proxy that drifted `d` from its anchor, with least candidate slack `m`, keeps
/// every candidate's status: it has not moved, or it moved less than half of `m`.
#[inline]
fn quiet(d: f32, m: f32) -> bool {
    d == 0.0 || d + d < m
}

/// Scratch of [`BroadPhase::scan_candidates`]: the list patches one scan collects. Reused by
/// every step; never shrinks.
#[derive(Clone, Debug, Default)]
pub(super) struct Patch {
    /// Indices of the candidates dropped, ascending.
    cand_gone: Vec<u32>,
    /// The new candidates, each with the index it goes before once the dropped ones are gone.
    cand_at: Vec<u32>,
    cand_new: Vec<u64>,
    /// Indices of the pairs that stopped overlapping, ascending, in the pair list.
    pairs_gone: Vec<u32>,
    /// Where each pair that started overlapping goes, once those are gone.
    pairs_at: Vec<u32>,
}

impl Patch {
    /// Grows every list ahead of its peaks (see `radix::ahead`), to at least `floor`:
    /// their lengths follow the escapes and the pairs that change, which swing from step to
    /// step.
    pub(super) fn keep_headroom(&mut self, floor: usize) {
        fn grow<T>(v: &mut Vec<T>, floor: usize) {
            crate::radix::ahead(v);
            if v.capacity() < floor {
                v.reserve(floor - v.len());
            }
        }
        grow(&mut self.cand_gone, floor);
        grow(&mut self.cand_at, floor);
        grow(&mut self.cand_new, floor);
        grow(&mut self.pairs_gone, floor);
        grow(&mut self.pairs_at, floor);
    }

    /// Heap bytes held (capacities).
    pub(super) fn heap_bytes(&self) -> usize {
        (self.cand_gone.capacity()
            + self.cand_at.capacity()
            + self.pairs_gone.capacity()
            + self.pairs_at.capacity())
            * 4
            + self.cand_new.capacity() * 8
    }
}

impl BroadPhase {
    /// Makes loud every proxy that must re-test its candidates this step: the pending ones,
    /// the escaped (and inserted) ones, and the movers that drifted half their slack. A loud
    /// proxy is re-anchored at its exact box; a quiet mover records its drift.
    pub(super) fn classify(&mut self) {
        let (st, loud) = (&mut self.store, &mut self.loud);
        for &p in &self.pending {
            let s = p as usize;
            st.flags[s] &= !flag::PENDING;
            if st.flags[s] & (flag::GONE | flag::LOUD) == 0 {
                make_loud(st, loud, p);
            }
        }
        self.pending.clear();
        for &m in &self.movers {
            let s = m as usize;
            let f = st.flags[s];
            if f & (flag::GONE | flag::LOUD) != 0 {
                continue;
            }
            let d = drift(&st.exact[s], &st.anchor[s]);
            if f & flag::ESCAPED == 0 && quiet(d, st.slack[s]) {
                st.drift[s] = d;
            } else {
                make_loud(st, loud, m);
            }
        }
    }

    /// Every live proxy anchored at its exact box, its slack the least over its candidates:
    /// after a pass that tested every candidate.
    pub(super) fn anchor_all(&mut self) {
        let st = &mut self.store;
        st.grow_incremental();
        for s in 0..st.slots() {
            st.anchor[s] = st.exact[s];
            st.slack[s] = f32::MAX;
            st.drift[s] = 0.0;
        }
        for &c in &self.cand {
            let (a, b) = unpack(c & !HIT);
            let s = slack(&st.exact[a], &st.exact[b]);
            st.slack[a] = st.slack[a].min(s);
            st.slack[b] = st.slack[b].min(s);
        }
        self.clear_pending();
    }

    /// Forgets the pending marks (the candidates they were about are gone).
    pub(super) fn clear_pending(&mut self) {
        for &p in &self.pending {
            self.store.flags[p as usize] &= !flag::PENDING;
        }
        self.pending.clear();
    }

    /// One scan over the candidates, merged with the escaped proxies' new ones (`fresh`,
    /// sorted, each once): drops those of escaped or removed proxies that were not found
    /// again, re-tests every one with a loud side (lowering both sides' slack, and marking
    /// pending a quiet side that drifted too far for it), keeps the others' last outcome, and
    /// patches the candidates, the pair list and the key pairs in place with the changes,
    /// which are this step's `added` and `removed`.
    pub(super) fn scan_candidates(&mut self) {
        let st = &mut self.store;
        let (flags, exact, anchor) = (&mut st.flags, &st.exact, &st.anchor);
        let (slk, drf) = (&mut st.slack, &mut st.drift);
        let pending = &mut self.pending;
        let p = &mut self.patch;
        for v in [
            &mut p.cand_gone,
            &mut p.cand_at,
            &mut p.pairs_gone,
            &mut p.pairs_at,
        ] {
            v.clear();
        }
        p.cand_new.clear();
        let (added, removed) = (&mut self.added_packed, &mut self.removed_packed);
        added.clear();
        removed.clear();
        let mut tested = 0usize;
        // The exact status of a pair with a loud side, its slack recorded on both sides.
        let mut test = |a: usize, b: usize, flags: &mut [u8]| {
            tested += 1;
            let s = slack(&anchor[a], &anchor[b]);
            for q in [a, b] {
                slk[q] = slk[q].min(s);
                let d = drf[q];
                if flags[q] & (flag::LOUD | flag::PENDING) == 0 && !quiet(d, s) {
                    flags[q] |= flag::PENDING;
                    pending.push(q as u32);
                }
            }
            exact[a].overlaps(&exact[b])
        };
        let fresh = &self.fresh;
        let drop = flag::ESCAPED | flag::GONE;
        // `hits`: the old candidates marked `HIT` so far, that is the old pair list's index
        // of the next one.
        let (mut j, mut hits) = (0usize, 0u32);
        let n = self.cand.len();
        let cand = &mut self.cand;
        let mut i = 0;
        loop {
            // Most candidates sort below the next new one and have no loud, escaped or removed
            // side: they keep their status, and only their `HIT` bit is counted.
            let next = fresh.get(j).copied().unwrap_or(u64::MAX);
            while i < n {
                let c = cand[i];
                let (a, b) = unpack(c);
                if c & !HIT >= next || (flags[a] | flags[b]) & (flag::LOUD | drop) != 0 {
                    break;
                }
                hits += (c >> 63) as u32;
                i += 1;
            }
            if i == n {
                break;
            }
            let c = cand[i];
            let key = c & !HIT;
            while j < fresh.len() && fresh[j] < key {
                let f = fresh[j];
                j += 1;
                let (a, b) = unpack(f);
                let hit = test(a, b, flags);
                p.cand_at.push(i as u32 - p.cand_gone.len() as u32);
                p.cand_new.push(f | if hit { HIT } else { 0 });
                if hit {
                    p.pairs_at.push(hits - p.pairs_gone.len() as u32);
                    added.push(f);
                }
            }
            i += 1;
            let was = c & HIT != 0;
            let (a, b) = unpack(key);
            let both = flags[a] | flags[b];
            let hit = if both & drop != 0 {
                if j < fresh.len() && fresh[j] == key {
                    j += 1;
                    test(a, b, flags)
                } else {
                    p.cand_gone.push(i as u32 - 1);
                    if was {
                        p.pairs_gone.push(hits);
                        removed.push(key);
                        hits += 1;
                    }
                    continue;
                }
            } else if both & flag::LOUD != 0 {
                test(a, b, flags)
            } else {
                hits += u32::from(was);
                continue;
            };
            if hit != was {
                cand[i - 1] = key | if hit { HIT } else { 0 };
                if hit {
                    p.pairs_at.push(hits - p.pairs_gone.len() as u32);
                    added.push(key);
                } else {
                    p.pairs_gone.push(hits);
                    removed.push(key);
                }
            }
            hits += u32::from(was);
        }
        let end = self.cand.len() as u32 - p.cand_gone.len() as u32;
        for &f in &fresh[j..] {
            let (a, b) = unpack(f);
            let hit = test(a, b, flags);
            p.cand_at.push(end);
            p.cand_new.push(f | if hit { HIT } else { 0 });
            if hit {
                p.pairs_at.push(hits - p.pairs_gone.len() as u32);
                added.push(f);
            }
        }
        self.stats.candidates_tested = tested;
        remove_at(&mut self.cand, &p.cand_gone);
        insert_at(&mut self.cand, &p.cand_at, &p.cand_new);
        remove_at(&mut self.packed, &p.pairs_gone);
        insert_at(&mut self.packed, &p.pairs_at, added);
        let store = &self.store;
        let to_pair = |&q: &u64| super::step::key_pair(store, q);
        self.added.clear();
        self.added.extend(self.added_packed.iter().map(to_pair));
        self.removed.clear();
        self.removed.extend(self.removed_packed.iter().map(to_pair));
        remove_at(&mut self.pairs, &p.pairs_gone);
        insert_at(&mut self.pairs, &p.pairs_at, &self.added);
    }
}

/// Marks `slot` loud and re-anchors it at its exact box; its slack is found again by the scan.
#[inline]
fn make_loud(st: &mut Store, loud: &mut Vec<u32>, slot: u32) {
    let s = slot as usize;
    st.flags[s] |= flag::LOUD;
    loud.push(slot);
    st.anchor[s] = st.exact[s];
    st.slack[s] = f32::MAX;
    st.drift[s] = 0.0;
}

/// Removes `v[i]` for every `i` of `gone` (ascending, distinct), in place: each run of kept
/// entries moves once.
pub(super) fn remove_at<T: Copy>(v: &mut Vec<T>, gone: &[u32]) {
    let Some(&first) = gone.first() else {
        return;
    };
    let mut to = first as usize;
    for (k, &g) in gone.iter().enumerate() {
        let from = g as usize + 1;
        let end = gone.get(k + 1).map_or(v.len(), |&n| n as usize);
        v.copy_within(from..end, to);
        to += end - from;
    }
    v.truncate(to);
}

/// Inserts `new[k]` before the entry at index `at[k]` of `v` as it is now (`at` ascending,
/// repeats allowed, `v.len()` appends), in place: from the back, each run of old entries
/// moves once.
pub(super) fn insert_at<T: Copy>(v: &mut Vec<T>, at: &[u32], new: &[T]) {
    debug_assert_eq!(at.len(), new.len());
    let Some(&first) = new.first() else {
        return;
    };
    let mut end = v.len();
    v.resize(end + new.len(), first);
    let mut to = v.len();
    for (&p, &x) in at.iter().zip(new).rev() {
        let p = p as usize;
        v.copy_within(p..end, to - (end - p));
        to -= end - p;
        end = p;
        to -= 1;
        v[to] = x;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Vec3;

    fn boxed(min: [f32; 3], max: [f32; 3]) -> SimdBox {
        SimdBox::new(&crate::Aabb::new(Vec3::from(min), Vec3::from(max)))
    }

    #[test]
    fn slack_is_least_margin_or_largest_gap() {
        let a = boxed([0.0; 3], [1.0; 3]);
        let b = boxed([0.75, 0.5, 0.0], [2.0, 2.0, 1.0]);
        // Overlap margins: x 0.25, y 0.5, z 1.0 (both sides).
        let s = slack(&a, &b);
        assert!(s <= 0.25 && s > 0.2499, "{s}");
        let c = boxed([3.0, 0.0, 1.5], [4.0, 1.0, 2.0]);
        // Gaps: x 2.0, z 0.5; y overlaps.
        let s = slack(&a, &c);
        assert!(s <= 2.0 && s > 1.999, "{s}");
        let touching = boxed([1.0, 0.0, 0.0], [2.0, 1.0, 1.0]);
        assert_eq!(slack(&a, &touching), 0.0);
        let huge = boxed([-f32::MAX; 3], [f32::MAX; 3]);
        let far = boxed([f32::MAX; 3], [f32::MAX; 3]);
        assert!(slack(&huge, &a).is_finite());
        assert_eq!(slack(&huge, &far), 0.0);
    }

    #[test]
    fn drift_bounds_every_face_move() {
        let a = boxed([0.0; 3], [1.0; 3]);
        let e = boxed([0.1, -0.2, 0.0], [1.0, 1.3, 1.0]);
        let d = drift(&e, &a);
        assert!((0.3..0.3001).contains(&d), "{d}");
        assert_eq!(drift(&a, &a), 0.0);
        let far = boxed([-f32::MAX; 3], [f32::MAX; 3]);
        let back = boxed([f32::MAX; 3], [f32::MAX; 3]);
        assert_eq!(drift(&far, &back), f32::INFINITY);
        assert!(!quiet(drift(&far, &back), f32::MAX));
    }

    #[test]
    fn patches_by_position() {
        let mut v: Vec<u32> = (0..10).collect();
        remove_at(&mut v, &[0, 3, 4, 9]);
        assert_eq!(v, [1, 2, 5, 6, 7, 8]);
        insert_at(&mut v, &[0, 2, 2, 6], &[100, 200, 201, 300]);
        assert_eq!(v, [100, 1, 2, 200, 201, 5, 6, 7, 8, 300]);
        remove_at(&mut v, &[]);
        insert_at(&mut v, &[], &[]);
        assert_eq!(v.len(), 10);
    }
}
