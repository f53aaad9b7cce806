//! Overlapping pairs: the tree against itself, a tree against another tree, and the pending
//! lists against both (tree queries and sort-and-sweep on x).

use super::Bvh;
use super::node::Node;
use crate::{Aabb, ProxyKey};

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
        // those of (child, b) for both children of a (or of b), so descending one side
        // partitions them again, and a cross item whose node boxes do not overlap holds no
        // pair because node boxes contain their primitives'. Every pair is thus produced by
        // exactly one leaf-level item, once.
        let mut stack = core::mem::take(&mut self.pair_stack);
        stack.clear();
        if !self.nodes.is_empty() {
            stack.push((0, 0));
        }
        while let Some((a, b)) = stack.pop() {
            if a != b {
                cross_step(self, self, a, b, &mut stack, &mut f);
                continue;
            }
            let node = &self.nodes[a as usize];
            if node.is_leaf() {
                let range = node.range();
                for i in range.clone() {
                    for j in i + 1..range.end {
                        if self.boxes[i].overlaps(&self.boxes[j]) {
                            f(self.keys[i], self.keys[j]);
                        }
                    }
                }
            } else {
                let (l, r) = node.children(a);
                if self.nodes[l as usize].overlaps(&self.nodes[r as usize]) {
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
        sort_by_min_x(&mut order, self.tree_len..self.boxes.len(), &self.boxes);
        for (n, &p) in order.iter().enumerate() {
            let bp = &self.boxes[p as usize];
            for &q in &order[n + 1..] {
                let bq = &self.boxes[q as usize];
                if bq.min.x > bp.max.x {
                    break;
                }
                if bp.overlaps(bq) {
                    f(self.keys[p as usize], self.keys[q as usize]);
                }
            }
        }
        self.sweep_a = order;
    }

    /// Calls `f(a, b)` once for every live primitive `a` of `self` and `b` of `other` whose
    /// current boxes overlap, in no particular order: tree × tree by simultaneous descent,
    /// pending lists by tree queries and a merged sort-and-sweep. Scratch lives in `self`.
    pub fn for_each_pair_with(&mut self, other: &Bvh, mut f: impl FnMut(ProxyKey, ProxyKey)) {
        let mut stack = core::mem::take(&mut self.pair_stack);
        stack.clear();
        if let (Some(a), Some(b)) = (self.nodes.first(), other.nodes.first())
            && a.overlaps(b)
        {
            stack.push((0, 0));
        }
        while let Some((a, b)) = stack.pop() {
            cross_step(self, other, a, b, &mut stack, &mut f);
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
        sort_by_min_x(&mut xs, self.tree_len..self.boxes.len(), &self.boxes);
        sort_by_min_x(&mut ys, other.tree_len..other.boxes.len(), &other.boxes);
        sweep_cross(&xs, &self.boxes, &ys, &other.boxes, |i, j| {
            f(self.keys[i], other.keys[j]);
        });
        self.sweep_a = xs;
        self.sweep_b = ys;
    }
}

/// One item `(a, b)` of a descent over two disjoint subtrees with overlapping boxes, `a` in
/// `ta` and `b` in `tb`: every overlapping primitive pair if both are leaves, else the items
/// of the larger interior node's children against the other, for the children whose box
/// overlaps the other's (pruned before the push, not after the pop).
#[inline]
fn cross_step(
    ta: &Bvh,
    tb: &Bvh,
    a: u32,
    b: u32,
    stack: &mut Vec<(u32, u32)>,
    f: &mut impl FnMut(ProxyKey, ProxyKey),
) {
    let na = &ta.nodes[a as usize];
    let nb = &tb.nodes[b as usize];
    debug_assert!(na.overlaps(nb));
    match (na.is_leaf(), nb.is_leaf()) {
        (true, true) => {
            let b_box = nb.aabb();
            for i in na.range() {
                let bi = &ta.boxes[i];
                if !bi.overlaps(&b_box) {
                    continue;
                }
                for j in nb.range() {
                    if bi.overlaps(&tb.boxes[j]) {
                        f(ta.keys[i], tb.keys[j]);
                    }
                }
            }
        }
        (false, true) => push_children_a(ta, na, a, nb, b, stack),
        (true, false) => push_children_b(na, a, tb, nb, b, stack),
        (false, false) => {
            if na.aabb().surface_area() >= nb.aabb().surface_area() {
                push_children_a(ta, na, a, nb, b, stack);
            } else {
                push_children_b(na, a, tb, nb, b, stack);
            }
        }
    }
}

/// Pushes `(child, b)` for the children of `a` whose box overlaps `b`'s.
#[inline]
fn push_children_a(ta: &Bvh, na: &Node, a: u32, nb: &Node, b: u32, stack: &mut Vec<(u32, u32)>) {
    let (l, r) = na.children(a);
    for c in [r, l] {
        if ta.nodes[c as usize].overlaps(nb) {
            stack.push((c, b));
        }
    }
}

/// Pushes `(a, child)` for the children of `b` whose box overlaps `a`'s.
#[inline]
fn push_children_b(na: &Node, a: u32, tb: &Bvh, nb: &Node, b: u32, stack: &mut Vec<(u32, u32)>) {
    let (l, r) = nb.children(b);
    for c in [r, l] {
        if tb.nodes[c as usize].overlaps(na) {
            stack.push((a, c));
        }
    }
}

/// Fills `order` with the indices `range`, sorted by `boxes[i].min.x`.
fn sort_by_min_x(order: &mut Vec<u32>, range: core::ops::Range<usize>, boxes: &[Aabb]) {
    order.clear();
    order.extend(range.map(|i| i as u32));
    order.sort_unstable_by(|&i, &j| boxes[i as usize].min.x.total_cmp(&boxes[j as usize].min.x));
}

/// Every overlapping pair of `xs` × `ys` (index lists sorted by `min.x`), as `f(x, y)`.
///
/// Merge the two lists by `min.x` (ties: `xs` first). When a box is taken, every box of the
/// other list it overlaps and that comes later in the merge lies at or after the other list's
/// cursor and has `min.x <= its max.x`, so scanning from the cursor until `min.x` passes its
/// `max.x` finds them all; a pair is found from whichever of its two boxes is taken first.
fn sweep_cross(xs: &[u32], bx: &[Aabb], ys: &[u32], by: &[Aabb], mut f: impl FnMut(usize, usize)) {
    let (mut i, mut j) = (0, 0);
    while i < xs.len() && j < ys.len() {
        let x = xs[i] as usize;
        let y = ys[j] as usize;
        if bx[x].min.x <= by[y].min.x {
            for &y2 in &ys[j..] {
                let y2 = y2 as usize;
                if by[y2].min.x > bx[x].max.x {
                    break;
                }
                if bx[x].overlaps(&by[y2]) {
                    f(x, y2);
                }
            }
            i += 1;
        } else {
            for &x2 in &xs[i..] {
                let x2 = x2 as usize;
                if bx[x2].min.x > by[y].max.x {
                    break;
                }
                if bx[x2].overlaps(&by[y]) {
                    f(x2, y);
                }
            }
            j += 1;
        }
    }
}
