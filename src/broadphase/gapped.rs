//! [`Gapped`]: a sorted list patched in place by position, with a gap at its end so that a
//! patch that grows it moves only the stretches between its changes. It holds the candidates,
//! their reverse index and the key pair list.

/// A stretch of old entries `[start, end)` that moves by `shift` places.
#[derive(Clone, Copy, Debug)]
struct Run {
    start: u32,
    end: u32,
    shift: i32,
}

/// [`patch_in`]'s scratch: the runs and the length of old entries per shift.
#[derive(Clone, Debug, Default)]
pub(super) struct Scratch {
    runs: Vec<Run>,
    per_shift: Vec<u32>,
}

impl Scratch {
    /// Grows both lists ahead of their peaks (see [`crate::radix::ahead`]).
    pub(super) fn ahead(&mut self) {
        crate::radix::ahead(&mut self.runs);
        crate::radix::ahead(&mut self.per_shift);
    }

    pub(super) fn heap_bytes(&self) -> usize {
        self.runs.capacity() * core::mem::size_of::<Run>() + self.per_shift.capacity() * 4
    }
}

/// Removes `buf[start + i]` for every `i` of `gone` (ascending, distinct) and inserts `new[k]`
/// before the old entry `at[k]` (`at` ascending, repeats allowed, the list's length appends),
/// in place, moving only the entries whose index changes; the list `buf[start..]` may move to
/// start anywhere in `0..=max_start`.
/// Between two changes the old entries all move by the same shift, and their order is kept.
/// The list's new start is chosen so that the longest total stretch of old entries stays
/// where it is (with `max_start` 0, the start stays 0 and the entries before the first change
/// stay): a change near the front then moves the few entries before it, not the many after
/// it. No entry's new place is still held by an entry moving the other way, so the runs that
/// move left are moved first, front to back, then those that move right, back to front, and
/// the new entries are written last. Returns the list's new start.
fn patch_in<T: Copy>(
    buf: &mut Vec<T>,
    start: usize,
    max_start: usize,
    gone: &[u32],
    at: &[u32],
    new: &[T],
    scratch: &mut Scratch,
) -> usize {
    debug_assert_eq!(at.len(), new.len());
    debug_assert!(start <= buf.len());
    if gone.is_empty() && new.is_empty() {
        return start;
    }
    let old = buf.len() - start;
    let Scratch { runs, per_shift } = scratch;
    runs.clear();
    let (mut g, mut k, mut from, mut shift) = (0, 0, 0usize, 0i32);
    loop {
        let next_at = at.get(k).map_or(old, |&a| a as usize);
        let next_gone = gone.get(g).map_or(old, |&i| i as usize);
        let end = next_at.min(next_gone);
        if end > from {
            runs.push(Run {
                start: from as u32,
                end: end as u32,
                shift,
            });
        }
        from = from.max(end);
        if k < at.len() && next_at <= next_gone {
            shift += 1;
            k += 1;
        } else if g < gone.len() {
            shift -= 1;
            g += 1;
            from = next_gone + 1;
        } else {
            break;
        }
    }
    // The base shift `c`: an old entry at `j` goes to `start - c + j + shift_j`, so the
    // entries whose shift is `c` stay. `c` keeps the new start in `0..=max_start`.
    let lowest = -(gone.len() as i64);
    let (lo, hi) = (start as i64 - max_start as i64, start as i64);
    let mut c = 0i64.clamp(lo, hi);
    if max_start > 0 {
        per_shift.clear();
        per_shift.resize(gone.len() + at.len() + 1, 0);
        for r in runs.iter() {
            per_shift[(i64::from(r.shift) - lowest) as usize] += r.end - r.start;
        }
        let mut best = 0;
        for (i, &n) in per_shift.iter().enumerate() {
            let shift = i as i64 + lowest;
            if n > best && (lo..=hi).contains(&shift) {
                (best, c) = (n, shift);
            }
        }
    }
    let new_start = (start as i64 - c) as usize;
    let len = old + new.len() - gone.len();
    let need = (new_start + len).max(buf.len());
    if need > buf.len() {
        let fill = new.first().copied().unwrap_or_else(|| buf[start]);
        buf.resize(need, fill);
    }
    let place = |r: &Run| (new_start as i64 + i64::from(r.start) + i64::from(r.shift)) as usize;
    for r in runs.iter().filter(|r| i64::from(r.shift) < c) {
        let from = start + r.start as usize;
        buf.copy_within(from..from + (r.end - r.start) as usize, place(r));
    }
    for r in runs.iter().rev().filter(|r| i64::from(r.shift) > c) {
        let from = start + r.start as usize;
        buf.copy_within(from..from + (r.end - r.start) as usize, place(r));
    }
    // The new entry `k` lands after the `k` new ones before it and the old ones before
    // `at[k]` that stay.
    let mut g = 0;
    for (k, (&a, &x)) in at.iter().zip(new).enumerate() {
        while g < gone.len() && gone[g] < a {
            g += 1;
        }
        buf[new_start + a as usize + k - g] = x;
    }
    buf.truncate(new_start + len);
    new_start
}

/// A list kept behind a gap at the front of its buffer, which [`Gapped::patch`] may grow or
/// shrink to move fewer entries: a sorted list patched in place each step (the pair list)
/// moves only the entries between the changes that do not cancel out, instead of every entry
/// after the first change.
#[derive(Clone, Debug)]
pub(super) struct Gapped<T> {
    buf: Vec<T>,
    start: usize,
}

impl<T> Default for Gapped<T> {
    fn default() -> Self {
        Gapped {
            buf: Vec::new(),
            start: 0,
        }
    }
}

impl<T> core::ops::DerefMut for Gapped<T> {
    #[inline]
    fn deref_mut(&mut self) -> &mut [T] {
        &mut self.buf[self.start..]
    }
}

impl<T> core::ops::Deref for Gapped<T> {
    type Target = [T];
    #[inline]
    fn deref(&self) -> &[T] {
        &self.buf[self.start..]
    }
}

/// The gap a list of `len` entries keeps at its front after a rebuild; patches keep it
/// between none and twice this.
fn gap_for(len: usize) -> usize {
    (len / GAP_FRACTION).clamp(MIN_GAP, MAX_GAP)
}

/// A [`Gapped`] list of `len` entries keeps a gap of `len / GAP_FRACTION` entries, at least
/// [`MIN_GAP`] and at most [`MAX_GAP`]: the changes of one step seldom shift the entries by more.
const GAP_FRACTION: usize = 64;
const MIN_GAP: usize = 16;
const MAX_GAP: usize = 4096;

impl<T: Copy> Gapped<T> {
    /// Replaces the list by what `fill` appends to an empty one, behind a gap made of `filler`
    /// for `len` entries (what the list is expected to hold).
    pub(super) fn refill(&mut self, len: usize, filler: T, fill: impl FnOnce(&mut Vec<T>)) {
        self.buf.clear();
        self.start = gap_for(len);
        self.buf.resize(self.start, filler);
        fill(&mut self.buf);
    }

    /// [`patch_in`] of the list, moving its start within the gap.
    pub(super) fn patch(&mut self, gone: &[u32], at: &[u32], new: &[T], scratch: &mut Scratch) {
        let len = self.buf.len() - self.start;
        let max_start = 2 * gap_for(len);
        self.start = patch_in(
            &mut self.buf,
            self.start,
            max_start.max(self.start),
            gone,
            at,
            new,
            scratch,
        );
    }

    /// Empties the list (and its gap).
    pub(super) fn clear(&mut self) {
        self.buf.clear();
        self.start = 0;
    }

    /// Grows the buffer ahead of its peaks (see `radix::ahead`).
    pub(super) fn ahead(&mut self) {
        crate::radix::ahead(&mut self.buf);
    }

    /// Entries the buffer holds room for, the gap's included.
    pub(super) fn capacity(&self) -> usize {
        self.buf.capacity()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `patch_in` (from start 0 without room to move, and from other starts with room) against the obvious
    /// rebuild, on random removals and insertions.
    #[test]
    fn patch_equals_rebuild() {
        let mut seed = 7u64;
        let mut next = |n: u64| {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 33) % n.max(1)
        };
        let mut scratch = Scratch::default();
        let mut moved_less = 0;
        for round in 0..4000 {
            let n = next(40) as u32;
            let old: Vec<u32> = (0..n).map(|i| 10 * i).collect();
            let gone: Vec<u32> = (0..n).filter(|_| next(4) == 0).collect();
            let mut at: Vec<u32> = (0..next(6))
                .map(|_| next(u64::from(n) + 1) as u32)
                .collect();
            at.sort_unstable();
            let new: Vec<u32> = at
                .iter()
                .enumerate()
                .map(|(k, &a)| 10 * a + 1 + k as u32)
                .collect();
            let mut want: Vec<u32> = Vec::new();
            for i in 0..=n {
                for (k, &a) in at.iter().enumerate() {
                    if a == i {
                        want.push(new[k]);
                    }
                }
                if i < n && !gone.contains(&i) {
                    want.push(old[i as usize]);
                }
            }
            if round % 2 == 0 {
                let mut v = old.clone();
                patch_in(&mut v, 0, 0, &gone, &at, &new, &mut scratch);
                assert_eq!(v, want, "round {round}: gone {gone:?} at {at:?}");
            } else {
                let start = next(8) as usize;
                let max_start = start + next(8) as usize;
                let mut buf: Vec<u32> = vec![u32::MAX; start];
                buf.extend_from_slice(&old);
                // Old entries found at their old place, the list starting at `buf`'s index
                // `-from` (entries are distinct).
                let stay = |buf: &[u32], from: isize| {
                    (0..n as usize)
                        .filter(|&j| {
                            let p = from + j as isize;
                            p >= 0 && buf.get(p as usize) == Some(&old[j])
                        })
                        .count()
                };
                let at_zero = {
                    let mut v = old.clone();
                    patch_in(&mut v, 0, 0, &gone, &at, &new, &mut scratch);
                    stay(&v, 0)
                };
                let new_start =
                    patch_in(&mut buf, start, max_start, &gone, &at, &new, &mut scratch);
                assert!(new_start <= max_start, "round {round}: start {new_start}");
                assert_eq!(
                    &buf[new_start..],
                    &want[..],
                    "round {round}: start {start} max {max_start} gone {gone:?} at {at:?}"
                );
                // Entries that kept their place: never fewer than with the start fixed.
                let kept = stay(&buf[new_start..], start as isize - new_start as isize);
                assert!(kept >= at_zero, "round {round}: kept {kept} < {at_zero}");
                moved_less += usize::from(kept > at_zero);
            }
        }
        assert!(moved_less > 0, "the start never moved");
    }
}
