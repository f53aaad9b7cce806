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

/// Bits per digit of [`sort`]'s radix passes.
const RADIX_BITS: u32 = 11;
/// Lists shorter than this are sorted by comparison.
const RADIX_MIN: usize = 256;

/// A key's slot index: the low 32 bits of `as_ffi()` (slotmap 1.x: `(version << 32) | idx`).
/// Keys order by `(idx, version)`, and two live keys of one slot map never share an index, so
/// among live keys the slot index alone orders them; `tests::slot_index_orders_live_keys`
/// pins this down against slotmap.
#[inline]
fn slot(k: ProxyKey) -> u32 {
    use slotmap::Key;
    k.data().as_ffi() as u32
}

/// Sorts a pair list by `(a, b)`, exactly as `pairs.sort_unstable()` would; `scratch` is
/// reused and never shrinks.
///
/// LSD radix sort on `(slot(a), slot(b))`, the key's slot indices: a few streaming passes of
/// 11-bit digits over only the bits the largest index uses, skipping digits every pair shares.
/// This equals the pairs' `Ord` when no two distinct keys share a slot (true for the live keys
/// of one slot map, e.g. a step's pairs); a final O(n) check falls back to a comparison sort
/// if that does not hold, so the result is always sorted.
pub fn sort(pairs: &mut Vec<Pair>, scratch: &mut Vec<Pair>) {
    let n = pairs.len();
    let max = pairs.iter().fold(0, |m, p| m | slot(p.a) | slot(p.b));
    let bits = 32 - max.leading_zeros();
    if n < RADIX_MIN || bits == 0 {
        pairs.sort_unstable();
        return;
    }
    let per_key = bits.div_ceil(RADIX_BITS);
    let width = bits.div_ceil(per_key);
    let radix = 1usize << width;
    let mask = (radix - 1) as u32;
    // Digit `d` of the 2·per_key digits, least significant first: b's digits, then a's.
    let digit = move |p: &Pair, d: u32| {
        let (k, d) = if d < per_key {
            (p.b, d)
        } else {
            (p.a, d - per_key)
        };
        ((slot(k) >> (d * width)) & mask) as usize
    };
    let passes = 2 * per_key;
    // At most 3 digits per key (32 bits / 11); on the stack, so a step allocates nothing.
    let mut counts = [[0u32; 1 << RADIX_BITS]; 6];
    for p in pairs.iter() {
        for d in 0..passes {
            counts[d as usize][digit(p, d)] += 1;
        }
    }
    scratch.clear();
    scratch.resize(
        n,
        Pair {
            a: pairs[0].a,
            b: pairs[0].b,
        },
    );
    for d in 0..passes {
        let c = &mut counts[d as usize][..radix];
        if c.iter().any(|&k| k as usize == n) {
            continue;
        }
        let mut sum = 0;
        for k in c.iter_mut() {
            let here = *k;
            *k = sum;
            sum += here;
        }
        for p in pairs.iter() {
            let b = digit(p, d);
            scratch[c[b] as usize] = *p;
            c[b] += 1;
        }
        core::mem::swap(pairs, scratch);
    }
    if !pairs.windows(2).all(|w| w[0] <= w[1]) {
        pairs.sort_unstable();
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
    fn radix_sort_equals_sort_unstable() {
        let mut sm = SlotMap::<ProxyKey, ()>::with_key();
        let keys: Vec<_> = (0..3000).map(|_| sm.insert(())).collect();
        let mut seed = 11u32;
        let mut next = || {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (seed >> 8) as usize
        };
        let mut scratch = Vec::new();
        for len in [0, 1, 255, 256, 5000] {
            let mut pairs: Vec<Pair> = (0..len)
                .filter_map(|_| {
                    let (i, j) = (next() % keys.len(), next() % keys.len());
                    (i != j).then(|| Pair::new(keys[i], keys[j]))
                })
                .collect();
            let mut want = pairs.clone();
            want.sort_unstable();
            sort(&mut pairs, &mut scratch);
            assert_eq!(pairs, want);
        }
        // Keys of two slot maps may share a slot: the fallback still sorts by `Ord`.
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
        sort(&mut pairs, &mut scratch);
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
