//! Proxy keys, canonical pairs, sorted pair lists and their difference (added / removed).

slotmap::new_key_type! {
    /// A handle to one proxy (sphere or body) of a structure. A removed proxy's key is never
    /// valid again in that structure (slotmap versioning), so a stale key is refused with
    /// [`Error::UnknownProxy`](crate::Error::UnknownProxy) instead of naming a newer proxy.
    pub struct ProxyKey;
}

/// Two proxies whose boxes overlap, in canonical order: `a < b`.
///
/// Ordering is by `(a, b)`, keys ordered by slot index, so a sorted pair list is
/// deterministic for a deterministic sequence of operations.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Pair {
    /// The smaller key.
    pub a: ProxyKey,
    /// The larger key.
    pub b: ProxyKey,
}

impl Pair {
    /// The canonical pair of two distinct keys, whichever order they come in.
    #[must_use]
    #[inline]
    pub fn new(x: ProxyKey, y: ProxyKey) -> Self {
        debug_assert_ne!(x, y, "a proxy never pairs with itself");
        // The smaller and larger rank as integer min and max: which key is smaller is a coin
        // toss in a traversal, so a branch here would mispredict half the time (a select of
        // the two keys compiles to one in some inlined contexts).
        let (rx, ry) = (key_rank(x), key_rank(y));
        Pair {
            a: key_of_rank(rx.min(ry)),
            b: key_of_rank(rx.max(ry)),
        }
    }
}

/// The key of a [`key_rank`]: every key's version is odd, which `from_ffi` keeps as it is.
#[inline]
fn key_of_rank(rank: u64) -> ProxyKey {
    slotmap::KeyData::from_ffi(rank.rotate_right(32)).into()
}

/// A key's place in the key order as one integer: keys order by `(slot index, version)`
/// and `as_ffi()` is `version << 32 | slot`, so swapping the halves gives `slot << 32 |
/// version`.
#[inline]
fn key_rank(k: ProxyKey) -> u64 {
    use slotmap::Key;
    k.data().as_ffi().rotate_left(32)
}

/// A key's slot index: the low 32 bits of `as_ffi()` (slotmap 1.x: `(version << 32) | idx`).
/// Keys order by `(idx, version)`, slot index first; `tests::slot_index_orders_live_keys`
/// pins this layout down against slotmap.
#[inline]
pub(crate) fn slot(k: ProxyKey) -> u32 {
    use slotmap::Key;
    k.data().as_ffi() as u32
}

/// Sorts pair lists by `(a, b)`, exactly as `sort_unstable` would, reusing its buffers: after
/// the first few steps sorting allocates nothing.
#[derive(Clone, Debug, Default)]
pub struct PairSorter {
    /// The second buffer of the scatter pass.
    scratch: Vec<Pair>,
    /// Per slot index: where its bucket starts, then (after a scatter) where it ends.
    starts: Vec<u32>,
}

/// Lists shorter than this are sorted by comparison.
const COUNTING_MIN: usize = 256;

impl PairSorter {
    /// A sorter with empty buffers.
    #[must_use]
    pub fn new() -> Self {
        Self::default()
    }

    /// Sorts `pairs` by `(a, b)`.
    ///
    /// Two stable counting sorts (LSD radix): by `b`'s slot index, then by `a`'s. Keys order
    /// by `(slot index, version)`, and the live keys of one slot map have distinct slot
    /// indices, so for them this is the full order: two streaming passes over the pairs and
    /// two over the slot range, no comparisons. A last pass checks the order with one integer
    /// compare per pair and falls back to a comparison sort when keys of one slot with
    /// different versions left it wrong, so the result is exact for any keys.
    pub fn sort(&mut self, pairs: &mut [Pair]) {
        let n = pairs.len();
        if n < COUNTING_MIN {
            pairs.sort_unstable();
            return;
        }
        let max = pairs
            .iter()
            .map(|p| slot(p.a).max(slot(p.b)))
            .max()
            .unwrap_or(0) as usize;
        self.scratch.clear();
        self.scratch.resize(n, pairs[0]);
        counting_pass(pairs, &mut self.scratch, &mut self.starts, max, |p| {
            slot(p.b)
        });
        counting_pass(&self.scratch, pairs, &mut self.starts, max, |p| slot(p.a));
        if !pairs.windows(2).all(|w| rank(&w[0]) <= rank(&w[1])) {
            pairs.sort_unstable();
        }
        debug_assert!(pairs.windows(2).all(|w| w[0] <= w[1]));
    }
}

/// One stable counting sort of `from` into `to` by `digit` (at most `max`), with `starts`
/// as the bucket table.
#[inline]
fn counting_pass(
    from: &[Pair],
    to: &mut [Pair],
    starts: &mut Vec<u32>,
    max: usize,
    digit: impl Fn(&Pair) -> u32,
) {
    starts.clear();
    starts.resize(max + 2, 0);
    for p in from {
        starts[digit(p) as usize + 1] += 1;
    }
    for i in 1..starts.len() {
        starts[i] += starts[i - 1];
    }
    for p in from {
        let s = &mut starts[digit(p) as usize];
        to[*s as usize] = *p;
        *s += 1;
    }
}

/// The pair order `(a, b)` as one integer (see [`key_rank`]).
#[inline]
fn rank(p: &Pair) -> u128 {
    (u128::from(key_rank(p.a)) << 64) | u128::from(key_rank(p.b))
}

/// Sorts a pair list by `(a, b)` and removes duplicates, in place.
pub fn sort_dedup(pairs: &mut Vec<Pair>) {
    pairs.sort_unstable();
    pairs.dedup();
}

/// The exact set differences of two sorted, deduplicated pair lists: `added = cur \ prev`,
/// `removed = prev \ cur`, both sorted. The output vectors are cleared first and reused.
///
/// One merge pass: walk both lists in order; a pair smaller than the other list's head exists
/// only on its own side, equal heads exist on both and advance together. O(|prev| + |cur|).
pub fn diff(prev: &[Pair], cur: &[Pair], added: &mut Vec<Pair>, removed: &mut Vec<Pair>) {
    added.clear();
    removed.clear();
    let (mut i, mut j) = (0, 0);
    while i < prev.len() && j < cur.len() {
        match prev[i].cmp(&cur[j]) {
            core::cmp::Ordering::Less => {
                removed.push(prev[i]);
                i += 1;
            }
            core::cmp::Ordering::Greater => {
                added.push(cur[j]);
                j += 1;
            }
            core::cmp::Ordering::Equal => {
                i += 1;
                j += 1;
            }
        }
    }
    removed.extend_from_slice(&prev[i..]);
    added.extend_from_slice(&cur[j..]);
}

#[cfg(test)]
mod tests {
    use super::*;
    use slotmap::{Key, SlotMap};
    use std::collections::BTreeSet;

    #[test]
    fn pair_is_canonical() {
        let mut sm = SlotMap::<ProxyKey, ()>::with_key();
        let x = sm.insert(());
        let y = sm.insert(());
        assert_eq!(Pair::new(x, y), Pair::new(y, x));
        assert!(Pair::new(y, x).a < Pair::new(y, x).b);
    }

    #[test]
    fn slot_index_orders_live_keys() {
        // Churn the slot map so versions differ, then check that on live keys the slot index
        // (low bits of `as_ffi`) orders exactly as `Ord`, and that distinct live keys never
        // share a slot: the premise of `sort`'s radix key.
        let mut sm = SlotMap::<ProxyKey, ()>::with_key();
        let mut live: Vec<ProxyKey> = (0..500).map(|_| sm.insert(())).collect();
        for round in 0..5 {
            live.retain(|&k| {
                let keep = slot(k) % (round + 2) != 0;
                if !keep {
                    sm.remove(k);
                }
                keep
            });
            live.extend((0..200).map(|_| sm.insert(())));
        }
        let mut by_ord = live.clone();
        by_ord.sort_unstable();
        let mut by_slot = live.clone();
        by_slot.sort_unstable_by_key(|&k| slot(k));
        assert_eq!(by_ord, by_slot);
        assert!(by_slot.windows(2).all(|w| slot(w[0]) < slot(w[1])));
        assert!(
            live.iter().any(|k| k.data().as_ffi() >> 32 > 1),
            "versions were bumped"
        );
    }

    #[test]
    fn key_rank_orders_like_ord() {
        let mut sm = SlotMap::<ProxyKey, ()>::with_key();
        let mut keys: Vec<ProxyKey> = (0..40).map(|_| sm.insert(())).collect();
        for &k in keys.clone().iter().step_by(3) {
            sm.remove(k);
        }
        keys.extend((0..20).map(|_| sm.insert(())));
        assert!(
            keys.iter().any(|k| k.data().as_ffi() >> 32 > 1),
            "versions bumped"
        );
        for &x in &keys {
            for &y in &keys {
                assert_eq!(key_rank(x).cmp(&key_rank(y)), x.cmp(&y), "{x:?} vs {y:?}");
                if x != y {
                    let p = Pair::new(x, y);
                    assert!(p.a < p.b && p == Pair::new(y, x));
                }
            }
        }
    }

    #[test]
    fn pair_sorter_equals_sort_unstable() {
        let mut sm = SlotMap::<ProxyKey, ()>::with_key();
        let keys: Vec<_> = (0..3000).map(|_| sm.insert(())).collect();
        let mut seed = 11u32;
        let mut next = || {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (seed >> 8) as usize
        };
        let mut sorter = PairSorter::new();
        for len in [0, 1, 255, 256, 5000, 40_000] {
            let mut pairs: Vec<Pair> = (0..len)
                .filter_map(|_| {
                    let (i, j) = (next() % keys.len(), next() % keys.len());
                    (i != j).then(|| Pair::new(keys[i], keys[j]))
                })
                .collect();
            let mut want = pairs.clone();
            want.sort_unstable();
            sorter.sort(&mut pairs);
            assert_eq!(pairs, want);
        }
        // Keys of two slot maps may share a slot (same index, other version): still `Ord`.
        let mut other = SlotMap::<ProxyKey, ()>::with_key();
        other.insert(());
        let stale = other.insert(());
        other.remove(stale);
        let bumped = other.insert(());
        let mut pairs: Vec<Pair> = (0..300)
            .map(|i| Pair::new(keys[i % 7 + 10], if i % 2 == 0 { keys[1] } else { bumped }))
            .collect();
        let mut want = pairs.clone();
        want.sort_unstable();
        sorter.sort(&mut pairs);
        assert_eq!(pairs, want);
    }

    #[test]
    fn diff_equals_set_difference() {
        let mut sm = SlotMap::<ProxyKey, ()>::with_key();
        let keys: Vec<_> = (0..12).map(|_| sm.insert(())).collect();
        let mut seed = 7u32;
        let mut next = || {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (seed >> 16) as usize
        };
        for _ in 0..200 {
            let mut lists: [Vec<Pair>; 2] = Default::default();
            for list in &mut lists {
                for _ in 0..next() % 30 {
                    let (i, j) = (next() % 12, next() % 12);
                    if i != j {
                        list.push(Pair::new(keys[i], keys[j]));
                    }
                }
                sort_dedup(list);
            }
            let (mut added, mut removed) = (Vec::new(), Vec::new());
            diff(&lists[0], &lists[1], &mut added, &mut removed);
            let p: BTreeSet<_> = lists[0].iter().copied().collect();
            let c: BTreeSet<_> = lists[1].iter().copied().collect();
            assert_eq!(added, c.difference(&p).copied().collect::<Vec<_>>());
            assert_eq!(removed, p.difference(&c).copied().collect::<Vec<_>>());
        }
    }
}
