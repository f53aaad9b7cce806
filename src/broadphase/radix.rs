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
}
