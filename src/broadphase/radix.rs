//! Least-significant-digit radix sorts of packed integer keys, reusing caller-owned buffers.

/// Bits per counting pass: 2048 counters (8 KiB) stay in L1.
const DIGIT_BITS: u32 = 11;
const BUCKETS: usize = 1 << DIGIT_BITS;

/// Sorts `keys` ascending, looking only at their low `bits` bits (the rest must be zero or
/// already in order, i.e. equal for all keys). Stable, O(n · bits / 11); `scratch` is resized
/// as needed and keeps its capacity.
pub(super) fn sort_u64(keys: &mut Vec<u64>, scratch: &mut Vec<u64>, bits: u32) {
    let n = keys.len();
    if n < 2 {
        return;
    }
    if n < 64 {
        keys.sort_unstable();
        return;
    }
    scratch.clear();
    scratch.resize(n, 0);
    let mut shift = 0;
    while shift < bits {
        if digit_pass(keys, scratch, shift) {
            core::mem::swap(keys, scratch);
        }
        shift += DIGIT_BITS;
    }
}

/// Writes to `splitters` the first keys of parts `1..parts` of a cut of the key range into
/// `parts` parts (fewer where keys repeat), increasing: the quantiles of `sorted`, a sorted
/// list like the one about to be sorted, of at least `parts` keys.
#[cfg(feature = "parallel")]
pub(super) fn split_points(sorted: &[u64], parts: usize, splitters: &mut Vec<u64>) {
    debug_assert!(sorted.len() >= parts || parts == 1);
    splitters.clear();
    for p in 1..parts {
        let k = sorted[sorted.len() * p / parts];
        if splitters.last().is_none_or(|&last| last < k) {
            splitters.push(k);
        }
    }
}

/// The part of `key` in the cut whose first keys are `splitters` (see [`split_points`]): the
/// number of them at most `key`, counted without a branch (there are a few dozen at most).
#[cfg(feature = "parallel")]
#[inline]
pub(super) fn part_of(splitters: &[u64], key: u64) -> usize {
    splitters.iter().map(|&s| usize::from(s <= key)).sum()
}

/// Sorts keys that their producers have already cut into `parts` parts into `out`, over
/// rayon's current pool: `buckets[i][p]` holds producer `i`'s keys of part `p`. Each part is
/// copied into its stretch of `out` and radix sorted there by its own task, with `tmp[p]` as
/// its second buffer; `bounds` gets the parts' first positions and the key count last. The
/// keys (distinct, zero above their low `bits` bits) end sorted whatever the cut.
#[cfg(feature = "parallel")]
pub(super) fn sort_parts(
    buckets: &[Vec<Vec<u64>>],
    parts: usize,
    out: &mut Vec<u64>,
    tmp: &mut Vec<Vec<u64>>,
    bounds: &mut Vec<usize>,
    bits: u32,
) {
    bounds.clear();
    bounds.push(0);
    for p in 0..parts {
        let len: usize = buckets.iter().map(|b| b[p].len()).sum();
        bounds.push(bounds[p] + len);
    }
    out.resize(bounds[parts], 0);
    if tmp.len() < parts {
        tmp.resize_with(parts, Vec::new);
    }
    let job = Gather {
        buckets,
        bounds,
        bits,
    };
    job.fill(0, &mut tmp[..parts], out);
}

/// What every part of [`sort_parts`] reads.
#[cfg(feature = "parallel")]
struct Gather<'a> {
    buckets: &'a [Vec<Vec<u64>>],
    bounds: &'a [usize],
    bits: u32,
}

#[cfg(feature = "parallel")]
impl Gather<'_> {
    /// Sorts parts `first..first + tmp.len()` into `out`, their stretch of the output,
    /// halving the parts between two tasks until one is left.
    fn fill(&self, first: usize, tmp: &mut [Vec<u64>], out: &mut [u64]) {
        if let [tmp] = tmp {
            let mut at = 0;
            for b in self.buckets {
                let keys = &b[first];
                out[at..at + keys.len()].copy_from_slice(keys);
                at += keys.len();
            }
            sort_slice(out, tmp, self.bits);
            return;
        }
        let mid = tmp.len() / 2;
        let at = self.bounds[first + mid] - self.bounds[first];
        let (ta, tb) = tmp.split_at_mut(mid);
        let (oa, ob) = out.split_at_mut(at);
        rayon::join(
            || self.fill(first, ta, oa),
            || self.fill(first + mid, tb, ob),
        );
    }
}

/// [`sort_u64`] of a slice: the passes alternate between `keys` and `tmp`, and the keys are
/// copied back if they end in `tmp`.
#[cfg(feature = "parallel")]
fn sort_slice(keys: &mut [u64], tmp: &mut Vec<u64>, bits: u32) {
    let n = keys.len();
    if n < 64 {
        keys.sort_unstable();
        return;
    }
    tmp.clear();
    tmp.resize(n, 0);
    let mut in_tmp = false;
    let mut shift = 0;
    while shift < bits {
        let moved = if in_tmp {
            digit_pass(tmp, keys, shift)
        } else {
            digit_pass(keys, tmp, shift)
        };
        in_tmp ^= moved;
        shift += DIGIT_BITS;
    }
    if in_tmp {
        keys.copy_from_slice(tmp);
    }
}

/// One counting pass on the digit at `shift`: `dst` gets `src` stably sorted by it. Returns
/// false, leaving `dst` as it was, if every key has the same digit there: the pass would move
/// nothing.
#[inline]
fn digit_pass(src: &[u64], dst: &mut [u64], shift: u32) -> bool {
    let mut counts = [0u32; BUCKETS];
    for &k in src {
        counts[digit(k, shift)] += 1;
    }
    if counts.iter().any(|&c| c as usize == src.len()) {
        return false;
    }
    let mut sum = 0u32;
    for c in counts.iter_mut() {
        let here = *c;
        *c = sum;
        sum += here;
    }
    for &k in src {
        let d = digit(k, shift);
        dst[counts[d] as usize] = k;
        counts[d] += 1;
    }
    true
}

#[inline]
fn digit(k: u64, shift: u32) -> usize {
    ((k >> shift) as usize) & (BUCKETS - 1)
}

/// Bits needed to write `x`.
pub(super) fn bits_of(x: u64) -> u32 {
    u64::BITS - x.leading_zeros()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sorts_like_sort_unstable() {
        let mut s = 0x9E37_79B9_7F4A_7C15u64;
        for n in [0, 1, 5, 63, 64, 65, 1000, 5000] {
            for bits in [3, 11, 22, 34, 63] {
                let mut keys: Vec<u64> = (0..n)
                    .map(|_| {
                        s ^= s << 7;
                        s ^= s >> 9;
                        s & ((1u64 << bits) - 1)
                    })
                    .collect();
                let mut want = keys.clone();
                want.sort_unstable();
                sort_u64(&mut keys, &mut Vec::new(), bits);
                assert_eq!(keys, want, "n {n} bits {bits}");
            }
        }
    }

    /// The parallel sort gives the serial one's output however the keys are spread over the
    /// producers (empty ones too), for cuts at the quantiles of the keys themselves and of
    /// other keys, any part count and thread count.
    #[cfg(feature = "parallel")]
    #[test]
    fn sorting_in_parts_gives_the_sorted_union() {
        let mut s = 0x2545_F491_4F6C_DD1Du64;
        let mut next = || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            s
        };
        let (mut splitters, mut tmp, mut bounds) = (Vec::new(), Vec::new(), Vec::new());
        for threads in [1, 2, 3] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            for (n, producers, bits) in [(0, 3, 40), (5, 2, 40), (1000, 1, 40), (30_000, 9, 49)] {
                let mut all: Vec<u64> = (0..n).map(|_| next() & ((1u64 << bits) - 1)).collect();
                all.sort_unstable();
                all.dedup();
                let other: Vec<u64> = (0..64).map(|i| i << (bits - 6)).collect();
                for (parts, by) in [
                    (1, &all[..]),
                    (2, &all[..]),
                    (7, &all[..]),
                    (64, &other[..]),
                ] {
                    if by.len() < parts {
                        continue;
                    }
                    split_points(by, parts, &mut splitters);
                    let np = splitters.len() + 1;
                    let mut buckets = vec![vec![Vec::new(); np]; producers];
                    for &k in &all {
                        let i = (next() % producers as u64) as usize;
                        buckets[i][part_of(&splitters, k)].push(k);
                    }
                    let mut out = vec![7; 3];
                    pool.install(|| {
                        sort_parts(&buckets, np, &mut out, &mut tmp, &mut bounds, bits);
                    });
                    assert_eq!(out, all, "n {n} parts {parts} threads {threads}");
                }
            }
        }
    }
}
