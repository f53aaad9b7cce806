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
    let mut counts = [0u32; BUCKETS];
    let mut shift = 0;
    while shift < bits {
        counts.fill(0);
        for &k in keys.iter() {
            counts[digit(k, shift)] += 1;
        }
        // A digit every key shares moves nothing: skip its pass.
        if counts.iter().any(|&c| c as usize == n) {
            shift += DIGIT_BITS;
            continue;
        }
        let mut sum = 0u32;
        for c in counts.iter_mut() {
            let here = *c;
            *c = sum;
            sum += here;
        }
        for &k in keys.iter() {
            let d = digit(k, shift);
            scratch[counts[d] as usize] = k;
            counts[d] += 1;
        }
        core::mem::swap(keys, scratch);
        shift += DIGIT_BITS;
    }
}

/// The most parts [`sort_u64_par`] splits the keys into: part indices are bytes.
#[cfg(feature = "parallel")]
const MAX_PARTS: usize = 64;
/// Keys sampled per part to pick the parts' first keys from.
#[cfg(feature = "parallel")]
const SAMPLES_PER_PART: usize = 64;
/// Keys per task of the first pass of [`sort_u64_par`] (which part each key is in).
#[cfg(feature = "parallel")]
const PIECE: usize = 8192;

/// Buffers of [`sort_u64_par`], reused by every sort; they never shrink.
#[cfg(feature = "parallel")]
#[derive(Clone, Debug, Default)]
pub(super) struct ParSort {
    /// Keys sampled from the inputs, sorted, to pick the parts' first keys from.
    sample: Vec<u64>,
    /// The first key of every part but the first, increasing.
    splitters: Vec<u64>,
    /// Per input: each key's part.
    part_of: Vec<Vec<u8>>,
    /// Per part: its keys and the radix sort's second buffer.
    parts: Vec<[Vec<u64>; 2]>,
    /// The parts' first positions in the output, and the key count last.
    bounds: Vec<usize>,
}

#[cfg(feature = "parallel")]
impl ParSort {
    /// Heap bytes held (capacities).
    pub(super) fn heap_bytes(&self) -> usize {
        (self.sample.capacity() + self.splitters.capacity() + self.bounds.capacity()) * 8
            + self.part_of.iter().map(Vec::capacity).sum::<usize>()
            + self
                .parts
                .iter()
                .map(|[a, b]| (a.capacity() + b.capacity()) * 8)
                .sum::<usize>()
    }
}

/// Sorts the keys of all `inputs` (distinct, zero above their low `bits` bits) into `out`,
/// over rayon's current pool: the key range is cut into at most `parts` ranges of about equal
/// counts (quantiles of a sample), and each range is gathered from every input and radix
/// sorted by its own task, into its own stretch of `out`. The keys are distinct, so `out` is
/// the same whatever the cut.
#[cfg(feature = "parallel")]
pub(super) fn sort_u64_par(
    inputs: &[Vec<u64>],
    out: &mut Vec<u64>,
    s: &mut ParSort,
    bits: u32,
    parts: usize,
) {
    use rayon::prelude::*;
    let total: usize = inputs.iter().map(Vec::len).sum();
    let parts = parts.min(MAX_PARTS).min(total / SAMPLES_PER_PART).max(1);
    let stride = (total / (parts * SAMPLES_PER_PART)).max(1);
    s.sample.clear();
    let mut skip = 0;
    for input in inputs {
        // The sample takes every `stride`-th key of the inputs as one sequence.
        s.sample.extend(input.iter().skip(skip).step_by(stride));
        skip = (skip + stride - input.len() % stride) % stride;
    }
    s.sample.sort_unstable();
    s.splitters.clear();
    for p in 1..parts {
        let k = s.sample[s.sample.len() * p / parts];
        if s.splitters.last().is_none_or(|&last| last < k) {
            s.splitters.push(k);
        }
    }
    if s.part_of.len() < inputs.len() {
        s.part_of.resize_with(inputs.len(), Vec::new);
    }
    for (part_of, input) in s.part_of.iter_mut().zip(inputs) {
        part_of.resize(input.len(), 0);
    }
    let splitters = &s.splitters;
    let counts = inputs
        .par_iter()
        .zip(s.part_of.par_iter_mut())
        .flat_map(|(input, part_of)| input.par_chunks(PIECE).zip(part_of.par_chunks_mut(PIECE)))
        .map(|(keys, part_of)| {
            let mut counts = [0usize; MAX_PARTS];
            for (q, &k) in part_of.iter_mut().zip(keys) {
                let p = splitters.partition_point(|&x| x <= k);
                counts[p] += 1;
                *q = p as u8;
            }
            counts
        })
        .reduce(
            || [0; MAX_PARTS],
            |a, b| core::array::from_fn(|i| a[i] + b[i]),
        );
    let np = splitters.len() + 1;
    s.bounds.clear();
    s.bounds.push(0);
    for c in &counts[..np] {
        s.bounds.push(s.bounds.last().copied().unwrap_or(0) + c);
    }
    if s.parts.len() < np {
        s.parts.resize_with(np, Default::default);
    }
    out.resize(total, 0);
    let job = Gather {
        inputs,
        part_of: &s.part_of[..inputs.len()],
        bounds: &s.bounds,
        bits,
    };
    job.fill(0, &mut s.parts[..np], out);
}

/// What every part of [`sort_u64_par`] reads.
#[cfg(feature = "parallel")]
struct Gather<'a> {
    inputs: &'a [Vec<u64>],
    part_of: &'a [Vec<u8>],
    bounds: &'a [usize],
    bits: u32,
}

#[cfg(feature = "parallel")]
impl Gather<'_> {
    /// Sorts parts `first..first + parts.len()` into `out` (their stretch of the output),
    /// halving the parts between two tasks until one is left.
    fn fill(&self, first: usize, parts: &mut [[Vec<u64>; 2]], out: &mut [u64]) {
        if let [[keys, tmp]] = parts {
            // One slot of slack: every key is stored, and the length advances past those of
            // this part.
            keys.clear();
            keys.resize(out.len() + 1, 0);
            let mut len = 0;
            for (input, part_of) in self.inputs.iter().zip(self.part_of) {
                for (&k, &q) in input.iter().zip(part_of) {
                    keys[len] = k;
                    len += usize::from(usize::from(q) == first);
                }
            }
            debug_assert_eq!(len, out.len());
            keys.truncate(len);
            sort_u64(keys, tmp, self.bits);
            out.copy_from_slice(keys);
            return;
        }
        let mid = parts.len() / 2;
        let at = self.bounds[first + mid] - self.bounds[first];
        let (pa, pb) = parts.split_at_mut(mid);
        let (oa, ob) = out.split_at_mut(at);
        rayon::join(
            || self.fill(first, pa, oa),
            || self.fill(first + mid, pb, ob),
        );
    }
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

    /// The parallel sort gives the serial one's output for any split of the keys over the
    /// inputs (empty inputs too), any part count and thread count.
    #[cfg(feature = "parallel")]
    #[test]
    fn parallel_sort_is_the_sorted_union() {
        let mut s = 0x2545_F491_4F6C_DD1Du64;
        let mut next = || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            s
        };
        let mut scratch = ParSort::default();
        for threads in [1, 2, 3] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            for (n, inputs, bits) in [(0, 3, 40), (5, 2, 40), (1000, 1, 20), (30_000, 9, 49)] {
                let mut all: Vec<u64> = (0..n).map(|_| next() & ((1u64 << bits) - 1)).collect();
                all.sort_unstable();
                all.dedup();
                let mut split = vec![Vec::new(); inputs];
                for &k in &all {
                    split[(next() % inputs as u64) as usize].push(k);
                }
                for parts in [1, 2, 7, 64] {
                    let mut out = vec![7; 3];
                    pool.install(|| sort_u64_par(&split, &mut out, &mut scratch, bits, parts));
                    assert_eq!(out, all, "n {n} parts {parts} threads {threads}");
                }
            }
        }
    }
}
