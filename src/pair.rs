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
        if x < y {
            Pair { a: x, b: y }
        } else {
            Pair { a: y, b: x }
        }
    }
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
    use slotmap::SlotMap;
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
