//! The one sweep-and-prune kernel: overlapping pairs within one list of boxes, or between two,
//! each list sorted by its boxes' `min` on one axis.
//!
//! Sorted by `min[AXIS]`, a box `a` can only overlap the boxes after it whose `min[AXIS]` is
//! at most `a.max[AXIS]`; the scan stops at the first one past that, and every box it visits
//! gets the full three-axis test. Between two lists, the box with the smaller `min[AXIS]` (the
//! first list's on a tie) scans the other list from its current position, then steps on: each
//! pair is seen once, by whichever of its boxes starts first.

use crate::geom::SimdBox;

/// Calls `f(i, j)`, `i < j`, once for every overlapping pair of `boxes`, which must be sorted
/// by `min[AXIS]` (closed intervals: touching boxes overlap).
#[inline]
pub(crate) fn self_pairs<const AXIS: usize>(boxes: &[SimdBox], mut f: impl FnMut(usize, usize)) {
    debug_assert!(boxes.is_sorted_by(|p, q| p.min[AXIS] <= q.min[AXIS]));
    for (i, a) in boxes.iter().enumerate() {
        scan::<AXIS>(a, &boxes[i + 1..], |k| f(i, i + 1 + k));
    }
}

/// Calls `f(i, j)` once for every overlapping pair `a[i]` × `b[j]`; both lists must be sorted
/// by `min[AXIS]`.
#[inline]
pub(crate) fn cross_pairs<const AXIS: usize>(
    a: &[SimdBox],
    b: &[SimdBox],
    mut f: impl FnMut(usize, usize),
) {
    debug_assert!(a.is_sorted_by(|p, q| p.min[AXIS] <= q.min[AXIS]));
    debug_assert!(b.is_sorted_by(|p, q| p.min[AXIS] <= q.min[AXIS]));
    let (mut i, mut j) = (0, 0);
    while i < a.len() && j < b.len() {
        if a[i].min[AXIS] <= b[j].min[AXIS] {
            scan::<AXIS>(&a[i], &b[j..], |k| f(i, j + k));
            i += 1;
        } else {
            scan::<AXIS>(&b[j], &a[i..], |k| f(i + k, j));
            j += 1;
        }
    }
}

/// Calls `f(k)` for every `rest[k]` overlapping `a`, scanning `rest` (sorted by `min[AXIS]`,
/// none starting before `a`) until a box starts past `a`'s end.
#[inline]
pub(crate) fn scan<const AXIS: usize>(a: &SimdBox, rest: &[SimdBox], mut f: impl FnMut(usize)) {
    let end = a.max[AXIS];
    for (k, b) in rest.iter().enumerate() {
        if b.min[AXIS] > end {
            break;
        }
        if a.overlaps(b) {
            f(k);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3A;

    /// A deterministic scatter of boxes of mixed sizes, some touching exactly.
    fn boxes(n: usize, seed: u32) -> Vec<SimdBox> {
        let mut s = seed.wrapping_mul(2_654_435_761).max(1);
        let mut next = move || {
            s ^= s << 13;
            s ^= s >> 17;
            s ^= s << 5;
            (s % 64) as f32 * 0.25
        };
        (0..n)
            .map(|_| {
                let min = Vec3A::new(next(), next(), next());
                let size = Vec3A::new(next(), next(), next()) * 0.1;
                SimdBox {
                    min,
                    max: min + size,
                }
            })
            .collect()
    }

    fn brute(a: &[SimdBox], b: &[SimdBox]) -> Vec<(usize, usize)> {
        let mut out = Vec::new();
        for (i, x) in a.iter().enumerate() {
            for (j, y) in b.iter().enumerate() {
                let lanes = x.min.cmple(y.max) & y.min.cmple(x.max);
                if lanes.all() {
                    out.push((i, j));
                }
            }
        }
        out
    }

    fn sorted_on<const AXIS: usize>(mut v: Vec<SimdBox>) -> Vec<SimdBox> {
        v.sort_by(|p, q| p.min[AXIS].total_cmp(&q.min[AXIS]));
        v
    }

    #[test]
    fn self_pairs_equal_all_pairs_on_every_axis() {
        for seed in 1..20 {
            let v = boxes(200, seed);
            for axis in 0..3 {
                let v = match axis {
                    0 => sorted_on::<0>(v.clone()),
                    1 => sorted_on::<1>(v.clone()),
                    _ => sorted_on::<2>(v.clone()),
                };
                let mut got = Vec::new();
                match axis {
                    0 => self_pairs::<0>(&v, |i, j| got.push((i, j))),
                    1 => self_pairs::<1>(&v, |i, j| got.push((i, j))),
                    _ => self_pairs::<2>(&v, |i, j| got.push((i, j))),
                }
                got.sort_unstable();
                let want: Vec<_> = brute(&v, &v).into_iter().filter(|(i, j)| i < j).collect();
                assert_eq!(got, want, "seed {seed} axis {axis}");
            }
        }
    }

    #[test]
    fn cross_pairs_equal_all_pairs_once() {
        for seed in 1..20 {
            let a = sorted_on::<1>(boxes(150, seed));
            let b = sorted_on::<1>(boxes(120, seed + 100));
            let mut got = Vec::new();
            cross_pairs::<1>(&a, &b, |i, j| got.push((i, j)));
            got.sort_unstable();
            assert_eq!(got, brute(&a, &b), "seed {seed}");
        }
    }
}
