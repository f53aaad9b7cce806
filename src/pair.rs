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
pub fn diff<T: Ord + Copy>(prev: &[T], cur: &[T], added: &mut Vec<T>, removed: &mut Vec<T>) {
    diff_mapped(prev, |&p| p, cur, added, removed);
}

/// [`diff`] of `prev` read through `map`, which keeps its order: `prev` mapped must be
/// sorted and deduplicated.
pub(crate) fn diff_mapped<P, T: Ord + Copy>(
    prev: &[P],
    map: impl Fn(&P) -> T,
    cur: &[T],
    added: &mut Vec<T>,
    removed: &mut Vec<T>,
) {
    added.clear();
    removed.clear();
    let (mut i, mut j) = (0, 0);
    while i < prev.len() && j < cur.len() {
        let p = map(&prev[i]);
        match p.cmp(&cur[j]) {
            core::cmp::Ordering::Less => {
                removed.push(p);
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
    removed.extend(prev[i..].iter().map(map));
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
            // The same difference with `prev` read through an order-keeping map (the slot
            // pairs of these keys, whose versions are all 1).
            let slots = |q: &Pair| (slot(q.a), slot(q.b));
            let cur_slots: Vec<_> = lists[1].iter().map(slots).collect();
            let (mut added_slots, mut removed_slots) = (Vec::new(), Vec::new());
            diff_mapped(
                &lists[0],
                slots,
                &cur_slots,
                &mut added_slots,
                &mut removed_slots,
            );
            assert_eq!(added_slots, added.iter().map(slots).collect::<Vec<_>>());
            assert_eq!(removed_slots, removed.iter().map(slots).collect::<Vec<_>>());
        }
    }
}
