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
pub(crate) struct PairScratch {
    pub(super) stack: Vec<(u32, u32)>,
    pub(super) sweep_a: Vec<u64>,
    sweep_b: Vec<u64>,
}

impl PairScratch {
    /// Heap bytes held (capacities).
    #[must_use]
    pub(crate) fn heap_bytes(&self) -> usize {
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
    pub(crate) fn for_each_pair_using(
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
    pub(super) fn pending_self_pairs(
        &self,
        order: &mut Vec<u64>,
        f: &mut impl FnMut(ProxyKey, ProxyKey),
    ) {
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
    pub(crate) fn for_each_pair_with_using(
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
    pub(super) fn pending_cross_pairs(
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

/// Runs the self-traversal of a tree from the items on `stack` until it is empty. The unordered
/// primitive pairs below a node n split into the pairs within its first child l, within its
/// second child r, and across l × r: so the item (n, n) is replaced by (l, l), (r, r),
/// (l, r), and a leaf (n, n) tests its own range i < j. A cross item (a, b) names two
/// disjoint subtrees; its pairs are those of the child pairs of a × b (a leaf standing for
/// itself), so descending partitions them again, and a cross item whose node boxes do not
/// overlap holds no pair because node boxes contain their primitives'. Every pair below the
/// items is thus produced by exactly one leaf-level item, once.
pub(super) fn drain_own(
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
pub(super) fn own_children(t: &Tree, n: u32, node: &Node, stack: &mut Vec<(u32, u32)>) {
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
pub(super) fn drain_cross(
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
pub(super) struct Tree<'a> {
    pub(super) nodes: &'a [Node],
    boxes: &'a [SimdBox],
    lanes: &'a Lanes,
    keys: &'a [ProxyKey],
}

impl<'a> Tree<'a> {
    pub(super) fn of(bvh: &'a Bvh) -> Self {
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
pub(super) fn cross_children(ta: &Tree, tb: &Tree, a: u32, b: u32, stack: &mut Vec<(u32, u32)>) {
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
pub(super) struct Noted {
    /// One block more than 64 lanes: [`Noted::pack`] empties the three lanes after the last
    /// noted box unconditionally.
    blocks: [Group; 64 / GROUP + 1],
    keys: [ProxyKey; 64],
    /// The pairs found by the leaf kernels, before they are handed on.
    found: Found,
}

impl Noted {
    pub(super) fn new() -> Noted {
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
