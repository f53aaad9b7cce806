//! What both pair passes stand on: the spheres radix-sorted by their node's walk key into
//! contiguous walk-ordered copies ([`Hot`]), the runs of equal keys (one per occupied node), and
//! the [`Tester`] that runs and counts the box tests of a pass through the sweep kernel.
//!
//! Order. Every sphere carries its node's walk key (`Lattice::walk_key`). A pass LSD-radix-sorts
//! `(walk key, id)` (two or three streaming passes; the order of the dense ids is left alone,
//! so `update` keeps streaming in insertion order) and gathers each sphere's box and cell range
//! into a contiguous walk-ordered array. A pass then never chases a list: each node is a run of
//! that array.

use super::placement::walk_key_bits;
use super::region::Lent;
use super::{NONE, Octree};
use crate::geom::SimdBox;
use crate::pair::ProxyKey;
#[cfg(feature = "parallel")]
use crate::radix::{ahead, sort_bits_in};
use crate::radix::{room_for, sort_bits, sort_bits_by};
use crate::sweep::{self, Ordered};
use core::borrow::Borrow;

/// Lists with at most this many spheres are tested all against all; longer ones are swept:
/// below it sorting the list costs more than the tests it saves.
pub(super) const SHORT_SELF: usize = 16;
/// Two lists with at most this many candidate pairs are tested all against all; larger ones
/// are swept: a sweep sorts both lists first, which only pays once the tests it skips
/// outnumber the sort's steps.
pub(super) const SHORT_CROSS: usize = 1024;
/// Two lists with a side of at most this many spheres are tested all against all: each sphere
/// of the other side then costs at most this many tests, less than its share of a sort.
pub(super) const SHORT_SIDE: usize = 4;

/// A sphere as the passes read it: box, integer cell range and id. 48 bytes.
#[derive(Clone, Copy, Debug)]
pub(super) struct Hot {
    /// `center ± radius`. 32 bytes.
    pub(super) bx: SimdBox,
    /// Range on the integer lattice, clamped to the lattice. 12 bytes.
    pub(super) qmin: [u16; 3],
    pub(super) qmax: [u16; 3],
    /// The sphere's id (its key is the tree's `key_of(id)`). 4 bytes.
    pub(super) id: u32,
}
const _: () = assert!(core::mem::size_of::<Hot>() == 48);

impl Hot {
    /// A placeholder for buffers about to be overwritten.
    pub(super) const EMPTY: Hot = Hot {
        bx: SimdBox::EMPTY,
        qmin: [0; 3],
        qmax: [0; 3],
        id: 0,
    };

    #[inline]
    pub(super) fn overlaps(&self, o: &Hot) -> bool {
        self.bx.overlaps(&o.bx)
    }
}

impl Borrow<SimdBox> for Hot {
    #[inline]
    fn borrow(&self) -> &SimdBox {
        &self.bx
    }
}

/// The two sweep orders a cross sweep needs, reused by every pass.
#[derive(Clone, Debug, Default)]
pub(super) struct Sweeps {
    pub(super) a: Vec<u64>,
    pub(super) b: Vec<u64>,
}

/// Buffers of the walk order, reused by every pass; they never shrink.
#[derive(Clone, Debug, Default)]
pub(super) struct Scratch {
    /// `(walk key << 32) | id`, sorted (the radix sort's second buffer is `node_key`, which
    /// the sorted items are then copied into).
    items: Vec<u64>,
    /// `(walk key, id)` for trees too deep for a 32-bit key (depth 10), and the radix sort's
    /// second buffer for them.
    wide: Vec<(u64, u32)>,
    wide_tmp: Vec<(u64, u32)>,
    counts: Vec<u32>,
    /// Walk-ordered copies: hot data and walk key of each sphere.
    pub(super) hot: Vec<Hot>,
    pub(super) node_key: Vec<u64>,
    pub(super) sweeps: Sweeps,
    /// The parallel sort's buffers (see [`Octree::sort_into_walk_order_par`]).
    #[cfg(feature = "parallel")]
    par: ParSort,
}

/// The most parts a parallel walk-order sort splits the spheres into: its lists number the
/// parts squared.
#[cfg(feature = "parallel")]
const MAX_PARTS: usize = 32;

/// Buffers of the parallel walk-order sort, reused by every pass; they never shrink.
#[cfg(feature = "parallel")]
#[derive(Clone, Debug, Default)]
struct ParSort {
    /// Walk keys sampled from the spheres, sorted, to pick the parts' first keys from.
    sample: Vec<u64>,
    /// The first walk key of every part but the first, increasing.
    splitters: Vec<u64>,
    /// Per range of ids and part: `(walk key << 32) | id` of the range's spheres in the part;
    /// range `c`'s part `p` at `c · parts + p`.
    buckets: Vec<Vec<u64>>,
    /// Per part: its sorting buffers.
    parts: Vec<PartSort>,
    /// The parts' first walk positions, and the sphere count last.
    bounds: Vec<u32>,
}

/// One part's radix counts (its items and their second buffer are its stretches of
/// `Scratch::items` and `Scratch::node_key`).
#[cfg(feature = "parallel")]
#[derive(Clone, Debug, Default)]
struct PartSort {
    counts: Vec<u32>,
}

#[cfg(feature = "parallel")]
impl ParSort {
    fn heap_bytes(&self) -> usize {
        self.sample.capacity() * 8
            + self.splitters.capacity() * 8
            + self.buckets.iter().map(|b| b.capacity() * 8).sum::<usize>()
            + self.bounds.capacity() * 4
            + self
                .parts
                .iter()
                .map(|p| p.counts.capacity() * 4)
                .sum::<usize>()
    }
}

impl Scratch {
    /// The buffers a re-root proposal borrows between passes (see [`Lent`]): the sort's
    /// items, the walk keys as its second buffer, and the counts.
    pub(super) fn lend(&mut self) -> Lent<'_> {
        Lent {
            values: &mut self.items,
            tmp: &mut self.node_key,
            counts: &mut self.counts,
        }
    }
    /// The sort's item buffer, whose contents matter only during a pass.
    pub(super) fn idle_items(&mut self) -> &mut Vec<u64> {
        &mut self.items
    }

    /// Heap bytes held (capacities).
    pub(super) fn heap_bytes(&self) -> usize {
        use core::mem::size_of_val;
        let v = |n: usize, one: usize| n * one;
        v(self.items.capacity(), 8)
            + v(self.wide.capacity() + self.wide_tmp.capacity(), 16)
            + v(self.counts.capacity(), 4)
            + v(self.hot.capacity(), size_of_val(&Hot::EMPTY))
            + v(self.node_key.capacity(), 8)
            + v(self.sweeps.a.capacity() + self.sweeps.b.capacity(), 8)
            + self.par_heap_bytes()
    }

    #[cfg(feature = "parallel")]
    fn par_heap_bytes(&self) -> usize {
        self.par.heap_bytes()
    }
    #[cfg(not(feature = "parallel"))]
    fn par_heap_bytes(&self) -> usize {
        0
    }
}

/// The runs of equal keys of `keys` (sorted): `(key, start, end)` for each, in order.
#[inline]
pub(super) fn runs(keys: &[u64]) -> impl Iterator<Item = (u64, usize, usize)> + '_ {
    let mut i = 0;
    core::iter::from_fn(move || {
        let &key = keys.get(i)?;
        let start = i;
        i += keys[i..].iter().take_while(|&&k| k == key).count();
        Some((key, start, i))
    })
}

/// A pass's view of the walk order: the sorted spheres and their node keys, the tester that
/// runs and counts the pass's box tests, and the sweep buffers.
pub(super) struct Walk<'a, F> {
    pub(super) hot: &'a [Hot],
    pub(super) node_key: &'a [u64],
    pub(super) t: Tester<'a, F>,
    pub(super) sweeps: &'a mut Sweeps,
}

/// Runs and counts the box tests of one pass, mapping ids to proxy keys.
pub(super) struct Tester<'a, F> {
    /// The tree's key versions by id.
    pub(super) versions: &'a [u32],
    pub(super) tests: u64,
    pub(super) emit: F,
}

/// True if `a × b` is tested all against all rather than swept.
#[inline]
pub(super) fn is_short_cross(a: usize, b: usize) -> bool {
    a * b <= SHORT_CROSS || a.min(b) <= SHORT_SIDE
}

impl<F: FnMut(ProxyKey, ProxyKey)> Tester<'_, F> {
    /// Tests one pair and emits it if it overlaps.
    #[inline]
    pub(super) fn test(&mut self, a: &Hot, b: &Hot) {
        self.tests += 1;
        if a.overlaps(b) {
            self.emit(a, b);
        }
    }

    /// Emits a pair known to overlap.
    #[inline]
    pub(super) fn emit(&mut self, a: &Hot, b: &Hot) {
        (self.emit)(
            super::key_at(self.versions, a.id),
            super::key_at(self.versions, b.id),
        );
    }

    /// Every pair within `list`: all against all when short, else a sweep along x.
    #[inline(never)]
    pub(super) fn within(&mut self, list: &[Hot], sweeps: &mut Sweeps) {
        if list.len() <= SHORT_SELF {
            self.tests += sweep::all_pairs(list, |_, a, _, b| self.emit(a, b));
        } else {
            self.sweep_within(list, &mut sweeps.a);
        }
    }

    /// [`Tester::within`] for long lists.
    #[inline(never)]
    fn sweep_within(&mut self, list: &[Hot], order: &mut Vec<u64>) {
        sweep::sort_entries(order, list, 0);
        let sorted = Ordered {
            order,
            items: list,
            axis: 0,
        };
        self.tests += sweep::self_pairs_of(&sorted, |i, j| self.emit(&list[i], &list[j]));
    }

    /// Every pair across the disjoint lists `a` and `b`: all against all when small, else a
    /// merged sweep along x.
    #[inline(never)]
    pub(super) fn between(&mut self, a: &[Hot], b: &[Hot], sweeps: &mut Sweeps) {
        if is_short_cross(a.len(), b.len()) {
            self.tests += sweep::all_cross(a, b, |_, x, _, y| self.emit(x, y));
        } else {
            sweep::sort_entries(&mut sweeps.a, a, 0);
            self.sweep_sorted(a, b, 0, sweeps);
        }
    }

    /// Every pair across the spheres of `a` listed in `sweeps.a` (sorted along `axis` by
    /// [`sweep::sort_entries`] or [`sweep::sort_entries_where`]) and all of `b`, by a merged
    /// sweep along `axis`.
    #[inline(never)]
    pub(super) fn sweep_sorted(&mut self, a: &[Hot], b: &[Hot], axis: usize, sweeps: &mut Sweeps) {
        sweep::sort_entries(&mut sweeps.b, b, axis);
        let (sa, sb) = (
            Ordered {
                order: &sweeps.a,
                items: a,
                axis,
            },
            Ordered {
                order: &sweeps.b,
                items: b,
                axis,
            },
        );
        self.tests += sweep::cross_pairs_of(&sa, &sb, |i, j| self.emit(&a[i], &b[j]));
    }
}

impl Octree {
    /// Sorts the spheres into walk order in `s` and returns a pass's view of it, with a tester
    /// that hands the overlapping pairs to `emit`; `None` for an empty tree.
    pub(super) fn begin_pass<'a, F>(&'a self, s: &'a mut Scratch, emit: F) -> Option<Walk<'a, F>> {
        if self.objs.is_empty() {
            return None;
        }
        self.sort_into_walk_order(s);
        Some(Walk {
            hot: &s.hot,
            node_key: &s.node_key,
            t: Tester {
                versions: &self.versions,
                tests: 0,
                emit,
            },
            sweeps: &mut s.sweeps,
        })
    }

    /// Sorts the spheres by walk key and fills the walk-ordered arrays of `s`: box, cell
    /// range and id, and walk key.
    fn sort_into_walk_order(&self, s: &mut Scratch) {
        let Scratch {
            items,
            wide,
            wide_tmp,
            counts,
            hot,
            node_key,
            ..
        } = s;
        let key_bits = walk_key_bits(self.lattice.depth);
        // Every buffer sized by the sphere count grows by `room_for`, not by doubling.
        let n = self.live;
        // `node_key` first maps ids to walk positions (see `scatter`).
        room_for(node_key, self.objs.len());
        room_for(hot, n);
        if key_bits <= 32 {
            room_for(items, n);
            items.clear();
            items.extend(
                self.objs
                    .iter()
                    .enumerate()
                    .filter(|(_, o)| o.node != NONE)
                    .map(|(id, o)| (u64::from(o.walk_key) << 32) | id as u64),
            );
            sort_bits(items, node_key, counts, 32, key_bits);
            self.scatter(items.iter().map(|&x| (x >> 32, x as u32)), hot, node_key);
        } else {
            room_for(wide, n);
            wide.clear();
            wide.extend(
                self.objs
                    .iter()
                    .enumerate()
                    .filter(|(_, o)| o.node != NONE)
                    .map(|(id, o)| (self.lattice.walk_key(o.node), id as u32)),
            );
            // Ids are unique and listed in increasing order, so the stable sort by walk key
            // alone gives the `(walk key, id)` order.
            sort_bits_by(wide, wide_tmp, counts, |&(key, _)| key, 0, key_bits);
            self.scatter(wide.iter().copied(), hot, node_key);
        }
    }

    /// Fills the walk-ordered copies from the sorted `(walk key, id)` sequence. Each sphere's
    /// walk position is noted by id first (in `node_key`, free until its keys are written
    /// last); then one pass reads the spheres in id order, as they lie in memory, and stores
    /// each at its position: stores to scattered places do not stall the loop the way loads
    /// from them would.
    fn scatter(
        &self,
        order: impl Iterator<Item = (u64, u32)> + Clone,
        hot: &mut Vec<Hot>,
        node_key: &mut Vec<u64>,
    ) {
        let n = self.live;
        let rank = node_key;
        rank.resize(self.objs.len(), 0);
        for (pos, (_, id)) in order.clone().enumerate() {
            rank[id as usize] = pos as u64;
        }
        // `rank` maps the live ids onto `0..n`: every entry below is overwritten, so the
        // buffers only change length when the sphere count does.
        hot.resize(n, Hot::EMPTY);
        for (id, (o, &pos)) in self.objs.iter().zip(rank.iter()).enumerate() {
            if o.node == NONE {
                continue;
            }
            hot[pos as usize] = Hot {
                bx: o.simd_box(),
                qmin: o.qmin,
                qmax: o.qmax,
                id: id as u32,
            };
        }
        let node_key = rank;
        node_key.clear();
        node_key.extend(order.map(|(key, _)| key));
    }
}

/// Spheres per part of the parallel walk-order sort, at least: a part's fixed costs (the radix
/// sort's counters, handing out the task) outweigh the split below it.
#[cfg(feature = "parallel")]
const MIN_PART_SPHERES: usize = 4096;
/// Walk keys sampled per part to pick the parts' first keys from: enough that the parts'
/// sizes stay within a few percent of each other.
#[cfg(feature = "parallel")]
const SAMPLES_PER_PART: usize = 64;

#[cfg(feature = "parallel")]
impl Octree {
    /// [`Octree::sort_into_walk_order`] split over rayon's current pool: the walk keys are cut
    /// into at most `parts` ranges of about equal sphere counts (quantiles of a sample), each
    /// a run of the walk order, and each range is gathered, sorted and copied out by its own
    /// task. Keys and ids are unique together, so the walk order is the serial sort's, whatever
    /// the cut. Trees too deep for 32-bit keys, or too small for two parts, sort serially.
    pub(super) fn sort_into_walk_order_par(&self, s: &mut Scratch, parts: usize) {
        use rayon::prelude::*;
        let key_bits = walk_key_bits(self.lattice.depth);
        let parts = parts.min(MAX_PARTS).min(self.live / MIN_PART_SPHERES);
        if key_bits > 32 || parts < 2 {
            self.sort_into_walk_order(s);
            return;
        }
        let Scratch {
            items,
            hot,
            node_key,
            par,
            ..
        } = s;
        let objs = &self.objs;
        let stride = (objs.len() / (parts * SAMPLES_PER_PART)).max(1);
        par.sample.clear();
        par.sample.extend(
            objs.iter()
                .step_by(stride)
                .filter(|o| o.node != NONE)
                .map(|o| u64::from(o.walk_key)),
        );
        if par.sample.is_empty() {
            self.sort_into_walk_order(s);
            return;
        }
        par.sample.sort_unstable();
        par.splitters.clear();
        for p in 1..parts {
            let k = par.sample[par.sample.len() * p / parts];
            if par.splitters.last().is_none_or(|&last| last < k) {
                par.splitters.push(k);
            }
        }
        // Each range of ids lists its spheres by part (the number of splitters at most the
        // walk key) as `(walk key << 32) | id`: a part then sorts only its own lists.
        let np = par.splitters.len() + 1;
        let splitters = &par.splitters;
        if par.buckets.len() < np * np {
            par.buckets.resize_with(np * np, Vec::new);
        }
        for b in &mut par.buckets[..np * np] {
            b.clear();
        }
        let range = objs.len().div_ceil(np);
        par.buckets[..np * np]
            .par_chunks_mut(np)
            .zip(objs.par_chunks(range))
            .enumerate()
            .for_each(|(c, (buckets, objs))| {
                for (i, o) in objs.iter().enumerate() {
                    if o.node != NONE {
                        // Counted without a branch: there are at most `MAX_PARTS − 1`.
                        let p: usize = splitters
                            .iter()
                            .map(|&x| usize::from(x <= u64::from(o.walk_key)))
                            .sum();
                        let key = u64::from(o.walk_key);
                        buckets[p].push((key << 32) | (c * range + i) as u64);
                    }
                }
                buckets.iter_mut().for_each(ahead);
            });
        par.bounds.clear();
        par.bounds.push(0);
        for p in 0..np {
            let len: usize = (0..np).map(|c| par.buckets[c * np + p].len()).sum();
            par.bounds.push(par.bounds[p] + len as u32);
        }
        let n = self.live;
        debug_assert_eq!(par.bounds[np] as usize, n);
        // Grown by `room_for`, as in the serial sort.
        room_for(items, n);
        room_for(hot, n);
        room_for(node_key, n);
        items.resize(n, 0);
        hot.resize(n, Hot::EMPTY);
        node_key.resize(n, 0);
        if par.parts.len() < np {
            par.parts.resize_with(np, PartSort::default);
        }
        let job = Parts {
            tree: self,
            buckets: &par.buckets[..np * np],
            bounds: &par.bounds,
            key_bits,
        };
        job.fill(0, &mut par.parts[..np], items, hot, node_key);
    }
}

/// What every part of a parallel walk-order sort reads.
#[cfg(feature = "parallel")]
struct Parts<'a> {
    buckets: &'a [Vec<u64>],
    tree: &'a Octree,
    bounds: &'a [u32],
    key_bits: u32,
}

#[cfg(feature = "parallel")]
impl Parts<'_> {
    /// Fills the walk-ordered copies of parts `first..first + parts.len()`, whose positions
    /// `items`, `hot` and `node_key` are, halving the parts between two tasks until
    /// one is left.
    fn fill(
        &self,
        first: usize,
        parts: &mut [PartSort],
        items: &mut [u64],
        hot: &mut [Hot],
        node_key: &mut [u64],
    ) {
        if let [part] = parts {
            self.fill_one(first, part, items, hot, node_key);
            return;
        }
        let mid = parts.len() / 2;
        let at = (self.bounds[first + mid] - self.bounds[first]) as usize;
        let (pa, pb) = parts.split_at_mut(mid);
        let (ia, ib) = items.split_at_mut(at);
        let (ha, hb) = hot.split_at_mut(at);
        let (na, nb) = node_key.split_at_mut(at);
        rayon::join(
            || self.fill(first, pa, ia, ha, na),
            || self.fill(first + mid, pb, ib, hb, nb),
        );
    }

    /// Part `p`: its spheres as the ranges listed them, sorted by `(walk key, id)`, then
    /// gathered into the part's own stretch of the copies in walk order. (The serial sort
    /// stores to scattered places instead, which stalls less than loading from them; the
    /// gather writes in order and leaves the scattered loads independent of each other, which
    /// a part's share of the spheres, spread over the whole id range, needs.)
    fn fill_one(
        &self,
        p: usize,
        part: &mut PartSort,
        items: &mut [u64],
        hot: &mut [Hot],
        node_key: &mut [u64],
    ) {
        let np = self.bounds.len() - 1;
        let mut at = 0;
        for listed in self.buckets.iter().skip(p).step_by(np) {
            items[at..at + listed.len()].copy_from_slice(listed);
            at += listed.len();
        }
        debug_assert_eq!(at, hot.len());
        // `node_key` is the sort's second buffer: the sorted items end in one of the two, and
        // each is read at the position its walk key is then stored at.
        let in_tmp = sort_bits_in(items, node_key, &mut part.counts, 32, self.key_bits);
        let tree = self.tree;
        for j in 0..hot.len() {
            let x = if in_tmp { node_key[j] } else { items[j] };
            let id = x as u32 as usize;
            let o = &tree.objs[id];
            node_key[j] = x >> 32;
            hot[j] = Hot {
                bx: o.simd_box(),
                qmin: o.qmin,
                qmax: o.qmax,
                id: id as u32,
            };
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn radix_sort_sorts_by_the_key_bits_and_is_stable() {
        let mut seed = 3u64;
        let mut items: Vec<u64> = (0..5000u64)
            .map(|id| {
                seed = seed.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1);
                ((seed >> 40) & 0x3f_ffff) << 32 | id
            })
            .collect();
        let mut want = items.clone();
        want.sort_by_key(|x| x >> 32);
        let (mut tmp, mut counts) = (Vec::new(), Vec::new());
        sort_bits(&mut items, &mut tmp, &mut counts, 32, 22);
        assert_eq!(items, want);
    }

    #[test]
    fn runs_are_the_stretches_of_equal_keys() {
        let keys = [1, 1, 3, 4, 4, 4, 9];
        let got: Vec<_> = runs(&keys).collect();
        assert_eq!(got, [(1, 0, 2), (3, 2, 3), (4, 3, 6), (9, 6, 7)]);
        assert_eq!(runs(&[]).count(), 0);
    }
}
