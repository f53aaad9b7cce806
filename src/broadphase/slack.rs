//! Exact without re-testing what cannot have changed: the *slack* of the incremental pass.
//!
//! A candidate pair's overlap status can only change once its boxes have moved by more than
//! its slack: for an overlapping pair the smallest of its overlap margins (`b.max − a.min` and
//! `a.max − b.min` on each axis), for a separated pair its largest gap. Both are
//! `|min over axes of min(b.max − a.min, a.max − b.min)|` ([`slack`]). Every proxy keeps an
//! *anchor* (its exact box when its candidates were last tested) and its *slack* `m` (the least
//! slack of its candidate pairs, computed from the anchors); its *drift* is how far any face of
//! its exact box is from the anchor's ([`drift`]). The drift is not stored: a proxy that moved
//! since it was anchored is flagged `DRIFTED`, and a re-test that lowers its slack computes it
//! from the two boxes (a proxy not flagged has drift 0). A pair whose two proxies have
//! `2·drift < m` needs no test: each side moved less than half the pair's slack, so the
//! status at the anchors, which the candidate records, is the status now.
//!
//! A step makes *loud* every proxy that moved with `2·drift ≥ m` (as its update is applied:
//! [`settle`], or the apply's walk over the stale spheres), and every one that escaped its fat
//! box, was inserted or was marked *pending* by the last step ([`BroadPhase::classify`]): a loud
//! proxy is re-anchored at its exact box and all its candidates are re-tested
//! ([`BroadPhase::update_candidates`], which finds them through the sorted candidate list and
//! its reverse index, without looking at the others). Each re-tested pair lowers both sides' `m`
//! to its new slack; a quiet side whose drift is no longer below half of it cannot keep the
//! candidate's recorded status equal to the status at the anchors, so it is marked pending: its
//! pairs were tested this step with the exact boxes, and it is re-anchored at the next.
//!
//! Rounding: a drift is rounded up and a slack down by more than half an ulp, so the test
//! `drift + drift < m` in `f32` implies it in the reals; touching boxes have slack 0 and are
//! re-tested whenever either side moves.
//!
//! The same pass keeps the lists exact in place: the candidates (minus those of escaped or
//! removed proxies, plus the escaped proxies' new ones), their reverse index and the key pair
//! list are patched by position ([`Gapped::patch`](super::gapped::Gapped::patch)) with the few pairs that started or stopped
//! overlapping, which are the step's `added` and `removed`. No packed pair list is kept beside
//! them: the key pairs are read packed (see [`super::packed::pack_pair`]) where the packed order
//! is needed, here and in a full pass's diff.

use super::BroadPhase;
use super::packed::{HIT, keys_into, pack_pair, sort_scratch, unpack};
use super::patch::Patch;
use super::regime::Incremental;
use super::store::flag;
use crate::geom::SimdBox;
use crate::radix::{PairBits, sort_u32_below, sort_u64, sort_u64_kept};
use glam::Vec3A;

/// Finding one proxy's candidates through the sorted list and the reverse index (a galloping
/// search from its hint per candidate it has, see [`Hints`]) is taken to cost about as much as
/// scanning this many candidates for a loud or removed side (the scan reads two flags per
/// candidate, from an array that stays in the cache): past that many proxies to visit, the
/// step scans.
pub(super) const CANDIDATES_PER_LOOKUP: usize = 300;

/// The candidates to visit and the reverse entries that change are sorted by a radix sort
/// from this many on, by the standard library's sort below it (whose cost per item is
/// higher, but which has no fixed cost).
const RADIX_FROM: usize = 2048;

/// The touched candidates are put in order through a bit map of every candidate position
/// (`Patch::touched_bits`) while there are at most this many candidates per touched one: the
/// map's words then cost at most 8 reads per touched candidate, a sort of 64 or more about
/// as many steps.
const CANDIDATES_PER_TOUCHED: usize = 512;

/// `1 + 2⁻²²`: a product with it rounds a positive normal `f32` up by at least one ulp.
const ROUND_UP: f32 = 1.0 + 1.0 / (1u32 << 22) as f32;
/// `1 − 2⁻²²`: a product with it rounds a positive normal `f32` down by at least one ulp.
const ROUND_DOWN: f32 = 1.0 - 1.0 / (1u32 << 22) as f32;

/// How far any face of `exact` is from the same face of `anchor` (L∞ over the six faces), in
/// `f32`: a face at the same coordinate has not moved, even an infinite one.
#[inline]
#[must_use]
pub(super) fn distance(exact: &SimdBox, anchor: &SimdBox) -> f32 {
    let moved = |e: Vec3A, a: Vec3A| Vec3A::select(e.cmpeq(a), Vec3A::ZERO, (e - a).abs());
    moved(exact.min, anchor.min)
        .max(moved(exact.max, anchor.max))
        .max_element()
}

/// [`distance`] rounded up: at least the real distance. Differences that round are normal
/// floats, which the product raises by more than their rounding error; subnormal differences
/// are exact.
#[inline]
#[must_use]
pub(super) fn drift(exact: &SimdBox, anchor: &SimdBox) -> f32 {
    distance(exact, anchor) * ROUND_UP
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
pub(super) fn quiet(d: f32, m: f32) -> bool {
    d == 0.0 || d + d < m
}

/// A cheaper sufficient test for `quiet(drift(exact, anchor), m)`: every face moved less than
/// half of `m` once rounded up, compared per face without reducing to the drift. False where
/// it cannot tell (a face at infinity, `m` 0), and the caller measures the drift. Exact: the
/// rounded-up product is monotone, so the largest face's passes iff all do, and `d < m / 2`
/// is `d + d < m` (halving and doubling are exact, or round a subnormal `m / 2` up by at most
/// half an ulp, which a float `d` below it cannot reach twice over).
#[inline]
pub(super) fn within(exact: &SimdBox, anchor: &SimdBox, m: f32) -> bool {
    let half = Vec3A::splat(m * 0.5);
    let lo = ((exact.min - anchor.min).abs() * ROUND_UP).cmplt(half);
    let hi = ((exact.max - anchor.max).abs() * ROUND_UP).cmplt(half);
    (lo & hi).all()
}

/// The quiet/loud rule: true if a mover whose exact box is now `exact`, anchored at `anchor`
/// with least candidate slack `m`, stays quiet (keeps every candidate's status), false if it
/// is loud. [`within`] first, the drift only where that cannot tell.
#[inline(always)]
pub(super) fn stays_quiet(exact: &SimdBox, anchor: &SimdBox, m: f32) -> bool {
    within(exact, anchor, m) || quiet(drift(exact, anchor), m)
}

/// Sets `hint[a]` to the index of `a`'s first entry in `list` (sorted by the high half `a`
/// of its entries without the `HIT` bit) for every `a` listed, after `hint` is grown to
/// `slots` entries.
fn hint_firsts(hint: &mut Vec<u32>, slots: usize, list: &[u64]) {
    fit(hint, slots);
    let mut last = u64::MAX;
    for (i, &e) in list.iter().enumerate() {
        let a = (e & !HIT) >> 32;
        if a != last {
            hint[a as usize] = i as u32;
            last = a;
        }
    }
}

/// Grows `hint` to `slots` entries (a new slot's hint is 0: any start is exact).
fn fit(hint: &mut Vec<u32>, slots: usize) {
    if hint.len() < slots {
        hint.resize(slots, 0);
    }
}

/// `list.partition_point(below)` (`below` true on a prefix of `list`), found by galloping
/// outward from `hint`: O(log d) probes for an answer `d` entries away, the first of them
/// next to each other.
///
/// Sorted keys looked up in turn, each from the last one's answer, cost a few probes near it
/// each ([`seek_sorted`]) where a binary search costs a cache miss at each of its last levels.
#[inline]
fn seek<T: Copy>(list: &[T], hint: usize, below: impl Fn(T) -> bool) -> usize {
    let n = list.len();
    let h = hint.min(n);
    if h < n && below(list[h]) {
        // The answer is past `h`: `below` holds up to `lo − 1`.
        let (mut lo, mut step) = (h + 1, 1);
        loop {
            let probe = lo + step - 1;
            if probe >= n {
                return lo + list[lo..].partition_point(|&e| below(e));
            }
            if !below(list[probe]) {
                return lo + list[lo..probe].partition_point(|&e| below(e));
            }
            lo = probe + 1;
            step *= 2;
        }
    }
    // The answer is at most `h`: `below` fails from `hi` on.
    let (mut hi, mut step) = (h, 1);
    loop {
        if hi < step {
            return list[..hi].partition_point(|&e| below(e));
        }
        let probe = hi - step;
        if below(list[probe]) {
            return probe + 1 + list[probe + 1..hi].partition_point(|&e| below(e));
        }
        hi = probe;
        step *= 2;
    }
}

/// For each of `keys`, in turn, the position `at(list, key)` = `list.partition_point(|e| below(e,
/// key))`, pushed to `out`; each is sought from the last answer (see [`seek`]), so keys in
/// ascending order cost a few probes each.
fn seek_sorted<T: Copy>(
    list: &[T],
    keys: &[u64],
    below: impl Fn(T, u64) -> bool,
    out: &mut Vec<u32>,
) {
    let mut at = 0;
    out.extend(keys.iter().map(|&k| {
        at = seek(list, at, |e| below(e, k));
        at as u32
    }));
}

/// The reverse index entry of the candidate `(a, b)`, `a < b`: `b` in the high half.
#[inline]
fn reverse(a: usize, b: usize) -> u64 {
    ((b as u64) << 32) | a as u64
}

impl BroadPhase {
    /// Makes loud every proxy that must re-test its candidates this step: the pending ones and
    /// the escaped (and inserted) ones; the movers that drifted half their slack were made loud
    /// as their updates were applied ([`settle`]). A loud proxy is re-anchored at its exact
    /// box.
    pub(super) fn classify(&mut self) {
        let Some(r) = &mut self.regime else {
            return;
        };
        let (flags, loud) = (&mut self.store.flags[..], &mut self.loud);
        for &p in &self.pending {
            let s = p as usize;
            flags[s] &= !flag::PENDING;
            if flags[s] & (flag::GONE | flag::LOUD) == 0 {
                make_loud(flags, r, loud, p);
            }
        }
        self.pending.clear();
        // The movers that stayed in their fat boxes were classified as their updates were
        // applied ([`BroadPhase::settle`]); every other mover escaped (or was inserted, or
        // changed groups).
        for &e in &self.escaped {
            if flags[e as usize] & (flag::GONE | flag::LOUD) == 0 {
                make_loud(flags, r, loud, e);
            }
        }
    }

    /// Every live proxy anchored at its exact box, its slack the least over its candidates,
    /// and the candidates' reverse index: after a pass that found and tested every candidate.
    pub(super) fn anchor_all(&mut self) {
        let Some(r) = &mut self.regime else {
            return;
        };
        let st = &mut self.store;
        r.fit(st.slots());
        for s in 0..st.slots() {
            r.anchor[s] = r.exact[s];
            r.slack[s] = f32::MAX;
            st.flags[s] &= !flag::DRIFTED;
        }
        for &c in r.cand.iter() {
            let (a, b) = unpack(c & !HIT);
            let s = slack(&r.exact[a], &r.exact[b]);
            r.slack[a] = r.slack[a].min(s);
            r.slack[b] = r.slack[b].min(s);
        }
        hint_firsts(&mut r.hints.cand, st.slots(), &r.cand);
        self.rebuild_rev();
        self.clear_pending();
    }

    /// Builds the reverse index from the candidates: on entering the regime, and after steps
    /// that left it.
    fn rebuild_rev(&mut self) {
        let Some(r) = &mut self.regime else {
            return;
        };
        let cand = &r.cand;
        let layout = PairBits::for_slots(self.store.slots());
        let scratch = sort_scratch(&mut self.octree, &mut self.sort_buf);
        r.rev.refill(cand.len(), 0, |list| {
            let at = list.len();
            list.extend(cand.iter().map(|&c| {
                let (a, b) = unpack(c & !HIT);
                reverse(a, b)
            }));
            sort_u64_kept(&mut list[at..], scratch, layout);
        });
        r.rev_stale = false;
        hint_firsts(&mut r.hints.rev, self.store.slots(), &r.rev);
    }

    /// Forgets the pending marks (the candidates they were about are gone).
    pub(super) fn clear_pending(&mut self) {
        for &p in &self.pending {
            self.store.flags[p as usize] &= !flag::PENDING;
        }
        self.pending.clear();
    }

    /// Visits the candidates of every loud or removed proxy (its forward range in `cand`, its
    /// lower partners through `rev`; when many proxies are loud, one scan of `cand`), merged with the escaped proxies' new ones (`fresh`,
    /// sorted, each once): drops those of escaped or removed proxies that were not found
    /// again, re-tests the others (lowering both sides' slack, and marking pending a quiet
    /// side that drifted too far for it), and patches the candidates, their reverse index,
    /// the pair list and the key pairs in place with the changes, which are this step's
    /// `added` and `removed`. Every other candidate keeps its last outcome untouched.
    pub(super) fn update_candidates(&mut self) {
        let Some(r) = &mut self.regime else {
            return;
        };
        let visits = self.loud.len() + self.store.freed().len();
        let lookup = visits * CANDIDATES_PER_LOOKUP < r.cand.len();
        r.patch.clear();
        if lookup && r.rev_stale && visits > 0 {
            self.rebuild_rev();
        }
        if lookup {
            self.touched_by_lookup();
        } else {
            self.touched_by_scan();
        }
        self.stats.candidates_tested = self.retest();
        self.patch_lists(lookup);
    }

    /// Lists in `patch.touched`, sorted and each once, the candidates of the loud and removed
    /// proxies, looked up through the candidates and their reverse index from the hints.
    fn touched_by_lookup(&mut self) {
        let Some(r) = &mut self.regime else {
            return;
        };
        let p = &mut r.patch;
        let (cand, rev) = (&r.cand[..], &r.rev[..]);
        let key_at = |i: usize| cand[i] & !HIT;
        let hints = &mut r.hints;
        // A proxy inserted since the hints were last set has none yet.
        fit(&mut hints.cand, self.store.slots());
        fit(&mut hints.rev, self.store.slots());
        for &s in self.loud.iter().chain(self.store.freed()) {
            let first = u64::from(s) << 32;
            let hint = hints.cand[s as usize] as usize;
            let mut i = seek(cand, hint, |c| c & !HIT < first);
            debug_assert_eq!(i, cand.partition_point(|&c| c & !HIT < first));
            hints.cand[s as usize] = i as u32;
            while i < cand.len() && key_at(i) >> 32 == u64::from(s) {
                p.touched.push(i as u32);
                i += 1;
            }
            let hint = hints.rev[s as usize] as usize;
            let mut r = seek(rev, hint, |e| e < first);
            debug_assert_eq!(r, rev.partition_point(|&e| e < first));
            hints.rev[s as usize] = r as u32;
            while r < rev.len() && rev[r] >> 32 == u64::from(s) {
                let key = (rev[r] << 32) | u64::from(s);
                // The lower side's candidates start at its hint; this one is among them.
                let hint = hints.cand[(rev[r] & 0xffff_ffff) as usize] as usize;
                let i = seek(cand, hint, |c| c & !HIT < key);
                debug_assert_eq!(key_at(i), key, "reverse index");
                p.touched.push(i as u32);
                r += 1;
            }
        }
        // A pair of two loud sides is listed twice.
        order_touched(p, cand.len());
    }

    /// [`BroadPhase::touched_by_lookup`] by one scan of every candidate.
    fn touched_by_scan(&mut self) {
        let Some(r) = &mut self.regime else {
            return;
        };
        let p = &mut r.patch;
        let cand = &r.cand[..];
        // In the candidates' order, each once: a mask per 64 candidates, built without a
        // branch (whether a side is loud is a coin toss when many are), then its bits.
        let flags = &self.store.flags;
        for (k, chunk) in cand.chunks(64).enumerate() {
            let mut bits = 0u64;
            for (j, &c) in chunk.iter().enumerate() {
                let (a, b) = unpack(c);
                let hit = (flags[a] | flags[b]) & (flag::LOUD | flag::GONE) != 0;
                bits |= u64::from(hit) << j;
            }
            while bits != 0 {
                p.touched.push((k * 64) as u32 + bits.trailing_zeros());
                bits &= bits - 1;
            }
        }
    }

    /// Re-tests the touched candidates and tests the escaped proxies' new ones (in `fresh`,
    /// sorted) in one walk, noting in `patch` the candidates that go and come, and in the
    /// packed `added` / `removed` the pairs whose status changed; returns the pairs tested.
    fn retest(&mut self) -> usize {
        let Some(r) = &mut self.regime else {
            return 0;
        };
        let p = &mut r.patch;
        let (flags, exact, anchor) = (&mut self.store.flags, &r.exact, &r.anchor);
        let slk = &mut r.slack;
        let pending = &mut self.pending;
        let (added, removed) = (&mut self.added_packed, &mut self.removed_packed);
        added.clear();
        removed.clear();
        let mut tested = 0usize;
        // The exact status of a pair with a loud side, its slack recorded on both sides.
        let mut test = |a: usize, b: usize, flags: &mut [u8]| {
            tested += 1;
            // A side that has not drifted is at its anchor: its exact box is read instead,
            // which the overlap test below reads anyway. A resting partner's anchor would be
            // one more cache miss per re-test in a large world. The array is picked by index,
            // without a branch: whether a side drifted is a coin toss in a settling pile.
            let drifted = (flags[a] | flags[b]) & flag::DRIFTED != 0;
            let from = [exact, anchor][usize::from(drifted)];
            let s = slack(&from[a], &from[b]);
            for q in [a, b] {
                // A quiet side stays quiet while it has not drifted, or while its slack does
                // not drop (it drifted less than half the old one). The flags are read first:
                // a quiet, drifted side is rare when many are loud, while a slack below the
                // side's least so far is a coin toss.
                if flags[q] & (flag::LOUD | flag::PENDING | flag::DRIFTED) == flag::DRIFTED
                    && s < slk[q]
                    && !quiet(drift(&exact[q], &anchor[q]), s)
                {
                    flags[q] |= flag::PENDING;
                    pending.push(q as u32);
                }
                slk[q] = slk[q].min(s);
            }
            exact[a].overlaps(&exact[b])
        };
        let fresh = &self.fresh;
        let cand: &mut [u64] = &mut r.cand;
        let mut j = 0;
        // Where the next new candidate can sort from: past the last touched candidate (one
        // equal to it was that candidate found again).
        let mut lo = 0;
        for t in 0..p.touched.len() {
            let i = p.touched[t] as usize;
            let c = cand[i];
            let key = c & !HIT;
            while j < fresh.len() && fresh[j] < key {
                if insert_new(fresh[j], cand, (lo, i), p, flags, &mut test) {
                    added.push(fresh[j]);
                }
                j += 1;
            }
            lo = i + 1;
            let was = c & HIT != 0;
            let (a, b) = unpack(key);
            let hit = if (flags[a] | flags[b]) & (flag::ESCAPED | flag::GONE) != 0 {
                if j < fresh.len() && fresh[j] == key {
                    j += 1;
                    test(a, b, flags)
                } else {
                    p.cand_gone.push(i as u32);
                    p.rev_keys.push(reverse(a, b));
                    if was {
                        removed.push(key);
                    }
                    continue;
                }
            } else {
                test(a, b, flags)
            };
            if hit != was {
                cand[i] = key | if hit { HIT } else { 0 };
                if hit {
                    added.push(key);
                } else {
                    removed.push(key);
                }
            }
        }
        for &f in &fresh[j..] {
            if insert_new(f, cand, (lo, cand.len()), p, flags, &mut test) {
                added.push(f);
            }
        }
        tested
    }

    /// Patches the candidates, their reverse index (while the lookups read it) and the key
    /// pairs with what [`BroadPhase::retest`] noted, and maps the events to keys.
    fn patch_lists(&mut self, lookup: bool) {
        let Some(r) = &mut self.regime else {
            return;
        };
        let p = &mut r.patch;
        let (added, removed) = (&self.added_packed, &self.removed_packed);
        // The reverse index, kept while the lookups read it: a dropped candidate's entry
        // goes, a new one's comes. A step that scanned leaves it (moving most of its entries
        // costs about what rebuilding it does, and many loud proxies scan step after step).
        if lookup {
            let rev = &mut r.rev;
            let layout = PairBits::for_slots(self.store.slots());
            sort_keys(&mut p.rev_keys, &mut p.keys_tmp, layout);
            seek_sorted(rev, &p.rev_keys, |r, e| r < e, &mut p.rev_gone);
            for &c in &p.cand_new {
                let (a, b) = unpack(c & !HIT);
                p.rev_new.push(reverse(a, b));
            }
            sort_keys(&mut p.rev_new, &mut p.keys_tmp, layout);
            seek_sorted(rev, &p.rev_new, |r, e| r < e, &mut p.rev_at);
            rev.patch(&p.rev_gone, &p.rev_at, &p.rev_new, &mut p.scratch);
        } else {
            r.rev_stale = true;
        }
        r.cand
            .patch(&p.cand_gone, &p.cand_at, &p.cand_new, &mut p.scratch);

        // The key pairs: the changed pairs' places in the old list, which is in the packed
        // pairs' order.
        let below = |q: crate::pair::Pair, k: u64| pack_pair(&q) < k;
        seek_sorted(&self.pairs[..], removed, below, &mut p.pairs_gone);
        seek_sorted(&self.pairs[..], added, below, &mut p.pairs_at);
        keys_into(&self.store, &self.added_packed, &mut self.added);
        keys_into(&self.store, &self.removed_packed, &mut self.removed);
        self.pairs
            .patch(&p.pairs_gone, &p.pairs_at, &self.added, &mut p.scratch);
    }
}

// A new candidate: tested, and inserted where it sorts, which the walk over the
// touched candidates has narrowed to `cand[lo..hi]` (a search of the whole list would
// miss the cache at most of its steps).
fn insert_new(
    f: u64,
    cand: &[u64],
    (lo, hi): (usize, usize),
    p: &mut Patch,
    flags: &mut [u8],
    test: &mut impl FnMut(usize, usize, &mut [u8]) -> bool,
) -> bool {
    let (a, b) = unpack(f);
    let hit = test(a, b, flags);
    let at = lo + cand[lo..hi].partition_point(|&c| c & !HIT < f);
    debug_assert_eq!(at, cand.partition_point(|&c| c & !HIT < f));
    p.cand_at.push(at as u32);
    p.cand_new.push(f | if hit { HIT } else { 0 });
    hit
}

impl BroadPhase {
    /// Classifies the mover `slot`, whose new exact box still lies in its fat box: quiet
    /// (flagged drifted) while it drifted less than half its slack, else loud.
    #[inline]
    pub(super) fn settle(&mut self, slot: u32) {
        let Some(r) = &mut self.regime else {
            return;
        };
        let (s, flags) = (slot as usize, &mut self.store.flags[..]);
        if flags[s] & flag::LOUD != 0 {
            return;
        }
        if stays_quiet(&r.exact[s], &r.anchor[s], r.slack[s]) {
            flags[s] |= flag::DRIFTED;
        } else {
            make_loud(flags, r, &mut self.loud, slot);
        }
    }
}

/// Puts `p.touched` (indices below `cands`) in ascending order, each once. Through the bit map
/// while the candidates are at most [`CANDIDATES_PER_TOUCHED`] per touched one (its words then
/// cost less than a sort), else by the standard library's sort below [`RADIX_FROM`] and the
/// radix sort from there.
fn order_touched(p: &mut Patch, cands: usize) {
    if cands <= p.touched.len() * CANDIDATES_PER_TOUCHED {
        let words = cands.div_ceil(64);
        if p.touched_bits.len() < words {
            p.touched_bits.resize(words, 0);
        }
        let map = &mut p.touched_bits[..words];
        for &i in &p.touched {
            map[i as usize / 64] |= 1 << (i % 64);
        }
        p.touched.clear();
        // Each word is cleared as it is read: the map is empty again for the next step.
        for (k, word) in map.iter_mut().enumerate() {
            let mut bits = core::mem::take(word);
            while bits != 0 {
                p.touched.push((k * 64) as u32 + bits.trailing_zeros());
                bits &= bits - 1;
            }
        }
        return;
    }
    if p.touched.len() < RADIX_FROM {
        p.touched.sort_unstable();
    } else {
        sort_u32_below(&mut p.touched, &mut p.touched_tmp, &mut p.counts, cands);
    }
    p.touched.dedup();
}

/// Sorts packed pairs: by the standard library's sort below [`RADIX_FROM`], by the radix
/// sort from there (`tmp` its second buffer, which may trade places with `keys`).
fn sort_keys(keys: &mut Vec<u64>, tmp: &mut Vec<u64>, layout: PairBits) {
    if keys.len() < RADIX_FROM {
        keys.sort_unstable();
    } else {
        sort_u64(keys, tmp, layout);
    }
}

/// Marks `slot` loud and re-anchors it at its exact box; its slack is found again by the scan.
#[inline]
fn make_loud(flags: &mut [u8], r: &mut Incremental, loud: &mut Vec<u32>, slot: u32) {
    let s = slot as usize;
    flags[s] = flags[s] & !flag::DRIFTED | flag::LOUD;
    loud.push(slot);
    r.anchor[s] = r.exact[s];
    r.slack[s] = f32::MAX;
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
        let unbounded = boxed([f32::NEG_INFINITY; 3], [f32::INFINITY; 3]);
        assert_eq!(drift(&unbounded, &unbounded), 0.0);
        assert_eq!(drift(&unbounded, &a), f32::INFINITY);
        let far = boxed([-f32::MAX; 3], [f32::MAX; 3]);
        let back = boxed([f32::MAX; 3], [f32::MAX; 3]);
        assert_eq!(drift(&far, &back), f32::INFINITY);
        assert!(!quiet(drift(&far, &back), f32::MAX));
    }

    /// `within` is the quiet test without the drift: whenever it says quiet, the drift measured
    /// in `f32` is quiet and, in exact arithmetic, every face moved less than half the slack.
    /// Random boxes and face moves from nothing to past the slack, at slacks from subnormal to
    /// `f32::MAX`; it must also say quiet often (the walk's fast path), and never at infinity.
    #[test]
    fn within_implies_quiet_in_f32_and_in_the_reals() {
        let mut rng = crate::rng::Rng::new(11);
        let (mut said, mut cases) = (0, 0);
        for _ in 0..200_000 {
            let scale = [1e-40f32, 1e-6, 1.0, 1e3, 1e30][rng.below(5) as usize];
            let m = match rng.below(8) {
                0 => 0.0,
                1 => f32::MAX,
                _ => rng.next_f32() * scale,
            };
            let lo = rng.vec3_in(Vec3::splat(-100.0), Vec3::splat(100.0));
            let anchor = boxed(lo.into(), (lo + Vec3::splat(rng.range(0.0, 3.0))).into());
            let mut face = |v: f32| v + (rng.next_f32() - 0.5) * m * rng.range(0.0, 1.5);
            let exact = SimdBox {
                min: Vec3A::from(anchor.min.to_array().map(&mut face)),
                max: Vec3A::from(anchor.max.to_array().map(&mut face)),
            };
            cases += 1;
            if !within(&exact, &anchor, m) {
                continue;
            }
            said += 1;
            assert!(quiet(drift(&exact, &anchor), m), "{exact:?} {anchor:?} {m}");
            for (e, a) in [(exact.min, anchor.min), (exact.max, anchor.max)] {
                for k in 0..3 {
                    let moved = (f64::from(e[k]) - f64::from(a[k])).abs();
                    assert!(moved + moved < f64::from(m), "{e} {a} {m}");
                }
            }
        }
        assert!(
            said > cases / 10,
            "the fast test said quiet {said} of {cases} times"
        );
        let a = boxed([0.0; 3], [1.0; 3]);
        let unbounded = boxed([f32::NEG_INFINITY; 3], [f32::INFINITY; 3]);
        assert!(!within(&unbounded, &unbounded, f32::MAX));
        assert!(!within(&a, &a, 0.0));
        assert!(within(&a, &a, f32::MIN_POSITIVE));
    }

    /// A sorted list of fewer than `len` values below `values`, with repeats.
    fn sorted_list(rng: &mut crate::rng::Rng, len: u32, values: u32) -> Vec<u64> {
        let n = rng.below(len);
        let mut list: Vec<u64> = (0..n).map(|_| u64::from(rng.below(values))).collect();
        list.sort_unstable();
        list
    }

    /// `seek` from any hint, in or out of range, is `partition_point`, on sorted lists with
    /// repeats, at every split point including both ends.
    #[test]
    fn seek_from_any_hint_is_the_partition_point() {
        let mut rng = crate::rng::Rng::new(5);
        for _ in 0..2000 {
            let list = sorted_list(&mut rng, 70, 40);
            let n = list.len();
            for key in 0..42u64 {
                let want = list.partition_point(|&e| e < key);
                let hint = rng.below(n as u32 + 5) as usize;
                assert_eq!(
                    seek(&list, hint, |e| e < key),
                    want,
                    "{list:?} {key} {hint}"
                );
            }
        }
    }

    /// `order_touched` leaves the indices ascending and each once, through the bit map (many
    /// touched among few candidates) and through the sorts (few among many, and past
    /// `RADIX_FROM`), and leaves the map clear for the next step.
    #[test]
    fn touched_candidates_come_out_ascending_and_once() {
        let mut rng = crate::rng::Rng::new(7);
        let mut p = Patch::default();
        for round in 0..3000 {
            let cands = 1 + rng.below(if round % 10 == 0 { 3_000_000 } else { 5000 }) as usize;
            let n = match round % 3 {
                0 => rng.below(8),
                1 => rng.below(200),
                _ => rng.below(5000),
            };
            let mut touched: Vec<u32> = (0..n).map(|_| rng.below(cands as u32)).collect();
            if round % 2 == 0 {
                // A pair of two loud sides is listed twice.
                touched.extend_from_within(..touched.len() / 2);
            }
            let mut want = touched.clone();
            want.sort_unstable();
            want.dedup();
            p.touched.clone_from(&touched);
            order_touched(&mut p, cands);
            assert_eq!(p.touched, want, "round {round}: {cands} candidates");
            assert!(p.touched_bits.iter().all(|&w| w == 0), "round {round}");
        }
    }

    /// `seek_sorted` gives each key its `partition_point`, for keys in ascending order (as
    /// the patches give them, repeats included) and in any order.
    #[test]
    fn seek_sorted_is_the_partition_point_of_each_key() {
        let mut rng = crate::rng::Rng::new(6);
        for round in 0..1000 {
            let list = sorted_list(&mut rng, 90, 60);
            let mut keys: Vec<u64> = (0..rng.below(30))
                .map(|_| u64::from(rng.below(64)))
                .collect();
            if round % 2 == 0 {
                keys.sort_unstable();
            }
            let mut got = Vec::new();
            seek_sorted(&list, &keys, |e, k| e < k, &mut got);
            let want: Vec<u32> = keys
                .iter()
                .map(|&k| list.partition_point(|&e| e < k) as u32)
                .collect();
            assert_eq!(got, want, "{list:?} {keys:?}");
        }
    }
}
