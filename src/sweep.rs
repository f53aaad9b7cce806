//! The one sweep-and-prune kernel: overlapping pairs within one list of boxes, or between two,
//! each list sorted by where its boxes start on one axis; and the all-against-all loops that
//! short lists take instead.
//!
//! Sorted by `min[AXIS]`, a box `a` can only overlap the boxes after it whose `min[AXIS]` is
//! at most `a.max[AXIS]`; the scan stops at the first one past that, and every box it visits
//! gets the full three-axis test. Between two lists, the box with the smaller `min[AXIS]` (the
//! first list's on a tie) scans the other list from its current position, then steps on: each
//! pair is seen once, by whichever of its boxes starts first.
//!
//! A list is either boxes stored in that order ([`Boxes`], the axis a const parameter), or an
//! order over boxes left where they are ([`Ordered`]: sorted entries `key << 32 | index`, where
//! `key` is the start mapped to an integer by [`ordered_bits`], so sorting is a plain `u64`
//! sort and the scan compares integers). The kernel functions take any [`Sorted`] list and
//! return how many box tests they did.

use crate::geom::{SimdBox, ordered_bits};
use core::borrow::Borrow;

/// A list in sweep order: where each element starts, where a box ends in the same terms, each
/// element's box and its index in the caller's list.
pub(crate) trait Sorted {
    /// What starts and ends compare as.
    type Key: PartialOrd + Copy;
    /// Number of elements.
    fn len(&self) -> usize;
    /// Where element `k` starts; non-decreasing in `k`.
    fn start(&self, k: usize) -> Self::Key;
    /// The largest start of an element that `b` can overlap along the axis.
    fn end(&self, b: &SimdBox) -> Self::Key;
    /// Element `k`'s box.
    fn get(&self, k: usize) -> &SimdBox;
    /// Element `k`'s index in the caller's list.
    fn index(&self, k: usize) -> usize;
}

/// Boxes stored sorted by `min[AXIS]`; element `k` is `boxes[k]`.
#[derive(Clone, Copy, Debug)]
#[allow(
    dead_code,
    reason = "the entry points for boxes stored in sweep order; the structures here sweep `Ordered` lists over boxes left in place, so only the tests call these"
)]
pub(crate) struct Boxes<'a, const AXIS: usize>(pub(crate) &'a [SimdBox]);

impl<const AXIS: usize> Sorted for Boxes<'_, AXIS> {
    type Key = f32;
    #[inline]
    fn len(&self) -> usize {
        self.0.len()
    }
    #[inline]
    fn start(&self, k: usize) -> f32 {
        self.0[k].min[AXIS]
    }
    #[inline]
    fn end(&self, b: &SimdBox) -> f32 {
        b.max[AXIS]
    }
    #[inline]
    fn get(&self, k: usize) -> &SimdBox {
        &self.0[k]
    }
    #[inline]
    fn index(&self, k: usize) -> usize {
        k
    }
}

/// Items left in place, visited in the order of `order` (filled by [`sort_entries`] on the same
/// `items` and `axis`): element `k` is `items[order[k] as u32]`.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Ordered<'a, T> {
    pub(crate) order: &'a [u64],
    pub(crate) items: &'a [T],
    pub(crate) axis: usize,
}

/// The integer a coordinate sorts by: [`ordered_bits`] of `x + 0.0`, so that `-0.0` and `0.0`
/// tie (a box ending at `-0.0` touches one starting at `0.0`).
#[inline]
fn key(x: f32) -> u64 {
    u64::from(ordered_bits(x + 0.0))
}

impl<T: Borrow<SimdBox>> Sorted for Ordered<'_, T> {
    type Key = u64;
    #[inline]
    fn len(&self) -> usize {
        self.order.len()
    }
    #[inline]
    fn start(&self, k: usize) -> u64 {
        self.order[k]
    }
    /// An entry `key << 32 | index` starts no later than `b` ends iff it is at most this.
    #[inline]
    fn end(&self, b: &SimdBox) -> u64 {
        key(b.max[self.axis]) << 32 | u64::from(u32::MAX)
    }
    #[inline]
    fn get(&self, k: usize) -> &SimdBox {
        self.items[self.index(k)].borrow()
    }
    #[inline]
    fn index(&self, k: usize) -> usize {
        self.order[k] as u32 as usize
    }
}

/// Fills `order` with the entries `key(min[axis]) << 32 | index` of `items`, sorted: the order
/// of an [`Ordered`] list. At most `u32::MAX` items.
#[inline]
pub(crate) fn sort_entries<T: Borrow<SimdBox>>(order: &mut Vec<u64>, items: &[T], axis: usize) {
    fill_sorted(order, items.iter().enumerate(), axis);
}

/// [`sort_entries`] of the items `keep` accepts only.
#[inline]
pub(crate) fn sort_entries_where<T: Borrow<SimdBox>>(
    order: &mut Vec<u64>,
    items: &[T],
    axis: usize,
    keep: impl Fn(&T) -> bool,
) {
    fill_sorted(
        order,
        items.iter().enumerate().filter(|(_, t)| keep(t)),
        axis,
    );
}

/// Fills `order` with the sorted entries of the `(index, item)`s (an exact-size iterator for
/// [`sort_entries`], so the fill writes without a capacity check per entry).
#[inline]
fn fill_sorted<'a, T: Borrow<SimdBox> + 'a>(
    order: &mut Vec<u64>,
    items: impl Iterator<Item = (usize, &'a T)>,
    axis: usize,
) {
    order.clear();
    order.extend(items.map(|(i, t)| {
        debug_assert!(i <= u32::MAX as usize);
        key(t.borrow().min[axis]) << 32 | i as u64
    }));
    order.sort_unstable();
}

/// Calls `f(i, j)` once for every overlapping pair of the list (`i`, `j` the caller's indices,
/// `i` of the element that comes first); returns the number of box tests.
#[inline]
pub(crate) fn self_pairs_of<L: Sorted>(list: &L, mut f: impl FnMut(usize, usize)) -> u64 {
    let mut tests = 0;
    for k in 0..list.len() {
        let a = list.get(k);
        let i = list.index(k);
        tests += scan_from(list, k + 1, a, list.end(a), |m| f(i, list.index(m)));
    }
    tests
}

/// Calls `f(i, j)` once for every overlapping pair of an element `i` of `a` and `j` of `b`
/// (the caller's indices); returns the number of box tests.
#[inline]
pub(crate) fn cross_pairs_of<A: Sorted, B: Sorted<Key = A::Key>>(
    a: &A,
    b: &B,
    mut f: impl FnMut(usize, usize),
) -> u64 {
    let (mut i, mut j, mut tests) = (0, 0, 0);
    while i < a.len() && j < b.len() {
        if a.start(i) <= b.start(j) {
            let (x, xi) = (a.get(i), a.index(i));
            tests += scan_from(b, j, x, b.end(x), |m| f(xi, b.index(m)));
            i += 1;
        } else {
            let (y, yj) = (b.get(j), b.index(j));
            tests += scan_from(a, i, y, a.end(y), |m| f(a.index(m), yj));
            j += 1;
        }
    }
    tests
}

/// Calls `f(m)` for every element `m >= from` of `list` whose box overlaps `a`, scanning until
/// an element starts past `end`; returns the number of elements tested.
#[inline]
fn scan_from<L: Sorted>(
    list: &L,
    from: usize,
    a: &SimdBox,
    end: L::Key,
    mut f: impl FnMut(usize),
) -> u64 {
    let mut m = from;
    while m < list.len() {
        if list.start(m) > end {
            break;
        }
        if a.overlaps(list.get(m)) {
            f(m);
        }
        m += 1;
    }
    (m - from) as u64
}

/// Calls `f(i, j)`, `i < j`, once for every overlapping pair of `boxes`, which must be sorted
/// by `min[AXIS]` (closed intervals: touching boxes overlap).
#[inline]
pub(crate) fn self_pairs<const AXIS: usize>(boxes: &[SimdBox], f: impl FnMut(usize, usize)) {
    debug_assert!(boxes.is_sorted_by(|p, q| p.min[AXIS] <= q.min[AXIS]));
    self_pairs_of(&Boxes::<AXIS>(boxes), f);
}

/// Calls `f(i, a, j, b)` (the indices and the items), `i < j`, for every overlapping pair of
/// `items`, all against all: the loop for lists too short to be worth sorting. Returns the
/// number of box tests.
#[inline]
pub(crate) fn all_pairs<T: Borrow<SimdBox>>(
    items: &[T],
    mut f: impl FnMut(usize, &T, usize, &T),
) -> u64 {
    for (i, a) in items.iter().enumerate() {
        each_overlap(a.borrow(), &items[i + 1..], |k, b| f(i, a, i + 1 + k, b));
    }
    let n = items.len() as u64;
    n * n.saturating_sub(1) / 2
}

/// Calls `f(i, a[i], j, b[j])` for every overlapping pair `a[i]` × `b[j]`, all against all,
/// the longer list in the inner loop. Returns the number of box tests.
#[inline]
pub(crate) fn all_cross<T: Borrow<SimdBox>, U: Borrow<SimdBox>>(
    a: &[T],
    b: &[U],
    mut f: impl FnMut(usize, &T, usize, &U),
) -> u64 {
    if a.len() <= b.len() {
        for (i, x) in a.iter().enumerate() {
            each_overlap(x.borrow(), b, |j, y| f(i, x, j, y));
        }
    } else {
        for (j, y) in b.iter().enumerate() {
            each_overlap(y.borrow(), a, |i, x| f(i, x, j, y));
        }
    }
    (a.len() * b.len()) as u64
}

/// Calls `f(k, &list[k])` for every `list[k]` overlapping `a`. The loop keeps no index: `k` is
/// worked out from the iterator's remaining length on a hit only.
#[inline]
fn each_overlap<T: Borrow<SimdBox>>(a: &SimdBox, list: &[T], mut f: impl FnMut(usize, &T)) {
    let mut rest = list.iter();
    while let Some(b) = rest.next() {
        if a.overlaps(b.borrow()) {
            f(list.len() - 1 - rest.len(), b);
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

    /// Boxes around the origin whose faces lie on `-0.0`, `0.0` and `±∞` as well.
    fn signed_boxes(n: usize, seed: u32) -> Vec<SimdBox> {
        let pool = [
            f32::NEG_INFINITY,
            -2.0,
            -0.5,
            -0.0,
            0.0,
            0.5,
            2.0,
            f32::INFINITY,
        ];
        let mut s = seed.wrapping_mul(2_654_435_761).max(1);
        let mut next = move || {
            s ^= s << 13;
            s ^= s >> 17;
            s ^= s << 5;
            pool[(s % pool.len() as u32) as usize]
        };
        (0..n)
            .map(|_| {
                let (a, b) = (
                    Vec3A::new(next(), next(), next()),
                    Vec3A::new(next(), next(), next()),
                );
                SimdBox {
                    min: a.min(b),
                    max: a.max(b),
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

    /// The ordered lists over boxes left in place, on every axis, with faces on both zeros
    /// and on the infinities: the same pairs as all against all, each once, and the short
    /// loops agree.
    #[test]
    fn ordered_lists_equal_all_pairs_once() {
        for seed in 1..30 {
            let (a, b) = (signed_boxes(90, seed), signed_boxes(70, seed + 50));
            let (mut oa, mut ob) = (Vec::new(), Vec::new());
            for axis in 0..3 {
                sort_entries(&mut oa, &a, axis);
                sort_entries(&mut ob, &b, axis);
                let la = Ordered {
                    order: &oa,
                    items: &a,
                    axis,
                };
                let lb = Ordered {
                    order: &ob,
                    items: &b,
                    axis,
                };
                let mut got = Vec::new();
                self_pairs_of(&la, |i, j| got.push((i.min(j), i.max(j))));
                got.sort_unstable();
                let want: Vec<_> = brute(&a, &a).into_iter().filter(|(i, j)| i < j).collect();
                assert_eq!(got, want, "self, seed {seed} axis {axis}");
                let mut short = Vec::new();
                all_pairs(&a, |i, _, j, _| short.push((i, j)));
                assert_eq!(short, want);

                let mut got = Vec::new();
                cross_pairs_of(&la, &lb, |i, j| got.push((i, j)));
                got.sort_unstable();
                let want = brute(&a, &b);
                assert_eq!(got, want, "cross, seed {seed} axis {axis}");
                for (x, y) in [(&a[..], &b[..]), (&a[..3], &b[..])] {
                    let mut short = Vec::new();
                    all_cross(x, y, |i, _, j, _| short.push((i, j)));
                    short.sort_unstable();
                    assert_eq!(short, brute(x, y));
                    let mut short = Vec::new();
                    all_cross(y, x, |j, _, i, _| short.push((i, j)));
                    short.sort_unstable();
                    assert_eq!(short, brute(x, y));
                }
            }
        }
    }

    #[test]
    fn entries_keep_only_what_is_kept_and_count_the_tests() {
        let v = boxes(100, 3);
        let mut order = Vec::new();
        sort_entries_where(&mut order, &v, 2, |b| b.min.x < 8.0);
        let kept: Vec<usize> = (0..v.len()).filter(|&i| v[i].min.x < 8.0).collect();
        let mut listed: Vec<usize> = order.iter().map(|&e| e as u32 as usize).collect();
        assert!(order.is_sorted());
        listed.sort_unstable();
        assert_eq!(listed, kept);
        let list = Ordered {
            order: &order,
            items: &v,
            axis: 2,
        };
        let tests = self_pairs_of(&list, |i, j| {
            assert!(kept.contains(&i) && kept.contains(&j))
        });
        let n = kept.len() as u64;
        assert!(tests <= n * (n - 1) / 2);
        assert_eq!(all_pairs(&v[..10], |_, _, _, _| {}), 45);
        assert_eq!(all_cross(&v[..10], &v[..7], |_, _, _, _| {}), 70);
    }
}
