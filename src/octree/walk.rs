//! What both pair passes stand on: the spheres radix-sorted by their node's walk key into
//! contiguous walk-ordered arrays, the runs of equal keys (one per occupied node), and the
//! [`Tester`] that runs and counts the box tests of a pass through the sweep kernel.
//!
//! Order. Every sphere carries its node's walk key (`Lattice::walk_key`). A pass LSD-radix-sorts
//! `(walk key << 32) | id` (two or three streaming passes; the order of the dense ids is left
//! alone, so `update` keeps streaming in insertion order) and keeps that sorted list: it is the
//! walk order's keys and ids at once. It then gathers each sphere's box into a contiguous
//! walk-ordered array: a loose pass reads only the boxes ([`Run`]), a strict pass copies with
//! each box its cell range and id ([`Hot`]), which its subdivisions and ancestor copies carry
//! along. A pass then never chases a list: each node is a run of those arrays.
//!
//! The radix sort's second buffer (also the map from ids to walk positions) is needed only
//! while the order is sorted: the broadphase lends its pair list, idle until the pass fills it
//! ([`Octree::prepare_pass`](super::Octree)), and a tree used alone keeps its own.

use super::Placement;
use super::placement::walk_key_bits;
use super::{NONE, Octree};
use crate::geom::SimdBox;
use crate::pair::ProxyKey;
#[cfg(feature = "parallel")]
use crate::radix::ParScatter;
#[cfg(feature = "parallel")]
use crate::radix::sort_bits_par;
use crate::radix::{room_for, sort_bits_by, sort_bits_in};
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

/// A sphere as the strict pass reads and copies it: box, integer cell range and id. 48 bytes.
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
}

impl Borrow<SimdBox> for Hot {
    #[inline]
    fn borrow(&self) -> &SimdBox {
        &self.bx
    }
}

/// A list of spheres a [`Tester`] tests: their boxes, and the id of the `i`-th.
pub(super) trait Listed<'a>: Copy {
    type Item: Borrow<SimdBox> + 'a;
    fn items(self) -> &'a [Self::Item];
    fn id(self, i: usize) -> u32;
}

impl<'a> Listed<'a> for &'a [Hot] {
    type Item = Hot;
    #[inline]
    fn items(self) -> &'a [Hot] {
        self
    }
    #[inline]
    fn id(self, i: usize) -> u32 {
        self[i].id
    }
}

/// A stretch of the walk order as the loose pass reads it: the boxes, and beside them the
/// sorted `(walk key << 32) | id` whose low half is each sphere's id.
#[derive(Clone, Copy, Debug)]
pub(super) struct Run<'a> {
    pub(super) boxes: &'a [SimdBox],
    pub(super) ids: &'a [u64],
}

impl<'a> Run<'a> {
    /// Positions `lo..hi` of the walk order `boxes` / `ids`.
    #[inline]
    pub(super) fn of(boxes: &'a [SimdBox], ids: &'a [u64], lo: usize, hi: usize) -> Self {
        Run {
            boxes: &boxes[lo..hi],
            ids: &ids[lo..hi],
        }
    }

    #[inline]
    pub(super) fn len(&self) -> usize {
        self.boxes.len()
    }
}

impl<'a> Listed<'a> for Run<'a> {
    type Item = SimdBox;
    #[inline]
    fn items(self) -> &'a [SimdBox] {
        self.boxes
    }
    #[inline]
    fn id(self, i: usize) -> u32 {
        self.ids[i] as u32
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
    /// The walk order: `(walk key << 32) | id`, sorted; for a tree too deep for a 32-bit key
    /// (depth 10), the id alone, with the key in `wide_key`. Between passes it holds nothing
    /// anyone reads, and the broadphase's pair sort borrows it ([`Octree::idle_buffer`]).
    pub(super) items: Vec<u64>,
    /// The radix sort's second buffer and the map from ids to walk positions, for a pass
    /// whose caller lent none ([`Octree::prepare_pass`]).
    pub(super) tmp: Vec<u64>,
    /// `(walk key, id)` for trees too deep for a 32-bit key, and the radix sort's second
    /// buffer for them; the walk-ordered keys of such a tree.
    wide: Vec<(u64, u32)>,
    wide_tmp: Vec<(u64, u32)>,
    wide_key: Vec<u64>,
    counts: Vec<u32>,
    /// The walk-ordered boxes of a loose tree.
    pub(super) boxes: Vec<SimdBox>,
    /// The walk-ordered copies of a strict tree.
    pub(super) hot: Vec<Hot>,
    pub(super) sweeps: Sweeps,
    /// True from [`Octree::prepare_pass`] to the pass it prepares: the order is sorted.
    pub(super) ready: bool,
    /// The parallel sort's counts and table (see [`Octree::sort_into_walk_order_par`]).
    #[cfg(feature = "parallel")]
    par: ParScatter,
}

/// The most tasks a parallel walk-order sort splits the spheres into: each counts its keys
/// in a row of `2¹¹` counters, and the stretches of the destination number as many per task.
#[cfg(feature = "parallel")]
const MAX_TASKS: usize = 32;

impl Scratch {
    /// The walk order's list, which holds nothing anyone reads between passes: the
    /// broadphase's pair sort and a re-root proposal borrow it as scratch.
    pub(super) fn idle_items(&mut self) -> &mut Vec<u64> {
        &mut self.items
    }

    /// The walk order's keys.
    #[cfg(feature = "parallel")]
    pub(super) fn keys(&self) -> Keys<'_> {
        Keys {
            items: &self.items,
            wide: &self.wide_key,
        }
    }

    /// Heap bytes held (capacities).
    pub(super) fn heap_bytes(&self) -> usize {
        use core::mem::size_of_val;
        let v = |n: usize, one: usize| n * one;
        v(
            self.items.capacity() + self.tmp.capacity() + self.wide_key.capacity(),
            8,
        ) + v(self.wide.capacity() + self.wide_tmp.capacity(), 16)
            + v(self.counts.capacity(), 4)
            + v(self.boxes.capacity(), 32)
            + v(self.hot.capacity(), size_of_val(&Hot::EMPTY))
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

/// The walk order's node keys: the high halves of the sorted list, or (a tree too deep for
/// 32-bit keys) a list of their own.
#[derive(Clone, Copy, Debug)]
pub(super) struct Keys<'a> {
    items: &'a [u64],
    wide: &'a [u64],
}

impl Keys<'_> {
    #[inline]
    pub(super) fn len(&self) -> usize {
        self.items.len()
    }

    /// The key of walk position `i`.
    #[inline]
    pub(super) fn get(&self, i: usize) -> u64 {
        if self.wide.is_empty() {
            self.items[i] >> 32
        } else {
            self.wide[i]
        }
    }
}

/// The runs of equal keys of `keys` (sorted): `(key, start, end)` for each, in order.
#[inline]
pub(super) fn runs(keys: Keys<'_>) -> impl Iterator<Item = (u64, usize, usize)> + '_ {
    let mut i = 0;
    let n = keys.len();
    core::iter::from_fn(move || {
        if i == n {
            return None;
        }
        let key = keys.get(i);
        let start = i;
        i += 1;
        while i < n && keys.get(i) == key {
            i += 1;
        }
        Some((key, start, i))
    })
}

/// A pass's view of the walk order: its keys and ids (`items`, see [`Scratch`]), the boxes
/// (loose) or copies (strict), the tester that runs and counts the pass's box tests, and the
/// sweep buffers.
pub(super) struct Walk<'a, F> {
    pub(super) keys: Keys<'a>,
    pub(super) ids: &'a [u64],
    pub(super) boxes: &'a [SimdBox],
    pub(super) hot: &'a [Hot],
    pub(super) t: Tester<'a, F>,
    pub(super) sweeps: &'a mut Sweeps,
}

/// Runs and counts the box tests of one pass, mapping ids to proxy keys.
pub(super) struct Tester<'a, F> {
    pub(super) versions: &'a [u32],
    pub(super) tests: u64,
    pub(super) emit: F,
}

/// True if two lists of these lengths are tested all against all (see [`SHORT_CROSS`] and
/// [`SHORT_SIDE`]).
#[inline]
pub(super) fn is_short_cross(a: usize, b: usize) -> bool {
    a * b <= SHORT_CROSS || a.min(b) <= SHORT_SIDE
}

impl<F: FnMut(ProxyKey, ProxyKey)> Tester<'_, F> {
    /// Tests one pair and reports it if the boxes overlap.
    #[inline]
    pub(super) fn test(&mut self, a: &Hot, b: &Hot) {
        self.tests += 1;
        if a.bx.overlaps(&b.bx) {
            self.emit(a, b);
        }
    }

    /// Reports an overlapping pair of copies.
    #[inline]
    pub(super) fn emit(&mut self, a: &Hot, b: &Hot) {
        self.emit_ids(a.id, b.id);
    }

    /// Reports an overlapping pair by ids.
    #[inline]
    pub(super) fn emit_ids(&mut self, a: u32, b: u32) {
        (self.emit)(
            super::key_at(self.versions, a),
            super::key_at(self.versions, b),
        );
    }

    /// Every overlapping pair within `list`.
    #[inline(never)]
    pub(super) fn within<'b, L: Listed<'b>>(&mut self, list: L, sweeps: &mut Sweeps) {
        let items = list.items();
        if items.len() <= SHORT_SELF {
            self.tests += sweep::all_pairs(items, |i, _, j, _| {
                self.emit_ids(list.id(i), list.id(j));
            });
        } else {
            self.sweep_within(list, &mut sweeps.a);
        }
    }

    #[inline(never)]
    fn sweep_within<'b, L: Listed<'b>>(&mut self, list: L, order: &mut Vec<u64>) {
        let items = list.items();
        sweep::sort_entries(order, items, 0);
        let sorted = Ordered {
            order,
            items,
            axis: 0,
        };
        self.tests += sweep::self_pairs_of(&sorted, |i, j| self.emit_ids(list.id(i), list.id(j)));
    }

    /// Every overlapping pair across `a` and `b`.
    #[inline(never)]
    pub(super) fn between<'b, A: Listed<'b>, B: Listed<'b>>(
        &mut self,
        a: A,
        b: B,
        sweeps: &mut Sweeps,
    ) {
        let (ia, ib) = (a.items(), b.items());
        if is_short_cross(ia.len(), ib.len()) {
            self.tests += sweep::all_cross(ia, ib, |i, _, j, _| {
                self.emit_ids(a.id(i), b.id(j));
            });
        } else {
            sweep::sort_entries(&mut sweeps.a, ia, 0);
            self.sweep_sorted(a, b, 0, sweeps);
        }
    }

    /// The pairs across `a`, whose entries `sweeps.a` lists sorted along `axis`, and `b`.
    #[inline(never)]
    pub(super) fn sweep_sorted<'b, A: Listed<'b>, B: Listed<'b>>(
        &mut self,
        a: A,
        b: B,
        axis: usize,
        sweeps: &mut Sweeps,
    ) {
        let (ia, ib) = (a.items(), b.items());
        sweep::sort_entries(&mut sweeps.b, ib, axis);
        let (sa, sb) = (
            Ordered {
                order: &sweeps.a,
                items: ia,
                axis,
            },
            Ordered {
                order: &sweeps.b,
                items: ib,
                axis,
            },
        );
        self.tests += sweep::cross_pairs_of(&sa, &sb, |i, j| self.emit_ids(a.id(i), b.id(j)));
    }
}

impl Octree {
    /// Sorts the spheres into walk order for the next pass, with `tmp` as the sort's second
    /// buffer (left empty, its capacity grown to the sphere and id counts if short): the
    /// broadphase lends its pair list, which holds nothing until the pass fills it. The pass
    /// must follow with no change to the tree in between. See [`Octree::sort_walk`] for
    /// `parts`.
    pub(super) fn prepare_walk(&self, s: &mut Scratch, tmp: &mut Vec<u64>, parts: usize) {
        if self.live > 0 {
            self.sort_walk(s, tmp, parts);
            tmp.clear();
            s.ready = true;
        }
    }

    /// Readies the walk order of a pass: sorted now, with the scratch's own second buffer,
    /// unless [`Octree::prepare_walk`] just did. False if the tree is empty.
    pub(super) fn ensure_walk(&self, s: &mut Scratch, parts: usize) -> bool {
        if self.live == 0 {
            s.ready = false;
            return false;
        }
        if !core::mem::take(&mut s.ready) {
            let mut tmp = core::mem::take(&mut s.tmp);
            self.sort_walk(s, &mut tmp, parts);
            tmp.clear();
            s.tmp = tmp;
        }
        true
    }

    /// Sorts into walk order, in up to `parts` parts over rayon's current pool with the
    /// feature `parallel` (see [`Octree::sort_into_walk_order_par`]), else serially.
    fn sort_walk(&self, s: &mut Scratch, tmp: &mut Vec<u64>, parts: usize) {
        #[cfg(feature = "parallel")]
        if parts > 1 {
            self.sort_into_walk_order_par(s, tmp, parts);
            return;
        }
        let _ = parts;
        self.sort_into_walk_order(s, tmp);
    }

    /// The walk order of a pass (see [`Octree::ensure_walk`]); `None` if the tree is empty.
    pub(super) fn begin_pass<'a, F>(&'a self, s: &'a mut Scratch, emit: F) -> Option<Walk<'a, F>> {
        if !self.ensure_walk(s, 1) {
            return None;
        }
        Some(Walk {
            keys: Keys {
                items: &s.items,
                wide: &s.wide_key,
            },
            ids: &s.items,
            boxes: &s.boxes,
            hot: &s.hot,
            t: Tester {
                versions: &self.versions,
                tests: 0,
                emit,
            },
            sweeps: &mut s.sweeps,
        })
    }

    /// Sorts the spheres by walk key and fills the walk order of `s`: the sorted list (keys
    /// and ids) and the boxes (loose) or copies (strict), with `tmp` as the second buffer.
    fn sort_into_walk_order(&self, s: &mut Scratch, tmp: &mut Vec<u64>) {
        let key_bits = walk_key_bits(self.lattice.depth);
        // Every buffer sized by the sphere count grows by `room_for`, not by doubling.
        let n = self.live;
        // `tmp` maps ids to walk positions last (see `scatter`).
        room_for(tmp, self.objs.len().max(n));
        let items = &mut s.items;
        room_for(items, n);
        items.clear();
        if key_bits <= 32 {
            s.wide_key.clear();
            items.extend(self.walk_items(0..self.objs.len()));
            tmp.resize(n, 0);
            if sort_bits_in(items, tmp, &mut s.counts, 32, key_bits) {
                items.copy_from_slice(tmp);
            }
        } else {
            let Scratch {
                wide,
                wide_tmp,
                wide_key,
                counts,
                ..
            } = s;
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
            room_for(wide_key, n);
            wide_key.clear();
            wide_key.extend(wide.iter().map(|&(key, _)| key));
            items.extend(wide.iter().map(|&(_, id)| u64::from(id)));
        }
        self.scatter(s, tmp);
    }

    /// `(walk key << 32) | id` of the placed spheres of ids `ids`, in id order: what a tree
    /// with 32-bit walk keys sorts.
    fn walk_items(&self, ids: core::ops::Range<usize>) -> impl Iterator<Item = u64> + '_ {
        let first = ids.start;
        self.objs[ids]
            .iter()
            .zip(first..)
            .filter(|(o, _)| o.node != NONE)
            .map(|(o, id)| (u64::from(o.walk_key) << 32) | id as u64)
    }

    /// Fills the walk-ordered boxes (or copies) from the sorted list. Each sphere's walk
    /// position is noted by id first (in `rank`); then one pass reads the spheres in id order,
    /// as they lie in memory, and stores each at its position: stores to scattered places do
    /// not stall the loop the way loads from them would.
    fn scatter(&self, s: &mut Scratch, rank: &mut Vec<u64>) {
        let n = self.live;
        rank.resize(self.objs.len(), 0);
        for (pos, &x) in s.items.iter().enumerate() {
            rank[x as u32 as usize] = pos as u64;
        }
        // `rank` maps the live ids onto `0..n`: every entry below is overwritten, so the
        // buffers only change length when the sphere count does.
        let live = self.objs.iter().zip(rank.iter()).enumerate();
        let live = live.filter(|(_, (o, _))| o.node != NONE);
        match self.lattice.placement {
            Placement::Loose => {
                room_for(&mut s.boxes, n);
                s.boxes.resize(n, SimdBox::EMPTY);
                for (_, (o, &pos)) in live {
                    s.boxes[pos as usize] = o.simd_box();
                }
            }
            Placement::Strict => {
                room_for(&mut s.hot, n);
                s.hot.resize(n, Hot::EMPTY);
                for (id, (o, &pos)) in live {
                    s.hot[pos as usize] = self.hot_of(o, id as u32);
                }
            }
        }
    }

    /// The strict pass's copy of the sphere `o` of id `id`: its cell range is quantised from
    /// the box it is placed by, as placement quantised it.
    #[inline]
    fn hot_of(&self, o: &super::Obj, id: u32) -> Hot {
        let aabb = o.aabb();
        Hot {
            bx: o.simd_box(),
            qmin: self.lattice.quantize(aabb.min),
            qmax: self.lattice.quantize(aabb.max),
            id,
        }
    }
}

/// Spheres per task of the parallel walk-order sort, at least: a task's fixed costs (its row
/// of counters, its stretches, handing it out) outweigh the split below it.
#[cfg(feature = "parallel")]
const MIN_TASK_SPHERES: usize = 4096;

#[cfg(feature = "parallel")]
impl Octree {
    /// [`Octree::sort_into_walk_order`] split over rayon's current pool in up to `parts`
    /// tasks: the radix sort's passes scatter by id range ([`sort_bits_par`], reading the
    /// first pass's keys from the spheres in place), then each task gathers the boxes of its
    /// stretch of the walk order. The walk order is the serial sort's at any task count.
    /// Trees too deep for 32-bit keys, too small for two tasks, or strict (whose pass is
    /// serial) sort serially.
    pub(super) fn sort_into_walk_order_par(
        &self,
        s: &mut Scratch,
        tmp: &mut Vec<u64>,
        parts: usize,
    ) {
        use rayon::prelude::*;
        let key_bits = walk_key_bits(self.lattice.depth);
        let tasks = parts.min(MAX_TASKS).min(self.live / MIN_TASK_SPHERES);
        if key_bits > 32 || tasks < 2 || self.lattice.placement == Placement::Strict {
            self.sort_into_walk_order(s, tmp);
            return;
        }
        s.wide_key.clear();
        let Scratch {
            items, boxes, par, ..
        } = s;
        let n = self.live;
        // Grown by `room_for`, as in the serial sort.
        room_for(items, n);
        room_for(boxes, n);
        room_for(tmp, n);
        items.resize(n, 0);
        boxes.resize(n, SimdBox::EMPTY);
        tmp.resize(n, 0);
        let keys = |ids| self.walk_items(ids);
        sort_bits_par(self.objs.len(), keys, items, tmp, par, tasks, 32, key_bits);
        // The gather writes in order and its scattered loads are independent of each other.
        let chunk = n.div_ceil(tasks);
        boxes
            .par_chunks_mut(chunk)
            .zip(items.par_chunks(chunk))
            .for_each(|(boxes, items)| self.gather_boxes(boxes, items));
    }

    /// The boxes of the walk-ordered `items` (`(walk key << 32) | id`), in their order. Not
    /// inlined: a profile shows each task's share by name.
    #[inline(never)]
    fn gather_boxes(&self, boxes: &mut [SimdBox], items: &[u64]) {
        for (b, &x) in boxes.iter_mut().zip(items) {
            *b = self.objs[x as u32 as usize].simd_box();
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
        let (mut tmp, mut counts) = (vec![0; items.len()], Vec::new());
        if sort_bits_in(&mut items, &mut tmp, &mut counts, 32, 22) {
            items.copy_from_slice(&tmp);
        }
        assert_eq!(items, want);
    }

    #[test]
    fn runs_are_the_stretches_of_equal_keys() {
        // Narrow keys are the high halves of the sorted list; wide ones a list of their own.
        let keys = [1u64, 1, 3, 4, 4, 4, 9];
        let want = [(1, 0, 2), (3, 2, 3), (4, 3, 6), (9, 6, 7)];
        let items: Vec<u64> = keys.iter().zip(10..).map(|(k, id)| k << 32 | id).collect();
        let narrow = Keys {
            items: &items,
            wide: &[],
        };
        assert_eq!(runs(narrow).collect::<Vec<_>>(), want);
        let ids: Vec<u64> = (10..17).collect();
        let wide = Keys {
            items: &ids,
            wide: &keys,
        };
        assert_eq!(runs(wide).collect::<Vec<_>>(), want);
        let empty = Keys {
            items: &[],
            wide: &[],
        };
        assert_eq!(runs(empty).count(), 0);
    }
}
