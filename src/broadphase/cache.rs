//! The pair cache of a [`BroadPhase`](super::BroadPhase) with [`Config::skin`](super::Config)
//! `> 0`: Verlet lists for a broadphase.
//!
//! The octree and the BVHs hold every proxy's **fat** box: its exact box (margin included)
//! grown by the skin when it was last placed. A proxy whose exact box stays inside its fat
//! box does not touch the structures at all. The cache keeps every **candidate** pair, two
//! proxies whose fat boxes overlap (never static×static), sorted by `(a, b)`. Since an exact
//! box lies inside its fat box, every overlapping pair is a candidate, and one pass over the
//! candidates testing their exact boxes gives this step's pairs in order, and, with a bit per
//! candidate saying whether it was a pair last step, `added` and `removed` in the same pass.
//!
//! When proxies are inserted, removed or leave their fat box ("marked"), the candidates that
//! name a marked proxy are dropped and the marked proxies' fat boxes are queried in the
//! structures again; when many are marked, the structures' own pair passes regenerate the
//! whole list instead.
//!
//! The list is not rewritten for a few marked proxies: a dropped candidate becomes a
//! tombstone in place, and new candidates go to a small sorted side list that the filter
//! merges in on the fly (each side entry knows where it falls in the main list). When
//! tombstones or side entries pass an eighth of the list, one merge compacts both.

use crate::geom::SimdBox as PrimBox;
use crate::pair::{Pair, slot};
use crate::{Aabb, ProxyKey};

/// Bits of a candidate's state byte.
const HOT: u8 = 1;
/// The candidate was dropped (tombstone); it is skipped until the next compaction.
const DEAD: u8 = 2;

/// Candidates, exact and fat boxes per slot, and the proxies marked since the last step.
#[derive(Clone, Debug, Default)]
pub(crate) struct PairCache {
    /// How far the fat boxes reach past the exact ones, on every side; `> 0`.
    skin: f32,
    /// Per slot index: the exact box (margin included) of the proxy living in that slot, in
    /// SIMD lanes for the filter.
    exact: Vec<PrimBox>,
    /// Per slot index: the fat box the structures hold for that proxy.
    fat: Vec<PrimBox>,
    /// Per slot index: marked since the last step.
    marked: Vec<bool>,
    /// Keys marked since the last step: inserted, removed, or given a new fat box. A key
    /// appears once; a slot twice only if its proxy was removed and the slot reused.
    dirty: Vec<ProxyKey>,
    /// Per entry of `dirty`: the fat box its candidates were found with (the one before it
    /// was marked; empty for an insert).
    old_fat: Vec<Aabb>,
    /// Candidates `(x, k)` with `x < k` of the marked keys `k`, as the caller found them by
    /// querying `old_fat` (the ones `(k, y)` are a range of the main list): to drop.
    pub(crate) stale: Vec<Pair>,
    /// The main candidate list, sorted by `(a, b)`, tombstones included.
    cand: Vec<Pair>,
    /// Per main entry: `HOT` if its exact boxes overlapped at the last step (it is in
    /// `pairs`), `DEAD` for a tombstone.
    state: Vec<u8>,
    /// Tombstones in `cand`.
    dead: usize,
    /// The side list: candidates added since the last compaction, sorted, disjoint from the
    /// live main entries.
    extra: Vec<Pair>,
    /// Per side entry: `HOT` or 0.
    extra_state: Vec<u8>,
    /// Per side entry: the index of the first main entry after it.
    extra_at: Vec<u32>,
    /// New candidates of marked proxies (the caller fills it), sorted and unique after
    /// [`PairCache::step`] took them in.
    pub(crate) fresh: Vec<Pair>,
    fresh_state: Vec<u8>,
    /// Pairs of the last step whose candidate left the side list this step, for `removed`.
    late: Vec<Pair>,
    /// Merge buffers.
    merged: Vec<Pair>,
    merged_state: Vec<u8>,
}

impl PairCache {
    /// An empty cache whose fat boxes reach `skin` past the exact ones.
    pub(crate) fn new(skin: f32) -> Self {
        Self {
            skin,
            ..Self::default()
        }
    }

    /// The skin, `> 0`.
    pub(crate) fn skin(&self) -> f32 {
        self.skin
    }

    /// True if the fat box no longer fits `exact`: the exact box left it, or shrank so far
    /// that the fat box is more than two skins wider on some axis than a fresh one would be
    /// (kept, it would only add candidates).
    #[inline]
    pub(crate) fn needs_new_fat(&self, key: ProxyKey, exact: &PrimBox) -> bool {
        let fat = &self.fat[slot(key) as usize];
        let slack = fat.extent() - exact.extent();
        !fat.contains(exact) || slack.max_element() > 4.0 * self.skin
    }

    /// Stores the exact box of a proxy whose fat box still fits.
    #[inline]
    pub(crate) fn set_exact(&mut self, key: ProxyKey, exact: PrimBox) {
        self.exact[slot(key) as usize] = exact;
    }

    /// The exact box stored for `key` (which must be live).
    #[inline]
    pub(crate) fn exact(&self, key: ProxyKey) -> Aabb {
        self.exact[slot(key) as usize].aabb()
    }

    /// The fat box stored for `key` (which must be live).
    #[inline]
    pub(crate) fn fat(&self, key: ProxyKey) -> Aabb {
        self.fat[slot(key) as usize].aabb()
    }

    /// Records a new proxy with its exact and fat boxes.
    pub(crate) fn insert(&mut self, key: ProxyKey, exact: PrimBox, fat: &Aabb) {
        let s = slot(key) as usize;
        if s >= self.exact.len() {
            self.exact.resize(s + 1, PrimBox::EMPTY);
            self.fat.resize(s + 1, PrimBox::EMPTY);
            self.marked.resize(s + 1, false);
        }
        self.exact[s] = exact;
        self.fat[s] = PrimBox::new(fat);
        self.marked[s] = true;
        self.dirty.push(key);
        self.old_fat.push(Aabb::EMPTY);
    }

    /// Records a proxy's new exact box and the new fat box the structures now hold for it.
    pub(crate) fn refat(&mut self, key: ProxyKey, exact: PrimBox, fat: &Aabb) {
        self.mark(key);
        let s = slot(key) as usize;
        self.exact[s] = exact;
        self.fat[s] = PrimBox::new(fat);
    }

    /// Records that `key` was removed: its candidates go at the next step.
    pub(crate) fn remove(&mut self, key: ProxyKey) {
        self.mark(key);
    }

    fn mark(&mut self, key: ProxyKey) {
        let s = slot(key) as usize;
        if !self.marked[s] {
            self.marked[s] = true;
            self.dirty.push(key);
            self.old_fat.push(self.fat[s].aabb());
        }
    }

    /// The keys marked since the last step (some may be dead by now).
    pub(crate) fn dirty(&self) -> &[ProxyKey] {
        &self.dirty
    }

    /// The keys marked since the last step, each with the fat box its current candidates
    /// were found with.
    pub(crate) fn marked_with_old_fat(&self) -> impl Iterator<Item = (ProxyKey, &Aabb)> {
        self.dirty.iter().copied().zip(&self.old_fat)
    }

    /// This step's `pairs`, `added` and `removed` (all sorted; the vectors are cleared
    /// first), bringing the candidates up to date on the way. `prev` is the last step's pair
    /// list, `fresh` was filled by the caller: with `full`, every candidate (sorted, unique);
    /// otherwise the candidates of the marked proxies (any order, duplicates allowed).
    pub(crate) fn step(
        &mut self,
        full: bool,
        prev: &[Pair],
        pairs: &mut Vec<Pair>,
        added: &mut Vec<Pair>,
        removed: &mut Vec<Pair>,
    ) {
        pairs.clear();
        added.clear();
        removed.clear();
        let mut out = Out {
            pairs,
            added,
            removed,
        };
        self.late.clear();
        if full {
            self.regenerate(prev);
            self.pass(&mut out);
        } else if self.dirty.is_empty() {
            self.pass(&mut out);
        } else {
            self.take_fresh(prev);
            self.drop_marked();
            self.pass(&mut out);
        }
        for &key in &self.dirty {
            self.marked[slot(key) as usize] = false;
        }
        self.dirty.clear();
        self.old_fat.clear();
        self.stale.clear();
        if !self.late.is_empty() {
            // Both sorted and disjoint (a late pair is no candidate any more): merge.
            self.late.sort_unstable();
            self.merged.clear();
            let mut j = 0;
            for &p in &self.late {
                while j < out.removed.len() && out.removed[j] < p {
                    self.merged.push(out.removed[j]);
                    j += 1;
                }
                self.merged.push(p);
            }
            self.merged.extend_from_slice(&out.removed[j..]);
            out.removed.clear();
            out.removed.extend_from_slice(&self.merged);
        }
        if (self.dead + self.extra.len()).saturating_mul(8) > self.cand.len() {
            self.compact();
        }
        // Room for a half more candidates in every buffer that may hold them all: the count
        // wanders from step to step, and steady steps should not allocate.
        let n = self.cand.len() + self.extra.len();
        headroom(&mut self.cand, n);
        headroom(&mut self.state, n);
        headroom(&mut self.merged, n);
        headroom(&mut self.merged_state, n);
        headroom(&mut self.fresh, n);
        // The side list and the patch lists stay below an eighth of the list or so.
        let side = n / 4;
        headroom(&mut self.extra, side);
        headroom(&mut self.extra_state, side);
        headroom(&mut self.extra_at, side);
        headroom(&mut self.fresh_state, side);
        headroom(&mut self.stale, side);
        headroom(&mut self.late, side);
    }

    /// Many proxies marked: `fresh`, the whole candidate set, replaces the lists. A
    /// candidate is hot iff `prev` holds it; the pairs of `prev` no candidate matches are late.
    fn regenerate(&mut self, prev: &[Pair]) {
        // Copied, not swapped: every buffer keeps one role, so its capacity only grows at a
        // new peak and steady steps allocate nothing.
        self.cand.clear();
        self.cand.extend_from_slice(&self.fresh);
        self.fresh.clear();
        self.dead = 0;
        self.extra.clear();
        self.extra_state.clear();
        self.extra_at.clear();
        self.state.clear();
        let mut i = 0;
        for p in &self.cand {
            while i < prev.len() && prev[i] < *p {
                self.late.push(prev[i]);
                i += 1;
            }
            let h = i < prev.len() && prev[i] == *p;
            i += usize::from(h);
            self.state.push(if h { HOT } else { 0 });
        }
        self.late.extend_from_slice(&prev[i..]);
    }

    /// A few proxies marked: the side list loses its entries naming a marked slot (their
    /// pairs of the last step go to `late` unless fresh again) and takes in `fresh`, each
    /// hot iff `prev` holds it. The main list's entries naming a marked slot are dropped by
    /// the pass that follows.
    fn take_fresh(&mut self, prev: &[Pair]) {
        self.fresh.sort_unstable();
        self.fresh.dedup();
        self.fresh_state.clear();
        self.fresh_state.extend(self.fresh.iter().map(|p| {
            if prev.binary_search(p).is_ok() {
                HOT
            } else {
                0
            }
        }));
        self.merged.clear();
        self.merged_state.clear();
        let marked = &self.marked;
        let (mut e, mut f) = (0, 0);
        while e < self.extra.len() || f < self.fresh.len() {
            let take_fresh =
                e == self.extra.len() || (f < self.fresh.len() && self.fresh[f] < self.extra[e]);
            if take_fresh {
                self.merged.push(self.fresh[f]);
                self.merged_state.push(self.fresh_state[f]);
                f += 1;
                continue;
            }
            let (p, st) = (self.extra[e], self.extra_state[e]);
            e += 1;
            if marked[slot(p.a) as usize] || marked[slot(p.b) as usize] {
                if st & HOT != 0 && self.fresh.binary_search(&p).is_err() {
                    self.late.push(p);
                }
            } else {
                self.merged.push(p);
                self.merged_state.push(st);
            }
        }
        self.extra.clear();
        self.extra.extend_from_slice(&self.merged);
        self.extra_state.clear();
        self.extra_state.extend_from_slice(&self.merged_state);
        self.extra_at.clear();
        let cand = &self.cand;
        self.extra_at.extend(
            self.extra
                .iter()
                .map(|p| cand.partition_point(|q| q < p) as u32),
        );
    }

    /// Makes tombstones of the main entries naming a marked key: `(k, y)` is the range of
    /// main entries whose first key is `k`, `(x, k)` is in `stale`. A dropped pair of the last
    /// step is late (removed this step) unless fresh again.
    fn drop_marked(&mut self) {
        let (cand, state, fresh) = (&self.cand, &mut self.state, &self.fresh);
        let (late, dead) = (&mut self.late, &mut self.dead);
        let mut tomb = |i: usize| {
            if state[i] & DEAD == 0 {
                if state[i] & HOT != 0 && fresh.binary_search(&cand[i]).is_err() {
                    late.push(cand[i]);
                }
                state[i] = DEAD;
                *dead += 1;
            }
        };
        for &key in &self.dirty {
            let lo = cand.partition_point(|q| q.a < key);
            let hi = lo + cand[lo..].partition_point(|q| q.a == key);
            (lo..hi).for_each(&mut tomb);
        }
        for p in &self.stale {
            let i = cand.partition_point(|q| q < p);
            if cand.get(i) == Some(p) {
                tomb(i);
            }
        }
    }

    /// Tests every live candidate, main and side list merged in order, and files it.
    fn pass(&mut self, out: &mut Out<'_>) {
        let exact = &self.exact;
        out.pairs.reserve(self.cand.len() + self.extra.len());
        let mut lo = 0;
        for j in 0..=self.extra.len() {
            let hi = self
                .extra_at
                .get(j)
                .map_or(self.cand.len(), |&at| at as usize);
            for (p, st) in self.cand[lo..hi].iter().zip(&mut self.state[lo..hi]) {
                if *st & DEAD == 0 {
                    let now = exact[slot(p.a) as usize].overlaps(&exact[slot(p.b) as usize]);
                    out.file(*p, now, st);
                }
            }
            if let (Some(p), Some(st)) = (self.extra.get(j), self.extra_state.get_mut(j)) {
                let now = exact[slot(p.a) as usize].overlaps(&exact[slot(p.b) as usize]);
                out.file(*p, now, st);
            }
            lo = hi;
        }
    }

    /// Merges the live main entries and the side list into a new main list.
    fn compact(&mut self) {
        self.merged.clear();
        self.merged_state.clear();
        let mut e = 0;
        for (&p, &st) in self.cand.iter().zip(&self.state) {
            while e < self.extra.len() && self.extra[e] < p {
                self.merged.push(self.extra[e]);
                self.merged_state.push(self.extra_state[e]);
                e += 1;
            }
            if st & DEAD == 0 {
                self.merged.push(p);
                self.merged_state.push(st);
            }
        }
        self.merged.extend_from_slice(&self.extra[e..]);
        self.merged_state.extend_from_slice(&self.extra_state[e..]);
        self.cand.clear();
        self.cand.extend_from_slice(&self.merged);
        self.state.clear();
        self.state.extend_from_slice(&self.merged_state);
        self.extra.clear();
        self.extra_state.clear();
        self.extra_at.clear();
        self.dead = 0;
    }

    /// Every live candidate with its hot bit, in order.
    fn live(&self) -> Vec<(Pair, bool)> {
        let mut all: Vec<(Pair, bool)> = self
            .cand
            .iter()
            .zip(&self.state)
            .filter(|(_, st)| **st & DEAD == 0)
            .map(|(p, st)| (*p, *st & HOT != 0))
            .chain(
                self.extra
                    .iter()
                    .zip(&self.extra_state)
                    .map(|(p, st)| (*p, *st & HOT != 0)),
            )
            .collect();
        all.sort_unstable_by_key(|x| x.0);
        all
    }

    /// Checks the cache (for `BroadPhase::validate`): both lists sorted, the live candidates
    /// unique, live keys only, fat boxes overlapping, the side list's positions right, the
    /// tombstone count right; with nothing marked, the hot candidates are exactly `pairs`
    /// (the last step's). `is_live` says whether a key is live.
    pub(crate) fn validate(&self, is_live: impl Fn(ProxyKey) -> bool, pairs: &[Pair]) {
        assert_eq!(
            self.cand.len(),
            self.state.len(),
            "cache: state bytes out of step"
        );
        assert_eq!(self.extra.len(), self.extra_state.len(), "cache: side bits");
        assert_eq!(
            self.extra.len(),
            self.extra_at.len(),
            "cache: side positions"
        );
        assert!(
            self.cand.windows(2).all(|w| w[0] <= w[1]),
            "cache: main unsorted"
        );
        assert!(
            self.extra.windows(2).all(|w| w[0] < w[1]),
            "cache: side unsorted"
        );
        for (p, &at) in self.extra.iter().zip(&self.extra_at) {
            assert_eq!(
                at as usize,
                self.cand.partition_point(|q| q < p),
                "cache: side at"
            );
        }
        let dead = self.state.iter().filter(|st| **st & DEAD != 0).count();
        assert_eq!(dead, self.dead, "cache: tombstone count");
        let live = self.live();
        assert!(
            live.windows(2).all(|w| w[0].0 < w[1].0),
            "cache: a candidate twice"
        );
        for (p, _) in &live {
            let (a, b) = (slot(p.a) as usize, slot(p.b) as usize);
            if self.marked[a] || self.marked[b] {
                continue;
            }
            assert!(
                is_live(p.a) && is_live(p.b),
                "cache: candidate {p:?} names a dead key"
            );
            assert!(
                self.fat[a].overlaps(&self.fat[b]),
                "cache: candidate {p:?} whose fat boxes do not overlap"
            );
        }
        if self.dirty.is_empty() {
            let hot: Vec<Pair> = live.iter().filter(|(_, h)| *h).map(|(p, _)| *p).collect();
            assert_eq!(
                hot, pairs,
                "cache: hot candidates differ from the last pairs"
            );
        }
        assert!(self.marked.iter().filter(|m| **m).count() <= self.dirty.len());
    }

    /// True if `pair` is a live candidate (for validation).
    pub(crate) fn is_candidate(&self, pair: &Pair) -> bool {
        let main = self.cand.partition_point(|q| q < pair);
        let in_main = self.cand.get(main) == Some(pair) && self.state[main] & DEAD == 0;
        in_main || self.extra.binary_search(pair).is_ok()
    }
}

/// Grows `v`'s capacity to half again `n` when it is below `n`.
fn headroom<T>(v: &mut Vec<T>, n: usize) {
    if v.capacity() < n {
        v.reserve(n + n / 2 - v.len());
    }
}

/// The three output lists of a step.
struct Out<'a> {
    pairs: &'a mut Vec<Pair>,
    added: &'a mut Vec<Pair>,
    removed: &'a mut Vec<Pair>,
}

impl Out<'_> {
    /// Files one tested candidate: into `pairs` if its boxes overlap (`now`), into `added`
    /// or `removed` if that differs from its state byte's `HOT` (last step), which becomes
    /// `now`.
    #[inline(always)]
    fn file(&mut self, p: Pair, now: bool, state: &mut u8) {
        // Pushed always and kept only if it overlaps: about a fifth of a pile's candidates
        // do not, in no pattern a branch predictor could follow.
        let len = self.pairs.len();
        self.pairs.push(p);
        self.pairs.truncate(len + usize::from(now));
        let was = *state & HOT != 0;
        if now != was {
            if now {
                self.added.push(p);
            } else {
                self.removed.push(p);
            }
            *state = u8::from(now);
        }
    }
}
