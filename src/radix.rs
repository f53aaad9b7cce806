//! The one radix sort: least-significant-digit sorts of `u64` keys by a range of their bits,
//! stable, reusing caller-owned buffers, and how those buffers grow.
//!
//! - [`sort_bits_in`] / [`sort_bits_by`]: any items by bits `lo..lo + bits` of their key. The
//!   octree's walk order sorts `(walk key << 32) | id` by the walk key's bits this way.
//! - [`sort_u64`] / [`sort_parts`]: packed slot pairs (one slot index in each 32-bit half, see
//!   `broadphase::step::pack`), the broadphase's pair lists. With `slots` slots each index fits
//!   in `s = bits_of(slots - 1)` bits, so the sort reads a pair as the `2s`-bit number
//!   `high half << s | low half` ([`PairBits`]): it orders pairs as the full keys do, and its
//!   digits cover only bits that vary. All digit counts are taken in one read of the keys.
//!   The digits are as wide as the number of keys pays for: each pass moves every key once,
//!   and each counter costs a clear, a prefix sum and a look at whether its digit varies, so
//!   a list with more keys than half the counters of fewer, wider passes takes those ([`plan`]:
//!   10 000 slots and 20 000 pairs sort in two passes of 14 bits instead of three of 10).

/// The widest digit of the narrow plan: 2048 counters (8 KiB) stay in L1.
const MAX_DIGIT_BITS: u32 = 11;

#[cfg(feature = "parallel")]
use core::ops::Range;
#[cfg(feature = "parallel")]
use rayon::prelude::*;

/// The plans a pair sort chooses from, as (counters per pass, passes): each covers keys of up
/// to `passes × log2(counters)` bits, and keeps its counters on the stack.
mod plan {
    /// Two passes of up to 14 bits: up to 2¹⁴ slots (128 KiB of counters).
    pub(super) const TWO: (usize, usize) = (1 << 14, 2);
    /// [`TWO`] for up to 2¹² slots (32 KiB): a small world's sort zeroes no more counters
    /// than its digits use.
    pub(super) const TWO_SMALL: (usize, usize) = (1 << 12, 2);
    /// Three passes of up to 12 bits: up to 2¹⁸ slots (48 KiB).
    pub(super) const THREE: (usize, usize) = (1 << 12, 3);
    /// Any key: passes of up to [`super::MAX_DIGIT_BITS`] bits, enough for two 32-bit slot
    /// indices (48 KiB).
    pub(super) const NARROW: (usize, usize) = (
        1 << super::MAX_DIGIT_BITS,
        64usize.div_ceil(super::MAX_DIGIT_BITS as usize),
    );
}

/// How the sort reads the pairs of a store of a given number of slots: the slot bits and
/// the digits that cover the `2 × slot_bits` bits of the compact key.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct PairBits {
    slot_bits: u32,
    digit_bits: u32,
    passes: u32,
}

impl PairBits {
    /// The layout for slot indices below `slots` (at most `2³¹`): `ceil(2s / 11)` passes of
    /// equal digits, the narrow plan ([`sort_in`] takes fewer, wider ones for long lists).
    pub(crate) fn for_slots(slots: usize) -> PairBits {
        let slot_bits = bits_of(slots.saturating_sub(1) as u64).max(1);
        PairBits::with_passes(slot_bits, (2 * slot_bits).div_ceil(MAX_DIGIT_BITS))
    }

    /// `passes` passes of equal digits over the `2 × slot_bits` bits of the compact key.
    fn with_passes(slot_bits: u32, passes: u32) -> PairBits {
        PairBits {
            slot_bits,
            digit_bits: (2 * slot_bits).div_ceil(passes),
            passes,
        }
    }

    /// This layout in the passes of `plan` (counters per pass, passes), if that saves a pass,
    /// its digits fit the counters, and `n` keys pay for them: at least half as many keys as
    /// counters in use (a pass moves each key for about what two counters cost).
    fn in_plan(self, (buckets, passes): (usize, usize), n: usize) -> Option<PairBits> {
        let wide = PairBits::with_passes(self.slot_bits, passes as u32);
        let used = (1usize << wide.digit_bits) * passes;
        (wide.passes < self.passes && 1usize << wide.digit_bits <= buckets && 2 * n >= used)
            .then_some(wide)
    }

    /// `high half << slot_bits | low half` of a packed pair both of whose slots are below
    /// `1 << slot_bits`: a bijection onto `2 × slot_bits` bits that keeps the keys' order.
    #[inline]
    fn compact(self, k: u64) -> u64 {
        debug_assert!(k >> 32 >> self.slot_bits == 0 && (k as u32) >> self.slot_bits == 0);
        (k & 0xFFFF_FFFF) | ((k >> 32) << self.slot_bits)
    }

    /// The packed pair of a compact key: the inverse of [`PairBits::compact`].
    #[inline]
    fn expand(self, c: u64) -> u64 {
        ((c >> self.slot_bits) << 32) | (c & ((1 << self.slot_bits) - 1))
    }

    /// The digit of compact key `c` at `shift`, below `B` (the plan's counters per pass, a
    /// power of two of at least `1 << digit_bits`).
    #[inline]
    fn digit<const B: usize>(self, c: u64, shift: u32) -> usize {
        ((c >> shift) as usize) & ((1 << self.digit_bits) - 1) & (B - 1)
    }
}

/// Sorts `keys` (packed pairs of slots below the layout's bound) ascending. Stable, one read
/// for the counts and one scatter per digit that varies; `scratch` is resized as needed and
/// keeps its capacity.
pub(crate) fn sort_u64(keys: &mut Vec<u64>, scratch: &mut Vec<u64>, layout: PairBits) {
    let n = keys.len();
    if n < 2 {
        return;
    }
    if n < 64 {
        keys.sort_unstable();
        return;
    }
    // The second buffer's old contents are overwritten: it only grows (zeroing just what
    // it gains), and ends as long as the longest list it has sorted.
    if scratch.len() < n {
        scratch.resize(n, 0);
    }
    if sort_in(keys, &mut scratch[..n], layout) {
        core::mem::swap(keys, scratch);
        keys.truncate(n);
    }
}

/// The sort of [`sort_u64`] over `keys` with `tmp` (of the same length) as the second buffer;
/// true if the sorted keys end in `tmp`. Takes the plan of fewest passes that the keys pay
/// for (see [`PairBits::in_plan`]).
fn sort_in(keys: &mut [u64], tmp: &mut [u64], layout: PairBits) -> bool {
    let n = keys.len();
    if let Some(two) = layout.in_plan(plan::TWO, n) {
        if 1 << two.digit_bits <= plan::TWO_SMALL.0 {
            sort_halves::<{ plan::TWO_SMALL.0 }>(keys, tmp, two)
        } else {
            sort_halves::<{ plan::TWO.0 }>(keys, tmp, two)
        }
    } else if let Some(three) = layout.in_plan(plan::THREE, n) {
        sort_planned::<{ plan::THREE.0 }, { plan::THREE.1 }>(keys, tmp, three)
    } else if layout.passes == 2 {
        sort_halves::<{ plan::NARROW.0 }>(keys, tmp, layout)
    } else {
        sort_planned::<{ plan::NARROW.0 }, { plan::NARROW.1 }>(keys, tmp, layout)
    }
}

/// [`sort_in`] in two passes whose digits are the packed key's halves (slots below `B` and
/// `1 << layout.slot_bits`): the low half (the larger slot), then the high half. Two passes
/// over `2s` bits have digits of `s` bits, the slots themselves, so the keys need no compact
/// form. Not inlined: its counters take only its own stack frame.
#[inline(never)]
fn sort_halves<const B: usize>(keys: &mut [u64], tmp: &mut [u64], layout: PairBits) -> bool {
    debug_assert!(layout.passes == 2 && layout.digit_bits == layout.slot_bits);
    let mut counts = [[0u32; B]; 2];
    let used = (1 << layout.slot_bits).min(B);
    let [lo, hi] = &mut counts;
    let low = |k: u64| k as usize & (B - 1);
    let high = |k: u64| (k >> 32) as usize & (B - 1);
    for &k in keys.iter() {
        debug_assert!(k >> 32 < B as u64 && (k as u32 as usize) < B);
        lo[low(k)] += 1;
        hi[high(k)] += 1;
    }
    let same = |k| k;
    let in_tmp = scatter(keys, tmp, lo, used, low, same);
    let (src, dst): (&[u64], &mut [u64]) = if in_tmp { (tmp, keys) } else { (keys, tmp) };
    in_tmp ^ scatter(src, dst, hi, used, high, same)
}

/// [`sort_in`] with `P` passes of at most `B` counters each. The counts pass also rewrites the
/// keys in compact form, which the scatters then read with a shift and a mask, and the last
/// scatter (or a final loop if it had nothing to move) writes them back in packed form. Not
/// inlined: each plan's counters take only its own stack frame.
#[inline(never)]
fn sort_planned<const B: usize, const P: usize>(
    keys: &mut [u64],
    tmp: &mut [u64],
    layout: PairBits,
) -> bool {
    debug_assert!(layout.passes as usize <= P && 1 << layout.digit_bits <= B);
    let mut counts = [[0u32; B]; P];
    count_digits(keys, layout, &mut counts);
    let mut in_tmp = false;
    let mut expanded = false;
    for (pass, c) in (0..layout.passes).zip(&mut counts) {
        let last = pass + 1 == layout.passes;
        let shift = pass * layout.digit_bits;
        let (src, dst): (&[u64], &mut [u64]) = if in_tmp { (tmp, keys) } else { (keys, tmp) };
        let used = 1 << layout.digit_bits;
        let digit = |c| layout.digit::<B>(c, shift);
        let moved = if last {
            scatter(src, dst, c, used, digit, |c| layout.expand(c))
        } else {
            scatter(src, dst, c, used, digit, |c| c)
        };
        in_tmp ^= moved;
        expanded = last && moved;
    }
    if !expanded {
        let out = if in_tmp { &mut *tmp } else { &mut *keys };
        for k in out {
            *k = layout.expand(*k);
        }
    }
    in_tmp
}

/// Writes to `splitters` the first keys of parts `1..parts` of a cut of the key range into
/// `parts` parts (fewer where keys repeat), increasing: the quantiles of `sorted` read
/// through `key`, a sorted list like the one about to be sorted (a sample of it, or all of
/// it), not empty unless `parts` is 1.
#[cfg(feature = "parallel")]
pub(crate) fn split_points<T>(
    sorted: &[T],
    key: impl Fn(&T) -> u64,
    parts: usize,
    splitters: &mut Vec<u64>,
) {
    debug_assert!(!sorted.is_empty() || parts <= 1);
    splitters.clear();
    for p in 1..parts {
        let k = key(&sorted[sorted.len() * p / parts]);
        if splitters.last().is_none_or(|&last| last < k) {
            splitters.push(k);
        }
    }
}

/// The part of `key` in the cut whose first keys are `splitters` (see [`split_points`]): the
/// number of them at most `key`, counted without a branch (there are a few dozen at most).
#[cfg(feature = "parallel")]
#[inline]
pub(crate) fn part_of(splitters: &[u64], key: u64) -> usize {
    splitters.iter().map(|&s| usize::from(s <= key)).sum()
}

/// One producer's keys for [`sort_parts`], each pushed with its part as it is found. One list
/// per producer, whatever the cut: where the keys follow place (a world inserted in one
/// batch) a producer's keys fall mostly in one part, and which one shifts as its objects
/// move, so a list per part would keep growing to new peaks.
#[cfg(feature = "parallel")]
#[derive(Clone, Debug, Default)]
pub(crate) struct Parted {
    /// The keys as found.
    keys: Vec<u64>,
    /// Each key's part.
    parts: Vec<u8>,
    /// Per part: how many keys it got.
    counts: Vec<usize>,
}

#[cfg(feature = "parallel")]
impl Parted {
    /// Empties the lists for a cut into `parts` parts (at most 256).
    pub(crate) fn reset(&mut self, parts: usize) {
        debug_assert!(parts <= 256, "a part is a byte");
        self.keys.clear();
        self.parts.clear();
        self.counts.clear();
        self.counts.resize(parts, 0);
    }

    /// Adds `key` of part `part`.
    #[inline]
    pub(crate) fn push(&mut self, part: usize, key: u64) {
        self.keys.push(key);
        self.parts.push(part as u8);
        self.counts[part] += 1;
    }

    /// Writes the keys, in the order found, to the front of their part's stretch in `row`
    /// (one stretch per part, each as long as the part's count).
    fn scatter(&self, row: &mut [&mut [u64]]) {
        for (&key, &part) in self.keys.iter().zip(&self.parts) {
            put_front(row, usize::from(part), key);
        }
    }

    /// Heap bytes held (capacities).
    pub(crate) fn heap_bytes(&self) -> usize {
        (self.keys.capacity() + self.counts.capacity()) * 8 + self.parts.capacity()
    }

    /// [`ahead`] on the lists that grow with the keys.
    pub(crate) fn ahead(&mut self) {
        ahead(&mut self.keys);
        ahead(&mut self.parts);
    }

    /// Applies `trim` (a caller's policy for giving back room) to the keys, and cuts the
    /// parts' list to the keys' room.
    pub(crate) fn trim(&mut self, trim: fn(&mut Vec<u64>, usize)) {
        trim(&mut self.keys, 0);
        if self.parts.capacity() > self.keys.capacity() {
            self.parts.shrink_to(self.keys.capacity());
        }
    }
}

/// The allocation of a table of destination stretches: empty between uses, and lent to each
/// (see [`recycle`]). A clone is empty.
#[cfg(feature = "parallel")]
#[derive(Debug, Default)]
pub(crate) struct Stretches(Vec<&'static mut [u64]>);

#[cfg(feature = "parallel")]
impl Clone for Stretches {
    fn clone(&self) -> Self {
        Stretches::default()
    }
}

#[cfg(feature = "parallel")]
impl Stretches {
    /// Bytes held on the heap.
    pub(crate) fn heap_bytes(&self) -> usize {
        self.0.capacity() * size_of::<&mut [u64]>()
    }

    /// Cuts `dst` into `rows × cols` stretches, column-major (every row's stretch of column
    /// 0, then of column 1, …), stretch `(r, c)` `len(r, c)` long, by one `split_at_mut`
    /// walk, then runs `write(r, row)` for each row over rayon's current pool, `row` holding
    /// its `cols` stretches in column order. The table of stretches borrows this one's
    /// allocation and gives it back.
    fn scatter(
        &mut self,
        dst: &mut [u64],
        (rows, cols): (usize, usize),
        len: impl Fn(usize, usize) -> usize,
        write: impl Fn(usize, &mut [&mut [u64]]) + Sync,
    ) {
        let mut table: Vec<&mut [u64]> = core::mem::take(&mut self.0);
        table.resize_with(rows * cols, Default::default);
        let mut rest = dst;
        for c in 0..cols {
            for r in 0..rows {
                // Clamped, though the lengths tile `dst` exactly: a miscount loses keys, not
                // the step.
                let n = len(r, c).min(rest.len());
                let (head, tail) = core::mem::take(&mut rest).split_at_mut(n);
                table[r * cols + c] = head;
                rest = tail;
            }
        }
        debug_assert!(rest.is_empty());
        table
            .par_chunks_mut(cols.max(1))
            .enumerate()
            .for_each(|(r, row)| write(r, row));
        self.0 = recycle(table);
    }
}

/// Writes `key` to the front of stretch `at` of `row`, which then starts past it.
#[cfg(feature = "parallel")]
#[inline]
fn put_front(row: &mut [&mut [u64]], at: usize, key: u64) {
    if let Some((first, rest)) = core::mem::take(&mut row[at]).split_first_mut() {
        *first = key;
        row[at] = rest;
    }
}

/// Sorts keys that their producers have already cut into `parts` parts into `out`, over
/// rayon's current pool: `producers[i]` holds producer `i`'s keys with their parts. `out` is
/// cut into the (part, producer) stretches, part-major, and each producer writes its keys
/// into its own (one `split_at_mut` walk hands them out; `stretches` lends the table's
/// allocation); then each part's stretch of `out` is radix sorted by its own task, with the
/// same stretch of `tmp` as its second buffer. `bounds` gets the parts' first positions and
/// the key count last. The keys (distinct packed pairs of slots below `layout`'s bound) end
/// sorted whatever the cut.
#[cfg(feature = "parallel")]
pub(crate) fn sort_parts(
    producers: &[Parted],
    parts: usize,
    out: &mut Vec<u64>,
    tmp: &mut Vec<u64>,
    (bounds, stretches): (&mut Vec<usize>, &mut Stretches),
    layout: PairBits,
) {
    bounds.clear();
    bounds.push(0);
    for p in 0..parts {
        let len: usize = producers.iter().map(|b| b.counts[p]).sum();
        bounds.push(bounds[p] + len);
    }
    out.resize(bounds[parts], 0);
    tmp.resize(bounds[parts], 0);
    stretches.scatter(
        out,
        (producers.len(), parts),
        |i, p| producers[i].counts[p],
        |i, row| producers[i].scatter(row),
    );
    sort_each_part(bounds, 0, parts, out, tmp, layout);
}

/// Sorts parts `first..first + parts` of [`sort_parts`]'s output in place, `out` and `tmp`
/// their stretches, halving the parts between two tasks until one is left.
#[cfg(feature = "parallel")]
fn sort_each_part(
    bounds: &[usize],
    first: usize,
    parts: usize,
    out: &mut [u64],
    tmp: &mut [u64],
    layout: PairBits,
) {
    if parts <= 1 {
        sort_slice(out, tmp, layout);
        return;
    }
    let mid = parts / 2;
    let at = bounds[first + mid] - bounds[first];
    let (ta, tb) = tmp.split_at_mut(at);
    let (oa, ob) = out.split_at_mut(at);
    rayon::join(
        || sort_each_part(bounds, first, mid, oa, ta, layout),
        || sort_each_part(bounds, first + mid, parts - mid, ob, tb, layout),
    );
}

/// [`sort_u64`] that leaves the keys in their own buffer (copied back if they end in the
/// second one), for a second buffer lent by another owner: `scratch` is grown to the keys'
/// length if it is shorter, and its contents are overwritten.
pub(crate) fn sort_u64_kept(keys: &mut [u64], scratch: &mut Vec<u64>, layout: PairBits) {
    let n = keys.len();
    if n >= 64 && scratch.len() < n {
        scratch.resize(n, 0);
    }
    let m = n.min(scratch.len());
    sort_slice(keys, &mut scratch[..m], layout);
}

/// [`sort_u64`] of a slice with a second buffer of the same length: the keys are copied back
/// if they end in `tmp`.
fn sort_slice(keys: &mut [u64], tmp: &mut [u64], layout: PairBits) {
    if keys.len() < 64 {
        keys.sort_unstable();
        return;
    }
    if sort_in(keys, tmp, layout) {
        keys.copy_from_slice(tmp);
    }
}

/// The counts of every digit of every pass, in one read of the keys, which it leaves in
/// compact form.
#[inline]
fn count_digits<const B: usize, const P: usize>(
    keys: &mut [u64],
    layout: PairBits,
    counts: &mut [[u32; B]; P],
) {
    let b = layout.digit_bits;
    match (layout.passes, &mut counts[..]) {
        // Two and three passes, unrolled: every plan up to 2¹⁸ slots.
        (2, [c0, c1, ..]) => {
            for k in keys {
                let c = layout.compact(*k);
                *k = c;
                c0[layout.digit::<B>(c, 0)] += 1;
                c1[layout.digit::<B>(c, b)] += 1;
            }
        }
        (3, [c0, c1, c2, ..]) => {
            for k in keys {
                let c = layout.compact(*k);
                *k = c;
                c0[layout.digit::<B>(c, 0)] += 1;
                c1[layout.digit::<B>(c, b)] += 1;
                c2[layout.digit::<B>(c, 2 * b)] += 1;
            }
        }
        (passes, counts) => {
            for k in keys {
                let c = layout.compact(*k);
                *k = c;
                for (p, counts) in counts[..passes as usize].iter_mut().enumerate() {
                    counts[layout.digit::<B>(c, p as u32 * b)] += 1;
                }
            }
        }
    }
}

/// One scatter of `src` into `dst`, stably sorted by `digit` (below `used`, at most `B`), each
/// key written as `out` of it; `counts` holds the digits' counts. Returns false, leaving
/// `dst` as it was, if every key has the same digit: the pass would move nothing.
#[inline(always)]
fn scatter<const B: usize>(
    src: &[u64],
    dst: &mut [u64],
    counts: &mut [u32; B],
    used: usize,
    digit: impl Fn(u64) -> usize,
    out: impl Fn(u64) -> u64,
) -> bool {
    let used = &mut counts[..used];
    if used.iter().any(|&c| c as usize == src.len()) {
        return false;
    }
    let mut sum = 0u32;
    for c in used.iter_mut() {
        let here = *c;
        *c = sum;
        sum += here;
    }
    for &c in src {
        // Masked to the array's length: no bounds check on the counters.
        let d = digit(c) & (B - 1);
        dst[counts[d] as usize] = out(c);
        counts[d] += 1;
    }
    true
}

/// Bits needed to write `x`.
fn bits_of(x: u64) -> u32 {
    u64::BITS - x.leading_zeros()
}

/// Sorts `items` by bits `lo..lo + bits` of `key(item)`, stable; `tmp` and `counts` are
/// scratch that keeps its capacity, and digits every item shares are skipped. The walk order
/// of trees too deep for a 32-bit walk key sorts `(walk key, id)` pairs this way.
#[inline]
pub(crate) fn sort_bits_by<T: Copy + Default>(
    items: &mut Vec<T>,
    tmp: &mut Vec<T>,
    counts: &mut Vec<u32>,
    key: impl Fn(&T) -> u64,
    lo: u32,
    bits: u32,
) {
    tmp.resize(items.len(), T::default());
    if sort_core(items, tmp, counts, key, lo, bits) {
        core::mem::swap(items, tmp);
    }
}

/// Sorts `u32` values, every one below `bound`, ascending: [`sort_bits_by`] on the values'
/// own bits (a list of slots or of list positions).
pub(crate) fn sort_u32_below(
    items: &mut Vec<u32>,
    tmp: &mut Vec<u32>,
    counts: &mut Vec<u32>,
    bound: usize,
) {
    let bits = u32::BITS - (bound as u32).leading_zeros();
    sort_bits_by(items, tmp, counts, |&v| u64::from(v), 0, bits);
}

/// [`sort_bits_by`] of `u64` keys in a slice with a second buffer of the same length, for a
/// caller that keeps its buffers where they are (parts of one buffer, or a lent one): returns
/// true if the sorted items ended in `tmp` (an odd number of passes moved them), false if in
/// `items`.
pub(crate) fn sort_bits_in(
    items: &mut [u64],
    tmp: &mut [u64],
    counts: &mut Vec<u32>,
    lo: u32,
    bits: u32,
) -> bool {
    debug_assert_eq!(items.len(), tmp.len());
    sort_core(items, tmp, counts, |&x| x, lo, bits)
}

/// The passes of [`sort_bits_by`], moving the items between `a` and `b` (equal lengths);
/// true if they end in `b`.
#[inline]
fn sort_core<T: Copy>(
    a: &mut [T],
    b: &mut [T],
    counts: &mut Vec<u32>,
    key: impl Fn(&T) -> u64,
    lo: u32,
    bits: u32,
) -> bool {
    let n = a.len();
    let radix = 1usize << MAX_DIGIT_BITS;
    let mask = (radix - 1) as u64;
    let passes = bits.div_ceil(MAX_DIGIT_BITS) as usize;
    counts.clear();
    counts.resize(radix * passes, 0);
    for x in a.iter() {
        let x = key(x);
        for p in 0..passes {
            let d = ((x >> (lo + p as u32 * MAX_DIGIT_BITS)) & mask) as usize;
            counts[p * radix + d] += 1;
        }
    }
    let (mut src, mut dst) = (a, b);
    let mut in_b = false;
    for p in 0..passes {
        let c = &mut counts[p * radix..(p + 1) * radix];
        if c.iter().any(|&k| k as usize == n) {
            continue;
        }
        let mut sum = 0;
        for k in c.iter_mut() {
            let here = *k;
            *k = sum;
            sum += here;
        }
        let shift = lo + p as u32 * MAX_DIGIT_BITS;
        for x in src.iter() {
            let d = ((key(x) >> shift) & mask) as usize;
            dst[c[d] as usize] = *x;
            c[d] += 1;
        }
        core::mem::swap(&mut src, &mut dst);
        in_b = !in_b;
    }
    in_b
}

/// Counters per digit of the parallel scatter: the serial [`sort_bits_in`]'s digits.
#[cfg(feature = "parallel")]
const RADIX: usize = 1 << MAX_DIGIT_BITS;

/// Buffers of [`sort_bits_par`], reused by every sort; they never shrink.
#[cfg(feature = "parallel")]
#[derive(Clone, Debug, Default)]
pub(crate) struct ParScatter {
    /// Per task and digit, task `t`'s at `t · RADIX + digit`: how many of the task's keys
    /// have the digit in the current pass, the length of its stretch of the destination.
    counts: Vec<u32>,
    /// The table of destination stretches, laid out as `counts`.
    stretches: Stretches,
}

#[cfg(feature = "parallel")]
impl ParScatter {
    /// Bytes held on the heap.
    pub(crate) fn heap_bytes(&self) -> usize {
        self.counts.capacity() * size_of::<u32>() + self.stretches.heap_bytes()
    }
}

/// [`sort_bits_in`] over rayon's current pool in `tasks` tasks, from a source read in place:
/// sorts the keys that `keys` lists for the ranges of `0..len` (in order, the same keys
/// each time it is called) by bits `lo..lo + bits`, stable, into `out`, which is as long as
/// all of them, with `tmp` (the same length) as the second buffer. `out` ends as the serial
/// sort of the listed keys leaves it, at any task and thread count.
///
/// Each pass is a least-significant-digit scatter split by source range. The source is cut
/// into `tasks` contiguous ranges, in order, and each task counts its keys per digit. The
/// stable sort by the digit puts a key of digit `d` from task `t` after every key of a
/// smaller digit, every key of digit `d` from an earlier task, and the earlier keys of its
/// own range: so task `t`'s keys of digit `d` fill one stretch of the destination, and these
/// stretches, in (digit, task) order, tile it. One walk of `split_at_mut` hands every task its
/// own stretch of each digit, disjoint from all others, and each task writes its keys into
/// them in order. The first pass reads the source through `keys`; each later one counts the
/// previous pass's output again by range (the counts depend on where the keys now are) and
/// is skipped if every key has the same digit.
#[cfg(feature = "parallel")]
#[allow(clippy::too_many_arguments)] // reason: the serial sort's arguments, a source and a task count
pub(crate) fn sort_bits_par<F, I>(
    len: usize,
    keys: F,
    out: &mut [u64],
    tmp: &mut [u64],
    s: &mut ParScatter,
    tasks: usize,
    lo: u32,
    bits: u32,
) where
    F: Fn(Range<usize>) -> I + Sync,
    I: Iterator<Item = u64>,
{
    debug_assert_eq!(out.len(), tmp.len());
    let n = out.len();
    let tasks = tasks.max(1);
    let passes = bits.div_ceil(MAX_DIGIT_BITS).max(1);
    s.counts.resize(tasks * RADIX, 0);
    let counts = &mut s.counts[..tasks * RADIX];
    let range = |t: usize, len: usize| len * t / tasks..len * (t + 1) / tasks;
    // The first pass writes the buffer from which the passes after it end in `out`.
    let mut in_out = passes % 2 == 1;
    let first = |t| keys(range(t, len));
    count_by_task(counts, lo, first);
    let dst = if in_out { &mut *out } else { &mut *tmp };
    scatter_by_task(counts, &mut s.stretches, dst, lo, first);
    for pass in 1..passes {
        let shift = lo + pass * MAX_DIGIT_BITS;
        let (src, dst): (&[u64], &mut [u64]) = if in_out { (out, tmp) } else { (tmp, out) };
        let chunk = |t| src[range(t, n)].iter().copied();
        count_by_task(counts, shift, chunk);
        let d0 = src.first().map_or(0, |&k| digit(k, shift));
        let same: usize = counts
            .iter()
            .skip(d0)
            .step_by(RADIX)
            .map(|&c| c as usize)
            .sum();
        if same == n {
            continue;
        }
        scatter_by_task(counts, &mut s.stretches, dst, shift, chunk);
        in_out = !in_out;
    }
    if !in_out {
        let at = n.div_ceil(tasks).max(1);
        out.par_chunks_mut(at)
            .zip(tmp.par_chunks(at))
            .for_each(|(o, t)| o.copy_from_slice(t));
    }
}

/// The digit of `k` at `shift` in the parallel scatter.
#[cfg(feature = "parallel")]
#[inline]
fn digit(k: u64, shift: u32) -> usize {
    (k >> shift) as usize & (RADIX - 1)
}

/// Counts in parallel the digits at `shift` of each task's keys (`keys(t)`) into its row of
/// `counts`.
#[cfg(feature = "parallel")]
fn count_by_task<I: Iterator<Item = u64>>(
    counts: &mut [u32],
    shift: u32,
    keys: impl Fn(usize) -> I + Sync,
) {
    counts
        .par_chunks_mut(RADIX)
        .enumerate()
        .for_each(|(t, row)| count_row(row, shift, keys(t)));
}

/// One task of [`count_by_task`]. Not inlined: a profile shows each task's share by name.
#[cfg(feature = "parallel")]
#[inline(never)]
fn count_row(row: &mut [u32], shift: u32, keys: impl Iterator<Item = u64>) {
    row.fill(0);
    let Ok(row) = <&mut [u32; RADIX]>::try_from(row) else {
        return;
    };
    for k in keys {
        row[digit(k, shift)] += 1;
    }
}

/// One pass of [`sort_bits_par`]: cuts `dst` into the (digit, task) stretches that `counts`
/// gives, in digit-major order, and has each task write its keys (`keys(t)`) in order into
/// its stretches, over rayon's current pool. `stretches` lends the table's allocation.
#[cfg(feature = "parallel")]
fn scatter_by_task<I: Iterator<Item = u64>>(
    counts: &[u32],
    stretches: &mut Stretches,
    dst: &mut [u64],
    shift: u32,
    keys: impl Fn(usize) -> I + Sync,
) {
    stretches.scatter(
        dst,
        (counts.len() / RADIX, RADIX),
        |t, d| counts[t * RADIX + d] as usize,
        |t, row| scatter_row(row, shift, keys(t)),
    );
}

/// One task of [`scatter_by_task`]: writes each key to the front of its digit's stretch in
/// `row`, which then starts past it. Not inlined: a profile shows each task's share by name.
#[cfg(feature = "parallel")]
#[inline(never)]
fn scatter_row(row: &mut [&mut [u64]], shift: u32, keys: impl Iterator<Item = u64>) {
    let Ok(row) = <&mut [&mut [u64]; RADIX]>::try_from(row) else {
        return;
    };
    for k in keys {
        put_front(row, digit(k, shift), k);
    }
}

/// The allocation of an emptied table of stretches, for the next pass to borrow again:
/// collecting a `Vec`'s iterator into items of the same size and alignment reuses its buffer
/// (std's in-place collect), so the table allocates only when it grows.
#[cfg(feature = "parallel")]
fn recycle<'a>(mut table: Vec<&mut [u64]>) -> Vec<&'a mut [u64]> {
    table.clear();
    // The map never runs: the table is empty.
    table.into_iter().map(|_| Default::default()).collect()
}

/// Grows `v` to half again its length once it is within a quarter of its capacity: a sort's
/// list whose length swings from step to step (the pair lists, the parallel walk-order sort's
/// parts) stops growing after its first few swings. Exactly to that capacity ([`grow_to`]).
pub(crate) fn ahead<T>(v: &mut Vec<T>) {
    if v.capacity() < v.len() + v.len() / 4 {
        grow_to(v, v.len() + v.len() / 2);
    }
}

/// Grows a full per-slot array by an eighth (at least `MIN_GROWTH` entries) instead of
/// `Vec`'s doubling: a world a little past a power of two, or one that reserved exactly and then
/// takes a few more slots (a churn's quarantined ones), keeps little spare. Still geometric,
/// so pushes stay amortised constant (and large reallocations are remaps, not copies).
pub(crate) fn grow_slots<T>(v: &mut Vec<T>, len: usize) {
    const MIN_GROWTH: usize = 64;
    if v.capacity() < len {
        grow_to(v, len + (len / 8).max(MIN_GROWTH));
    }
}

/// Makes room for `len` items in a list refilled by every pass (the octree's walk order and
/// runs): exactly the first time, so a world that keeps its count keeps no spare, and by an
/// eighth past `len` ([`grow_slots`]) once it outgrows that, not by `Vec`'s doubling.
pub(crate) fn room_for<T>(v: &mut Vec<T>, len: usize) {
    if v.capacity() == 0 {
        grow_to(v, len);
    } else {
        grow_slots(v, len);
    }
}

/// [`grow_to`] as a hint for a size the user gave: room the allocator cannot give (or a size
/// past `isize::MAX` bytes) is not reserved, without an error or a panic.
pub(crate) fn try_grow_to<T>(v: &mut Vec<T>, want: usize) {
    if v.capacity() < want {
        // A hint: on failure the list keeps its capacity and grows as it fills.
        let _ = v.try_reserve_exact(want - v.len());
    }
}

/// Grows `v`'s capacity to `want` if it is below: exactly, where `Vec::reserve` would double
/// a capacity a little short, so a list kept ahead of its peak holds no more than asked.
pub(crate) fn grow_to<T>(v: &mut Vec<T>, want: usize) {
    if v.capacity() < want {
        v.reserve_exact(want - v.len());
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A random packed pair of two distinct slots below `slots` (at least 2), the smaller in
    /// the high half, as `step::pack` makes them.
    fn random_pair(next: &mut impl FnMut() -> u64, slots: u64) -> u64 {
        let a = next() % slots;
        let b = (a + 1 + next() % (slots - 1)) % slots;
        (a.min(b) << 32) | a.max(b)
    }

    fn xorshift(mut s: u64) -> impl FnMut() -> u64 {
        move || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            s
        }
    }

    /// A pool of `threads` threads.
    #[cfg(feature = "parallel")]
    fn pool_of(threads: usize) -> rayon::ThreadPool {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
    }

    #[test]
    fn sorts_like_sort_unstable() {
        let mut next = xorshift(0x9E37_79B9_7F4A_7C15);
        for n in [0, 1, 5, 63, 64, 65, 1000, 5000, 20_000] {
            for slots in [
                2,
                3,
                100,
                2048,
                2049,
                4096,
                4097,
                10_000,
                70_000,
                1 << 22,
                1 << 31,
            ] {
                let mut keys: Vec<u64> = (0..n).map(|_| random_pair(&mut next, slots)).collect();
                // Repeats too: the sort is stable and keeps them.
                if n > 10 {
                    keys[n / 2] = keys[n / 3];
                }
                let mut want = keys.clone();
                want.sort_unstable();
                sort_u64(
                    &mut keys,
                    &mut Vec::new(),
                    PairBits::for_slots(slots as usize),
                );
                assert_eq!(keys, want, "n {n} slots {slots}");
            }
        }
    }

    /// Long lists take fewer, wider passes, short ones keep the narrow plan; every plan's
    /// digits cover the compact key and fit its counters (the sorts of those plans are
    /// checked by `sorts_like_sort_unstable`, whose 20 000 keys take them).
    #[test]
    fn plans_save_passes_on_long_lists() {
        let passes = |slots: usize, n: usize| {
            let layout = PairBits::for_slots(slots);
            let chosen = [plan::TWO, plan::THREE]
                .into_iter()
                .find_map(|p| layout.in_plan(p, n).map(|l| (l, p.0)))
                .unwrap_or((layout, plan::NARROW.0));
            let (l, buckets) = chosen;
            assert!(l.digit_bits * l.passes >= 2 * l.slot_bits);
            assert!(1 << l.digit_bits <= buckets);
            l.passes
        };
        assert_eq!(passes(10_000, 20_000), 2);
        assert_eq!(passes(10_000, 5_000), 3);
        assert_eq!(passes(110_000, 240_000), 3);
        assert_eq!(passes(110_000, 1_000), 4);
        assert_eq!(passes(2048, 100_000), 2);
        assert_eq!(passes(1 << 31, 1 << 24), 6);
    }

    /// `sort_bits_in` sorts a slice stably by the key bits, its answer in whichever buffer
    /// it says, for every pass count (the walk order's keys take one to three).
    #[cfg(feature = "parallel")]
    #[test]
    fn sort_bits_in_says_where_the_sorted_items_are() {
        let mut next = xorshift(0x0123_4567_89AB_CDEF);
        for (n, bits) in [
            (0, 8),
            (1, 8),
            (300, 8),
            (3000, 11),
            (3000, 12),
            (5000, 22),
            (5000, 33),
        ] {
            let mut items: Vec<u64> = (0..n as u64)
                .map(|id| ((next() & ((1 << bits) - 1)) << 32) | id)
                .collect();
            let mut want = items.clone();
            want.sort_by_key(|x| x >> 32);
            let (mut tmp, mut counts) = (vec![0; n], Vec::new());
            let in_tmp = sort_bits_in(&mut items, &mut tmp, &mut counts, 32, bits);
            assert_eq!(if in_tmp { tmp } else { items }, want, "n {n} bits {bits}");
        }
    }

    /// The parallel scatter leaves the serial sort's output (stable: the bits outside the
    /// sorted ones are a payload in source order) for keys read in place with gaps, at 1, 2, 3
    /// and 8 threads and any task count: random keys, every key the same, every key the same
    /// in one digit, few distinct keys, one task's worth of keys, fewer keys than tasks, none.
    #[cfg(feature = "parallel")]
    #[test]
    fn the_parallel_scatter_sorts_as_the_serial_sort() {
        let mut next = xorshift(0x5DEE_CE66_D1CE_4E5B);
        let mut s = ParScatter::default();
        let same_digit = |k: u64, lo: u32| (k & !(0x7FF << (lo + 11))) | (0x2A5 << (lo + 11));
        for threads in [1, 2, 3, 8] {
            let pool = pool_of(threads);
            for (n, lo, bits) in [
                (0, 0, 22),
                (1, 32, 21),
                (5, 32, 21),
                (100, 0, 11),
                (5000, 32, 21),
                (5000, 0, 33),
                (5000, 3, 40),
                (20_000, 32, 32),
            ] {
                for case in ["random", "equal", "equal digit", "few"] {
                    // Every fifth entry of the source is a gap the keys skip.
                    let source: Vec<Option<u64>> = (0..n)
                        .map(|i| {
                            let k = match case {
                                "random" => next(),
                                "equal" => 0x1234_5678_9ABC_DEF0,
                                "equal digit" => same_digit(next(), lo),
                                _ => (next() % 3) << lo | (next() >> 44 << 44),
                            };
                            (i % 5 != 4).then_some(k)
                        })
                        .collect();
                    let listed: Vec<u64> = source.iter().flatten().copied().collect();
                    let (mut want, mut tmp) = (listed.clone(), vec![0; listed.len()]);
                    if sort_bits_in(&mut want, &mut tmp, &mut Vec::new(), lo, bits) {
                        want = tmp.clone();
                    }
                    for tasks in [1, 2, 3, 8, 13] {
                        let mut out = vec![7; listed.len()];
                        let keys = |r: Range<usize>| source[r].iter().flatten().copied();
                        pool.install(|| {
                            sort_bits_par(n, keys, &mut out, &mut tmp, &mut s, tasks, lo, bits);
                        });
                        let at = format!("{case} n {n} bits {lo}+{bits} tasks {tasks}");
                        assert_eq!(out, want, "{at} threads {threads}");
                    }
                }
            }
        }
    }

    /// The table of stretches keeps its allocation from pass to pass: the parallel scatter
    /// allocates nothing in steady state.
    #[cfg(feature = "parallel")]
    #[test]
    fn recycling_the_table_keeps_its_allocation() {
        let mut buf = [0u64; 4];
        let mut table: Vec<&mut [u64]> = Vec::with_capacity(100);
        let at = table.as_ptr() as usize;
        table.push(&mut buf);
        let table: Vec<&'static mut [u64]> = recycle(table);
        assert!(table.is_empty());
        assert_eq!((table.as_ptr() as usize, table.capacity()), (at, 100));
    }

    /// The compact key orders pairs as the full keys do, at the extremes of every layout.
    #[test]
    fn compact_keys_keep_the_order() {
        for slots in [1usize, 2, 5, 2048, 2049, 1 << 16, (1 << 16) + 1, 1 << 31] {
            let layout = PairBits::for_slots(slots);
            let top = slots.saturating_sub(1) as u64;
            let mut keys: Vec<u64> = [0, 1, top / 2, top.saturating_sub(1), top]
                .iter()
                .flat_map(|&a| [0, 1, top / 2, top].map(move |b| (a << 32) | b))
                .collect();
            keys.sort_unstable();
            keys.dedup();
            assert!(layout.passes as usize <= plan::NARROW.1);
            assert!(layout.digit_bits * layout.passes >= 2 * layout.slot_bits);
            assert!(
                keys.windows(2)
                    .all(|w| layout.compact(w[0]) < layout.compact(w[1]))
            );
            assert!(layout.compact(*keys.last().unwrap()) >> (2 * layout.slot_bits) == 0);
        }
    }

    /// The parallel sort gives the serial one's output however the keys are spread over the
    /// producers (empty ones too), for cuts at the quantiles of the keys themselves and of
    /// other keys, any part count and thread count.
    #[cfg(feature = "parallel")]
    #[test]
    fn sorting_in_parts_gives_the_sorted_union() {
        let mut next = xorshift(0x2545_F491_4F6C_DD1D);
        let (mut splitters, mut tmp, mut bounds) = (Vec::new(), Vec::new(), Vec::new());
        for threads in [1, 2, 3] {
            let pool = pool_of(threads);
            for (n, producers, slots) in [
                (0, 3, 500),
                (5, 2, 500),
                (1000, 1, 9000),
                (30_000, 9, 1 << 20),
            ] {
                let mut all: Vec<u64> = (0..n).map(|_| random_pair(&mut next, slots)).collect();
                all.sort_unstable();
                all.dedup();
                let other: Vec<u64> = (0..64).map(|i| (i * slots / 64) << 32).collect();
                for (parts, by) in [
                    (1, &all[..]),
                    (2, &all[..]),
                    (7, &all[..]),
                    (64, &other[..]),
                ] {
                    if by.len() < parts {
                        continue;
                    }
                    split_points(by, |&k| k, parts, &mut splitters);
                    let np = splitters.len() + 1;
                    let mut buckets = vec![Parted::default(); producers];
                    for b in &mut buckets {
                        b.reset(np);
                    }
                    for &k in &all {
                        let i = (next() % producers as u64) as usize;
                        buckets[i].push(part_of(&splitters, k), k);
                    }
                    let mut out = vec![7; 3];
                    pool.install(|| {
                        let layout = PairBits::for_slots(slots as usize);
                        let lent = (&mut bounds, &mut Stretches::default());
                        sort_parts(&buckets, np, &mut out, &mut tmp, lent, layout);
                    });
                    assert_eq!(out, all, "n {n} parts {parts} threads {threads}");
                }
            }
        }
    }
}
