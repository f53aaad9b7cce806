//! Overlapping pairs: the tree against itself, a tree against another tree, and the pending
//! lists against both (tree queries and sort-and-sweep on x).

use super::Bvh;
use super::lanes::{Found, GROUP, Group, Lanes, Splat, bits, low_bits};
use super::node::Node;
use crate::geom::SimdBox;
use crate::pair::{Pair, ProxyKey};
use crate::sweep::{self, Ordered};

/// Scratch of the pair traversals: the stack of node pairs and the sweep orders of the
/// pending boxes. [`Bvh::for_each_pair`] uses the tree's own; the `&self` traversals
/// ([`Bvh::for_each_pair_using`], [`Bvh::for_each_pair_with_using`]) take one from the caller,
/// so that one tree can be traversed by several threads at once, each with its own. It only
/// grows, to the deepest traversal so far.
#[derive(Clone, Debug, Default)]
pub struct PairScratch {
    stack: Vec<(u32, u32)>,
    sweep_a: Vec<u64>,
    sweep_b: Vec<u64>,
}

impl PairScratch {
    /// Heap bytes held (capacities).
    #[must_use]
    pub fn heap_bytes(&self) -> usize {
        self.stack.capacity() * 8 + (self.sweep_a.capacity() + self.sweep_b.capacity()) * 8
    }

    /// Where the buffers live and how large they are: equal before and after a call that
    /// neither grew nor moved them (the allocation tests).
    #[cfg(test)]
    pub(crate) fn fingerprint(&self) -> [(usize, usize); 2] {
        [
            (self.stack.as_ptr() as usize, self.stack.capacity()),
            (self.sweep_a.as_ptr() as usize, self.sweep_a.capacity()),
        ]
    }
}

impl Bvh {
    /// Calls `f(a, b)` once for every unordered pair of live primitives whose current boxes
    /// overlap (closed: touching counts), in no particular order and with `a`, `b` in no
    /// particular order. Exact between `update` and `refit`. Allocation-free once the scratch
    /// stack has grown to the tree's needs.
    pub fn for_each_pair(&mut self, f: impl FnMut(ProxyKey, ProxyKey)) {
        let mut scratch = core::mem::take(&mut self.pair_scratch);
        self.for_each_pair_using(&mut scratch, f);
        self.pair_scratch = scratch;
    }

    /// [`Bvh::for_each_pair`] of a shared tree, with the caller's scratch.
    pub fn for_each_pair_using(
        &self,
        scratch: &mut PairScratch,
        mut f: impl FnMut(ProxyKey, ProxyKey),
    ) {
        debug_assert!(
            !self.has_deferred(),
            "pairs of a tree with deferred enlargements"
        );
        let stack = &mut scratch.stack;
        stack.clear();
        let t = Tree::of(self);
        if !t.nodes.is_empty() {
            stack.push((0, 0));
        }
        drain_own(&t, stack, &mut Noted::new(), &mut f);
        self.pending_self_pairs(&mut scratch.sweep_a, &mut f);
    }

    /// Pending × tree, then pending × pending (sort-and-sweep on x with `order` as scratch).
    fn pending_self_pairs(&self, order: &mut Vec<u64>, f: &mut impl FnMut(ProxyKey, ProxyKey)) {
        for p in self.tree_len..self.boxes.len() {
            self.query_tree(&self.boxes[p], |i| f(self.keys[p], self.keys[i]));
        }
        let (boxes, keys) = (self.pending_boxes(), self.pending_keys());
        sweep::sort_entries(order, boxes, 0);
        let list = Ordered {
            order,
            items: boxes,
            axis: 0,
        };
        sweep::self_pairs_of(&list, |i, j| f(keys[i], keys[j]));
    }

    /// Appends every overlapping pair of [`Bvh::for_each_pair`], canonical (`a < b`) but
    /// **unsorted**, to `out` (which is not cleared); sort with [`crate::pair::sort_dedup`] if
    /// order matters.
    pub fn pairs_into(&mut self, out: &mut Vec<Pair>) {
        self.for_each_pair(|a, b| out.push(Pair::new(a, b)));
    }

    /// Calls `f(a, b)` once for every live primitive `a` of `self` and `b` of `other` whose
    /// current boxes overlap, in no particular order: tree × tree by simultaneous descent,
    /// pending lists by tree queries and a merged sort-and-sweep. Scratch lives in `self`.
    pub fn for_each_pair_with(&mut self, other: &Bvh, f: impl FnMut(ProxyKey, ProxyKey)) {
        let mut scratch = core::mem::take(&mut self.pair_scratch);
        self.for_each_pair_with_using(other, &mut scratch, f);
        self.pair_scratch = scratch;
    }

    /// [`Bvh::for_each_pair_with`] of shared trees, with the caller's scratch.
    pub fn for_each_pair_with_using(
        &self,
        other: &Bvh,
        scratch: &mut PairScratch,
        mut f: impl FnMut(ProxyKey, ProxyKey),
    ) {
        debug_assert!(
            !(self.has_deferred() || other.has_deferred()),
            "pairs of a tree with deferred enlargements"
        );
        let stack = &mut scratch.stack;
        stack.clear();
        let (ta, tb) = (Tree::of(self), Tree::of(other));
        if let (Some(a), Some(b)) = (ta.nodes.first(), tb.nodes.first())
            && a.bounds().overlaps(&b.bounds())
        {
            stack.push((0, 0));
        }
        drain_cross(&ta, &tb, stack, &mut Noted::new(), &mut f);
        self.pending_cross_pairs(other, scratch, &mut f);
    }

    /// The pairs of `self` × `other` that name a pending primitive: pending × tree both ways
    /// by tree queries, pending × pending by a merged sort-and-sweep on x.
    fn pending_cross_pairs(
        &self,
        other: &Bvh,
        scratch: &mut PairScratch,
        f: &mut impl FnMut(ProxyKey, ProxyKey),
    ) {
        for p in self.tree_len..self.boxes.len() {
            other.query_tree(&self.boxes[p], |i| f(self.keys[p], other.keys[i]));
        }
        for q in other.tree_len..other.boxes.len() {
            self.query_tree(&other.boxes[q], |i| f(self.keys[i], other.keys[q]));
        }
        let (xs, ys) = (&mut scratch.sweep_a, &mut scratch.sweep_b);
        let (bx, kx) = (self.pending_boxes(), self.pending_keys());
        let (by, ky) = (other.pending_boxes(), other.pending_keys());
        sweep::sort_entries(xs, bx, 0);
        sweep::sort_entries(ys, by, 0);
        let (lx, ly) = (
            Ordered {
                order: xs,
                items: bx,
                axis: 0,
            },
            Ordered {
                order: ys,
                items: by,
                axis: 0,
            },
        );
        sweep::cross_pairs_of(&lx, &ly, |i, j| f(kx[i], ky[j]));
    }
}

/// Scratch of [`Bvh::for_each_pair_split`], owned by its caller and reused: the items handed
/// out (each list with a second buffer for its next round), the order tasks take them in, and
/// one [`PairScratch`] per task.
#[cfg(feature = "parallel")]
#[derive(Clone, Debug, Default)]
pub(crate) struct SplitScratch {
    own: [Vec<(u32, u32)>; 2],
    cross: [Vec<(u32, u32)>; 2],
    /// `(weight, item)` of every item, heaviest first; `item` indexes `own` then `cross`.
    order: Vec<(u32, u32)>,
    tasks: Vec<PairScratch>,
}

#[cfg(feature = "parallel")]
impl SplitScratch {
    /// Heap bytes held (capacities).
    pub(crate) fn heap_bytes(&self) -> usize {
        (self.own.iter().chain(&self.cross))
            .map(|v| v.capacity() * 8)
            .sum::<usize>()
            + self.order.capacity() * 8
            + self.tasks.capacity() * core::mem::size_of::<PairScratch>()
            + self
                .tasks
                .iter()
                .map(PairScratch::heap_bytes)
                .sum::<usize>()
    }

    /// Expands the items of both descents over `ta` and `ta` × `tb` for `tasks` tasks and
    /// orders them heaviest first (see [`Bvh::for_each_pair_split`]).
    fn prepare(&mut self, ta: &Tree, tb: &Tree, tasks: usize) {
        let SplitScratch {
            own: [own, own_next],
            cross: [cross, cross_next],
            order,
            ..
        } = self;
        own.clear();
        cross.clear();
        let mut total = 0u64;
        if let Some(root) = ta.nodes.first() {
            own.push((0, 0));
            total += u64::from(own_weight(ta, 0, 0));
            if tb
                .nodes
                .first()
                .is_some_and(|r| r.bounds().overlaps(&root.bounds()))
            {
                cross.push((0, 0));
                total += u64::from(cross_weight(ta, tb, 0, 0));
            }
        }
        let limit = (total / (tasks * ITEMS_PER_TASK) as u64).max(1) as u32;
        while own.len() + cross.len() < tasks * MAX_ITEMS_PER_TASK {
            let grew_own = expand_own(ta, limit, own, own_next);
            let grew_cross = expand_cross(ta, tb, limit, cross, cross_next);
            if !(grew_own || grew_cross) {
                break;
            }
        }
        order.clear();
        order.extend(
            own.iter()
                .map(|&(a, b)| own_weight(ta, a, b))
                .chain(cross.iter().map(|&(a, b)| cross_weight(ta, tb, a, b)))
                .zip(0..),
        );
        order.sort_unstable_by(|x, y| y.cmp(x));
    }
}

/// Items a split pair pass aims to make per task: an item weighs at most the whole
/// descents' weight over this many per task, so that the threads, taking the heaviest items
/// first, end within about one light item of each other.
#[cfg(feature = "parallel")]
const ITEMS_PER_TASK: usize = 8;

/// The most items a split pair pass makes per task, whatever their weights (a cap on the
/// serial expansion for trees whose cross items stay heavy).
#[cfg(feature = "parallel")]
const MAX_ITEMS_PER_TASK: usize = 64;

#[cfg(feature = "parallel")]
impl Bvh {
    /// The pairs of [`Bvh::for_each_pair`] and of [`Bvh::for_each_pair_with`]`(other)`, found
    /// in `out.len()` tasks over rayon's current pool: task `c` calls `emit(&mut out[c], a, b)`
    /// for each pair it finds, `a` in `self` (each pair is found by one task, once; which one
    /// depends on the threads' timing).
    ///
    /// The items of both descents are first expanded on the calling thread (an item is
    /// replaced by its children's items, as the descents themselves do) until none weighs
    /// more than `1 / (tasks · ITEMS_PER_TASK)` of their total or can be expanded. An item's
    /// weight is the node count of its subtree, the smaller one's for a cross item: a self
    /// item's descent costs about that, and a cross item's no more than a descent of its
    /// smaller side. Items partition the pairs, so each task then takes items, heaviest first,
    /// from one shared counter, and runs the serial descents from each with its own stack:
    /// a thread that lags (or is not scheduled) takes fewer, and no thread waits at the end
    /// for more than one item of another. The pending boxes' pairs go to task 0 first.
    pub(crate) fn for_each_pair_split<S, E>(
        &self,
        other: &Bvh,
        scratch: &mut SplitScratch,
        out: &mut [S],
        emit: &E,
    ) where
        S: Send,
        E: Fn(&mut S, ProxyKey, ProxyKey) + Sync,
    {
        use core::sync::atomic::{AtomicUsize, Ordering};
        use rayon::prelude::*;
        debug_assert!(
            !(self.has_deferred() || other.has_deferred()),
            "pairs of a tree with deferred enlargements"
        );
        let tasks = out.len();
        if tasks == 0 {
            return;
        }
        let (ta, tb) = (Tree::of(self), Tree::of(other));
        scratch.prepare(&ta, &tb, tasks);
        let SplitScratch {
            own: [own, _],
            cross: [cross, _],
            order,
            tasks: scratches,
        } = scratch;
        if scratches.len() < tasks {
            scratches.resize_with(tasks, PairScratch::default);
        }
        let (own, cross, order) = (&own[..], &cross[..], &order[..]);
        let next = AtomicUsize::new(0);
        let (ta, tb) = (&ta, &tb);
        out.par_iter_mut()
            .zip(&mut scratches[..tasks])
            .enumerate()
            .for_each(|(c, (o, s))| {
                let mut f = |a, b| emit(o, a, b);
                if c == 0 {
                    self.pending_self_pairs(&mut s.sweep_a, &mut f);
                    self.pending_cross_pairs(other, s, &mut f);
                }
                let mut noted = Noted::new();
                while let Some(&(_, item)) = order.get(next.fetch_add(1, Ordering::Relaxed)) {
                    let item = item as usize;
                    s.stack.clear();
                    if let Some(&own_item) = own.get(item) {
                        s.stack.push(own_item);
                        drain_own(ta, &mut s.stack, &mut noted, &mut f);
                    } else {
                        s.stack.push(cross[item - own.len()]);
                        drain_cross(ta, tb, &mut s.stack, &mut noted, &mut f);
                    }
                }
            });
    }
}

/// The node count of the subtree of `n`: in the depth-first array it ends where the subtree
/// of its last second child, down the right spine, does.
#[cfg(feature = "parallel")]
fn subtree_nodes(t: &Tree, n: u32) -> u32 {
    let mut m = n;
    while !t.nodes[m as usize].is_leaf() {
        m = t.nodes[m as usize].first;
    }
    m + 1 - n
}

/// The weight of a self-traversal item (see [`Bvh::for_each_pair_split`]).
#[cfg(feature = "parallel")]
fn own_weight(t: &Tree, a: u32, b: u32) -> u32 {
    if a == b {
        subtree_nodes(t, a)
    } else {
        cross_weight(t, t, a, b)
    }
}

/// The weight of a cross item (see [`Bvh::for_each_pair_split`]).
#[cfg(feature = "parallel")]
fn cross_weight(ta: &Tree, tb: &Tree, a: u32, b: u32) -> u32 {
    subtree_nodes(ta, a).min(subtree_nodes(tb, b))
}

/// Replaces the self-traversal items of `cur` that weigh more than `limit` by their
/// children's items (see [`drain_own`]), the others kept, with `next` as the second buffer;
/// true if any item was replaced.
#[cfg(feature = "parallel")]
fn expand_own(t: &Tree, limit: u32, cur: &mut Vec<(u32, u32)>, next: &mut Vec<(u32, u32)>) -> bool {
    next.clear();
    let mut grew = false;
    for &(a, b) in cur.iter() {
        let na = &t.nodes[a as usize];
        let light = own_weight(t, a, b) <= limit;
        if !light && a == b && !na.is_leaf() {
            own_children(t, a, na, next);
            grew = true;
        } else if !light && a != b && !(na.is_leaf() && t.nodes[b as usize].is_leaf()) {
            cross_children(t, t, a, b, next);
            grew = true;
        } else {
            next.push((a, b));
        }
    }
    core::mem::swap(cur, next);
    grew
}

/// [`expand_own`] for the cross items of `ta` × `tb`.
#[cfg(feature = "parallel")]
fn expand_cross(
    ta: &Tree,
    tb: &Tree,
    limit: u32,
    cur: &mut Vec<(u32, u32)>,
    next: &mut Vec<(u32, u32)>,
) -> bool {
    next.clear();
    let mut grew = false;
    for &(a, b) in cur.iter() {
        let leaves = ta.nodes[a as usize].is_leaf() && tb.nodes[b as usize].is_leaf();
        if leaves || cross_weight(ta, tb, a, b) <= limit {
            next.push((a, b));
        } else {
            cross_children(ta, tb, a, b, next);
            grew = true;
        }
    }
    core::mem::swap(cur, next);
    grew
}

/// Runs the self-traversal of a tree from the items on `stack` until it is empty. The unordered
/// primitive pairs below a node n split into the pairs within its first child l, within its
/// second child r, and across l × r: so the item (n, n) is replaced by (l, l), (r, r),
/// (l, r), and a leaf (n, n) tests its own range i < j. A cross item (a, b) names two
/// disjoint subtrees; its pairs are those of the child pairs of a × b (a leaf standing for
/// itself), so descending partitions them again, and a cross item whose node boxes do not
/// overlap holds no pair because node boxes contain their primitives'. Every pair below the
/// items is thus produced by exactly one leaf-level item, once.
fn drain_own(
    t: &Tree,
    stack: &mut Vec<(u32, u32)>,
    noted: &mut Noted,
    f: &mut impl FnMut(ProxyKey, ProxyKey),
) {
    while let Some((a, b)) = stack.pop() {
        if a != b {
            cross_step(t, t, a, b, stack, noted, f);
            continue;
        }
        let node = &t.nodes[a as usize];
        if node.is_leaf() {
            leaf_self_pairs(t, node, &mut noted.found, f);
        } else {
            own_children(t, a, node, stack);
        }
    }
}

/// The items that replace the interior self item (n, n): see [`drain_own`].
#[inline]
fn own_children(t: &Tree, n: u32, node: &Node, stack: &mut Vec<(u32, u32)>) {
    let (l, r) = node.children(n);
    if t.nodes[l as usize]
        .bounds()
        .overlaps(&t.nodes[r as usize].bounds())
    {
        stack.push((l, r));
    }
    stack.extend_from_slice(&[(r, r), (l, l)]);
}

/// Runs the descent over `ta` × `tb` from the cross items on `stack` until it is empty.
fn drain_cross(
    ta: &Tree,
    tb: &Tree,
    stack: &mut Vec<(u32, u32)>,
    noted: &mut Noted,
    f: &mut impl FnMut(ProxyKey, ProxyKey),
) {
    while let Some((a, b)) = stack.pop() {
        cross_step(ta, tb, a, b, stack, noted, f);
    }
}

/// The slices of a tree that the descents read (tree primitives only, not the pending ones).
struct Tree<'a> {
    nodes: &'a [Node],
    boxes: &'a [SimdBox],
    lanes: &'a Lanes,
    keys: &'a [ProxyKey],
}

impl<'a> Tree<'a> {
    fn of(bvh: &'a Bvh) -> Self {
        Tree {
            nodes: &bvh.nodes,
            boxes: &bvh.boxes[..bvh.tree_len],
            lanes: &bvh.lanes,
            keys: &bvh.keys[..bvh.tree_len],
        }
    }
}

/// One item `(a, b)` of a descent over two disjoint subtrees with overlapping boxes, `a` in
/// `ta` and `b` in `tb`: every overlapping primitive pair if both are leaves, else the items
/// of their children ([`cross_children`]).
#[inline]
fn cross_step(
    ta: &Tree,
    tb: &Tree,
    a: u32,
    b: u32,
    stack: &mut Vec<(u32, u32)>,
    noted: &mut Noted,
    f: &mut impl FnMut(ProxyKey, ProxyKey),
) {
    let na = &ta.nodes[a as usize];
    let nb = &tb.nodes[b as usize];
    if na.is_leaf() && nb.is_leaf() {
        leaf_pairs(ta, na, tb, nb, noted, f);
    } else {
        cross_children(ta, tb, a, b, stack);
    }
}

/// The items that replace the cross item `(a, b)` of which at least one node is interior: the
/// child pairs of both interior nodes (a leaf standing in for itself) whose boxes overlap
/// (pruned before the push, not after the pop).
#[inline]
fn cross_children(ta: &Tree, tb: &Tree, a: u32, b: u32, stack: &mut Vec<(u32, u32)>) {
    let na = &ta.nodes[a as usize];
    let nb = &tb.nodes[b as usize];
    match (na.is_leaf(), nb.is_leaf()) {
        (false, true) => {
            let bb = nb.bounds();
            let (l, r) = na.children(a);
            for c in [r, l] {
                if ta.nodes[c as usize].bounds().overlaps(&bb) {
                    stack.push((c, b));
                }
            }
        }
        (true, false) => {
            let ab = na.bounds();
            let (l, r) = nb.children(b);
            for c in [r, l] {
                if tb.nodes[c as usize].bounds().overlaps(&ab) {
                    stack.push((a, c));
                }
            }
        }
        _ => {
            debug_assert!(!na.is_leaf() && !nb.is_leaf());
            let (al, ar) = na.children(a);
            let (bl, br) = nb.children(b);
            let (bl_box, br_box) = (
                tb.nodes[bl as usize].bounds(),
                tb.nodes[br as usize].bounds(),
            );
            for c in [ar, al] {
                let cb = ta.nodes[c as usize].bounds();
                if cb.overlaps(&br_box) {
                    stack.push((c, br));
                }
                if cb.overlaps(&bl_box) {
                    stack.push((c, bl));
                }
            }
        }
    }
}

/// Every overlapping pair within one leaf: each box is tested against all the leaf's blocks,
/// [`GROUP`] at a time ([`Lanes`]), the lanes up to its own masked off, and the pairs go
/// through `found` (no branch on a test's outcome, nor on a box's place in the leaf). Leaves
/// too long for one mask, which only a `max_leaf_size` above 61 makes, take the plain loop.
#[inline]
fn leaf_self_pairs(
    t: &Tree,
    node: &Node,
    found: &mut Found,
    f: &mut impl FnMut(ProxyKey, ProxyKey),
) {
    let range = node.range();
    let keys = &t.keys[range.clone()];
    let Some(leaf) = t.lanes.leaf(range.start, range.len()) else {
        sweep::all_pairs(&t.boxes[range], |i, _, j, _| f(keys[i], keys[j]));
        return;
    };
    for (i, b) in t.boxes[range].iter().enumerate() {
        let q = Splat::of(b);
        // Lanes after box i's own: bits `off + i + 1..`.
        let after = leaf.off + i + 1;
        let later = leaf.valid & !low_bits(after);
        found.push(i, leaf.mask_from(after / GROUP, &q) & later);
    }
    found.drain(|i, k| f(keys[i], keys[k - leaf.off]));
}

/// Every overlapping pair of the primitives of leaf `na` (in `ta`) × leaf `nb` (in `tb`). A
/// box of either leaf that misses the other leaf's box pairs with nothing there, so the boxes
/// of b that meet a's leaf box are noted first, then those of a that meet the union of b's
/// noted boxes (tighter than b's leaf box), and only those are tested against each other:
/// two leaves that overlap at a corner cost one pass over each, not the product. b's noted
/// boxes are packed into blocks of their own ([`Noted::pack`]) while their union is taken,
/// and each noted box of a is tested against them [`GROUP`] at a time; the results are bit
/// masks read through [`Found`], so the loops branch on their counts, not on the tests
/// (whose outcomes the branch predictor cannot guess). Leaves too long for one mask, which
/// only a `max_leaf_size` above 61 makes, take the plain loop.
#[inline]
fn leaf_pairs(
    ta: &Tree,
    na: &Node,
    tb: &Tree,
    nb: &Node,
    noted: &mut Noted,
    f: &mut impl FnMut(ProxyKey, ProxyKey),
) {
    let (ra, rb) = (na.range(), nb.range());
    let (keys_a, keys_b) = (&ta.keys[ra.clone()], &tb.keys[rb.clone()]);
    let (Some(la), Some(lb)) = (
        ta.lanes.leaf(ra.start, ra.len()),
        tb.lanes.leaf(rb.start, rb.len()),
    ) else {
        let b_box = nb.bounds();
        for (bi, &ki) in ta.boxes[ra].iter().zip(keys_a) {
            if bi.overlaps(&b_box) {
                for (bj, &kj) in tb.boxes[rb.clone()].iter().zip(keys_b) {
                    if bi.overlaps(bj) {
                        f(ki, kj);
                    }
                }
            }
        }
        return;
    };
    let near_b = lb.mask(&Splat::of(&na.bounds()));
    if near_b == 0 {
        return;
    }
    let Noted {
        blocks,
        keys: packed,
        found,
    } = noted;
    let (blocks, union) = Noted::pack(blocks, packed, (&tb.boxes[rb], keys_b, lb.off, near_b));
    let boxes_a = &ta.boxes[ra];
    for i in bits(la.mask(&Splat::of(&union))) {
        let q = Splat::of(&boxes_a[i - la.off]);
        let mut m = 0u64;
        for (g, block) in blocks.iter().enumerate() {
            m |= u64::from(block.overlaps(&q)) << (GROUP * g);
        }
        found.push(i - la.off, m);
    }
    found.drain(|i, k| f(keys_a[i], packed[k]));
}

/// The noted boxes of one leaf: its boxes, keys, the bit of its first box, and the mask of the
/// noted ones.
type NotedSide<'a> = (&'a [SimdBox], &'a [ProxyKey], usize, u64);

/// The noted boxes of one leaf of a leaf pair, packed into blocks, and their keys: a
/// descent's scratch, reused by each of its leaf pairs.
struct Noted {
    /// One block more than 64 lanes: [`Noted::pack`] empties the three lanes after the last
    /// noted box unconditionally.
    blocks: [Group; 64 / GROUP + 1],
    keys: [ProxyKey; 64],
    /// The pairs found by the leaf kernels, before they are handed on.
    found: Found,
}

impl Noted {
    fn new() -> Noted {
        Noted {
            blocks: [Group::EMPTY; 64 / GROUP + 1],
            keys: [ProxyKey::default(); 64],
            found: Found::new(),
        }
    }

    /// Packs the noted boxes of `side` into `blocks` and their keys into `keys`, in leaf
    /// order, the spare lanes of the last block empty (they overlap nothing), so that a box is
    /// tested against all of them in `ceil(noted / 4)` block tests however they lie in their
    /// leaf. Returns those blocks and the union of the noted boxes.
    #[inline]
    fn pack<'b>(
        blocks: &'b mut [Group; 64 / GROUP + 1],
        keys: &mut [ProxyKey; 64],
        side: NotedSide,
    ) -> (&'b [Group], SimdBox) {
        let (boxes, side_keys, off, near) = side;
        let (mut n, mut union) = (0, SimdBox::EMPTY);
        for k in bits(near) {
            let b = &boxes[k - off];
            union = union.union(b);
            blocks[n / GROUP].set(n, b);
            keys[n] = side_keys[k - off];
            n += 1;
        }
        // Lanes n..n + 3: past the last noted box, within its block or the next one.
        for k in n..n + GROUP - 1 {
            blocks[k / GROUP].set(k, &SimdBox::EMPTY);
        }
        (&blocks[..n.div_ceil(GROUP)], union)
    }
}

#[cfg(all(test, feature = "parallel"))]
mod tests {
    use super::super::BvhConfig;
    use super::*;
    use crate::geom::Aabb;
    use crate::rng::Rng;
    use glam::Vec3;
    use slotmap::SlotMap;

    /// A tree of `n` random boxes built, then changed so that every kind of primitive is
    /// there: boxes moved out of their leaves, pending inserts and tombstones.
    fn changed_tree(rng: &mut Rng, keys: &mut SlotMap<ProxyKey, ()>, n: usize) -> Bvh {
        let random_box = |rng: &mut Rng| {
            let c = rng.vec3_in(Vec3::splat(-20.0), Vec3::splat(20.0));
            Aabb::new(c, c + rng.vec3_in(Vec3::splat(0.1), Vec3::splat(2.5)))
        };
        let mut bvh = Bvh::new(BvhConfig {
            rebuild_after_changes: f32::INFINITY,
            ..BvhConfig::default()
        })
        .unwrap();
        let mut live = Vec::new();
        for _ in 0..n {
            let k = keys.insert(());
            bvh.insert_keyed(k, random_box(rng)).unwrap();
            live.push(k);
        }
        bvh.rebuild();
        for &k in live.iter().step_by(7) {
            bvh.update(k, random_box(rng)).unwrap();
        }
        for &k in live.iter().skip(3).step_by(11) {
            bvh.remove(k).unwrap();
        }
        for _ in 0..n / 20 {
            bvh.insert_keyed(keys.insert(()), random_box(rng)).unwrap();
        }
        bvh.validate();
        bvh
    }

    /// Regression: the split once handed each task a contiguous stretch of its items, and
    /// the diagonal items, which hold most of the pairs, fell to one or two tasks (one task of
    /// eight found 44 % of `bodies`' pairs while its thread's partner idled). Now the items
    /// are expanded by weight and taken heaviest first: no item holds more than a small share
    /// of the pairs, and the items together hold each pair once.
    #[test]
    fn split_items_are_light() {
        let mut rng = Rng::new(31);
        let config = BvhConfig {
            max_leaf_size: 32,
            traversal_cost: 16.0,
            ..BvhConfig::default()
        };
        let spread = |rng: &mut Rng, n: usize, half: f32| -> Vec<Aabb> {
            (0..n)
                .map(|_| {
                    let c = rng.vec3_in(Vec3::splat(-half), Vec3::splat(half));
                    Aabb::new(c, c + rng.vec3_in(Vec3::splat(0.2), Vec3::splat(1.6)))
                })
                .collect()
        };
        let (a, _) = Bvh::from_aabbs(config, &spread(&mut rng, 6000, 30.0)).unwrap();
        let (b, _) = Bvh::from_aabbs(config, &spread(&mut rng, 600, 30.0)).unwrap();
        let (ta, tb) = (Tree::of(&a), Tree::of(&b));
        let mut want = Vec::new();
        a.for_each_pair_using(&mut PairScratch::default(), |x, y| {
            want.push(Pair::new(x, y));
        });
        a.for_each_pair_with_using(&b, &mut PairScratch::default(), |x, y| {
            want.push(Pair::new(x, y));
        });
        want.sort_unstable();
        let mut scratch = SplitScratch::default();
        for tasks in [2, 8, 32] {
            scratch.prepare(&ta, &tb, tasks);
            let SplitScratch {
                own: [own, _],
                cross: [cross, _],
                order,
                ..
            } = &scratch;
            assert!(order.windows(2).all(|w| w[0] >= w[1]), "heaviest first");
            let (mut got, mut most, mut stack) = (Vec::new(), 0, Vec::new());
            for &(_, item) in order {
                let before = got.len();
                let mut f = |x, y| got.push(Pair::new(x, y));
                let item = item as usize;
                if let Some(&own_item) = own.get(item) {
                    stack.push(own_item);
                    drain_own(&ta, &mut stack, &mut Noted::new(), &mut f);
                } else {
                    stack.push(cross[item - own.len()]);
                    drain_cross(&ta, &tb, &mut stack, &mut Noted::new(), &mut f);
                }
                most = most.max(got.len() - before);
            }
            got.sort_unstable();
            assert_eq!(got, want, "tasks {tasks}");
            assert!(
                most * 2 * tasks <= want.len(),
                "tasks {tasks}: one item holds {most} of {} pairs",
                want.len()
            );
        }
    }

    /// The split descents find each pair of `a` × `a` and `a` × `b` once, whatever the task
    /// and thread counts, as brute force over the live boxes does.
    #[test]
    fn split_descents_find_every_pair_once() {
        let mut rng = Rng::new(29);
        let mut scratch = SplitScratch::default();
        for (n, m) in [(0, 0), (0, 5), (1, 0), (6, 3), (300, 40), (3000, 400)] {
            let mut keys = SlotMap::with_key();
            let a = changed_tree(&mut rng, &mut keys, n);
            let b = changed_tree(&mut rng, &mut keys, m);
            let (mut boxes_a, mut boxes_b) = (Vec::new(), Vec::new());
            a.for_each(|k, x| boxes_a.push((k, x)));
            b.for_each(|k, x| boxes_b.push((k, x)));
            let mut want = Vec::new();
            for (i, (ka, xa)) in boxes_a.iter().enumerate() {
                for (kb, xb) in boxes_a[i + 1..].iter().chain(&boxes_b) {
                    if xa.overlaps(xb) {
                        want.push(Pair::new(*ka, *kb));
                    }
                }
            }
            want.sort_unstable();
            for threads in [1, 2, 3, 8] {
                let pool = rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .build()
                    .unwrap();
                for tasks in [1, 2, 3, 8, 33] {
                    let mut out = vec![Vec::new(); tasks];
                    pool.install(|| {
                        a.for_each_pair_split(&b, &mut scratch, &mut out, &|o, x, y| {
                            o.push(Pair::new(x, y));
                        });
                    });
                    let mut got: Vec<Pair> = out.concat();
                    got.sort_unstable();
                    assert_eq!(got, want, "n {n} m {m} threads {threads} tasks {tasks}");
                }
            }
        }
    }
}
