//! Overlapping pairs: the tree against itself, a tree against another tree, and the pending
//! lists against both (tree queries and sort-and-sweep on x).

use super::Bvh;
use super::node::Node;
use crate::geom::SimdBox;
use crate::pair::{Pair, ProxyKey};
use crate::sweep::{self, Ordered};

impl Bvh {
    /// Calls `f(a, b)` once for every unordered pair of live primitives whose current boxes
    /// overlap (closed: touching counts), in no particular order and with `a`, `b` in no
    /// particular order. Exact between `update` and `refit`. Allocation-free once the scratch
    /// stack has grown to the tree's needs.
    pub fn for_each_pair(&mut self, mut f: impl FnMut(ProxyKey, ProxyKey)) {
        // Self-traversal of node pairs. The unordered primitive pairs below a node n split
        // into the pairs within its first child l, within its second child r, and across
        // l × r: so (n, n) is replaced by (l, l), (r, r), (l, r), and a leaf (n, n) tests its
        // own range i < j. A cross item (a, b) names two disjoint subtrees; its pairs are
        // those of the child pairs of a × b (a leaf standing for itself), so descending
        // partitions them again, and a cross item whose node boxes do not overlap holds no
        // pair because node boxes contain their primitives'. Every pair is thus produced by
        // exactly one leaf-level item, once.
        let mut stack = core::mem::take(&mut self.pair_stack);
        stack.clear();
        let t = Tree::of(self);
        if !t.nodes.is_empty() {
            stack.push((0, 0));
        }
        while let Some((a, b)) = stack.pop() {
            if a != b {
                cross_step(&t, &t, a, b, &mut stack, &mut f);
                continue;
            }
            let node = &t.nodes[a as usize];
            if node.is_leaf() {
                let range = node.range();
                leaf_self_pairs(&t.boxes[range.clone()], &t.keys[range], &mut f);
            } else {
                let (l, r) = node.children(a);
                if t.nodes[l as usize]
                    .bounds()
                    .overlaps(&t.nodes[r as usize].bounds())
                {
                    stack.push((l, r));
                }
                stack.extend_from_slice(&[(r, r), (l, l)]);
            }
        }
        self.pair_stack = stack;

        // Pending × tree, then pending × pending.
        for p in self.tree_len..self.boxes.len() {
            self.query_tree(&self.boxes[p], |i| f(self.keys[p], self.keys[i]));
        }
        let mut order = core::mem::take(&mut self.sweep_a);
        let (boxes, keys) = (self.pending_boxes(), self.pending_keys());
        sweep::sort_entries(&mut order, boxes, 0);
        let list = Ordered {
            order: &order,
            items: boxes,
            axis: 0,
        };
        sweep::self_pairs_of(&list, |i, j| f(keys[i], keys[j]));
        self.sweep_a = order;
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
    pub fn for_each_pair_with(&mut self, other: &Bvh, mut f: impl FnMut(ProxyKey, ProxyKey)) {
        let mut stack = core::mem::take(&mut self.pair_stack);
        stack.clear();
        let (ta, tb) = (Tree::of(self), Tree::of(other));
        if let (Some(a), Some(b)) = (ta.nodes.first(), tb.nodes.first())
            && a.bounds().overlaps(&b.bounds())
        {
            stack.push((0, 0));
        }
        while let Some((a, b)) = stack.pop() {
            cross_step(&ta, &tb, a, b, &mut stack, &mut f);
        }
        self.pair_stack = stack;

        for p in self.tree_len..self.boxes.len() {
            other.query_tree(&self.boxes[p], |i| f(self.keys[p], other.keys[i]));
        }
        for q in other.tree_len..other.boxes.len() {
            self.query_tree(&other.boxes[q], |i| f(self.keys[i], other.keys[q]));
        }
        let mut xs = core::mem::take(&mut self.sweep_a);
        let mut ys = core::mem::take(&mut self.sweep_b);
        let (bx, kx) = (self.pending_boxes(), self.pending_keys());
        let (by, ky) = (other.pending_boxes(), other.pending_keys());
        sweep::sort_entries(&mut xs, bx, 0);
        sweep::sort_entries(&mut ys, by, 0);
        let (lx, ly) = (
            Ordered {
                order: &xs,
                items: bx,
                axis: 0,
            },
            Ordered {
                order: &ys,
                items: by,
                axis: 0,
            },
        );
        sweep::cross_pairs_of(&lx, &ly, |i, j| f(kx[i], ky[j]));
        self.sweep_a = xs;
        self.sweep_b = ys;
    }
}

/// The slices of a tree that the descents read (tree primitives only, not the pending ones).
struct Tree<'a> {
    nodes: &'a [Node],
    boxes: &'a [SimdBox],
    keys: &'a [ProxyKey],
}

impl<'a> Tree<'a> {
    fn of(bvh: &'a Bvh) -> Self {
        Tree {
            nodes: &bvh.nodes,
            boxes: &bvh.boxes[..bvh.tree_len],
            keys: &bvh.keys[..bvh.tree_len],
        }
    }
}

/// One item `(a, b)` of a descent over two disjoint subtrees with overlapping boxes, `a` in
/// `ta` and `b` in `tb`: every overlapping primitive pair if both are leaves, else the items
/// of the children of both interior nodes (a leaf standing in for itself) whose boxes
/// overlap (pruned before the push, not after the pop).
#[inline]
fn cross_step(
    ta: &Tree,
    tb: &Tree,
    a: u32,
    b: u32,
    stack: &mut Vec<(u32, u32)>,
    f: &mut impl FnMut(ProxyKey, ProxyKey),
) {
    let na = &ta.nodes[a as usize];
    let nb = &tb.nodes[b as usize];
    match (na.is_leaf(), nb.is_leaf()) {
        (true, true) => leaf_pairs(ta, na, tb, nb, f),
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
        (false, false) => {
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

/// The most boxes whose tests fit one mask (`u64`) of [`mask_of`].
const MASK_BITS: usize = u64::BITS as usize;

/// Every overlapping pair within one leaf. Each box's tests against the boxes after it go into a
/// bit mask and the pairs are read from its set bits (see [`leaf_pairs`]); leaves of more than
/// `MASK_BITS + 1` boxes, which only a `max_leaf_size` above 64 makes, take the plain loop.
#[inline]
fn leaf_self_pairs(boxes: &[SimdBox], keys: &[ProxyKey], f: &mut impl FnMut(ProxyKey, ProxyKey)) {
    if boxes.len() > MASK_BITS + 1 {
        sweep::all_pairs(boxes, |i, _, j, _| f(keys[i], keys[j]));
        return;
    }
    for (i, (bi, &ki)) in boxes.iter().zip(keys).enumerate() {
        for k in bits(mask_of(&boxes[i + 1..], bi)) {
            f(ki, keys[i + 1 + k]);
        }
    }
}

/// Every overlapping pair of the primitives of leaf `na` (in `ta`) × leaf `nb` (in `tb`). A
/// box of either leaf that misses the other leaf's box pairs with nothing there, so the boxes
/// of each leaf that meet the other leaf's box are noted in a bit mask first, and only those
/// are tested against each other: two leaves that overlap at a corner cost one pass over each,
/// not the product. Every test's result goes into a bit mask too, and the pairs are read from
/// the set bits, so the loops branch on their counts, not on the tests (whose outcomes the
/// branch predictor cannot guess). Leaves of more than [`MASK_BITS`] boxes, which only a
/// `max_leaf_size` above 64 makes, take the plain loop.
#[inline]
fn leaf_pairs(ta: &Tree, na: &Node, tb: &Tree, nb: &Node, f: &mut impl FnMut(ProxyKey, ProxyKey)) {
    let (a_box, b_box) = (na.bounds(), nb.bounds());
    let (ra, rb) = (na.range(), nb.range());
    let (boxes_a, keys_a) = (&ta.boxes[ra.clone()], &ta.keys[ra]);
    let (boxes_b, keys_b) = (&tb.boxes[rb.clone()], &tb.keys[rb]);
    if boxes_a.len() > MASK_BITS || boxes_b.len() > MASK_BITS {
        for (bi, &ki) in boxes_a.iter().zip(keys_a) {
            if bi.overlaps(&b_box) {
                for (bj, &kj) in boxes_b.iter().zip(keys_b) {
                    if bi.overlaps(bj) {
                        f(ki, kj);
                    }
                }
            }
        }
        return;
    }
    let near_a = mask_of(boxes_b, &a_box);
    if near_a == 0 {
        return;
    }
    for i in bits(mask_of(boxes_a, &b_box)) {
        let bi = &boxes_a[i];
        let mut hits = 0;
        for k in bits(near_a) {
            hits |= u64::from(bi.overlaps(&boxes_b[k])) << k;
        }
        for k in bits(hits) {
            f(keys_a[i], keys_b[k]);
        }
    }
}

/// Bit `k` set iff `boxes[k]` overlaps `b` (at most [`MASK_BITS`] boxes), computed without
/// branches.
#[inline]
fn mask_of(boxes: &[SimdBox], b: &SimdBox) -> u64 {
    debug_assert!(boxes.len() <= MASK_BITS);
    boxes
        .iter()
        .enumerate()
        .fold(0, |m, (k, bk)| m | u64::from(bk.overlaps(b)) << k)
}

/// The positions of the set bits of `m`, lowest first.
#[inline]
fn bits(mut m: u64) -> impl Iterator<Item = usize> {
    core::iter::from_fn(move || {
        (m != 0).then(|| {
            let k = m.trailing_zeros() as usize;
            m &= m - 1;
            k
        })
    })
}
