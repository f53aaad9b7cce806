//! Rays against the current boxes: [`Bvh::cast_ray`], [`Bvh::cast_ray_all`], and the ray
//! candidate walks (one tree or two at once) that the sphere casts and the `BroadPhase`'s rays
//! re-test exactly. The walk keeps its stack inline, so it does not allocate unless the trees
//! are deeper than [`INLINE_STACK`].

use super::Bvh;
use super::lanes::{GROUP, Group};
use super::node::INLINE_STACK;
use crate::geom::{Aabb, SimdBox, inverse_dir, ray_is_valid};
use crate::pair::ProxyKey;
use crate::search::{FirstHit, Slab};
use core::ops::ControlFlow;
use glam::{Vec3, Vec4};
use slotmap::Key;

impl Slab {
    /// Bit `k` set iff [`Slab::entry`] of box `k` of `group` by `limit` is some, for a
    /// segment with no zero direction component (`finite`): the same operations on the same
    /// floats, lane by lane (`t_near` is the largest of the axes' and 0, `t_far` the smallest
    /// of the axes' and `limit`).
    /// `INFLATED` false skips the growth, for a slab of `inflate == 0` (a ray), whose boxes
    /// grown by `±0` are the boxes themselves, bit for bit.
    #[inline(always)]
    fn group_mask<const INFLATED: bool>(&self, group: &Group, limit: f32) -> u32 {
        debug_assert!(self.finite && (INFLATED || self.inflate == 0.0));
        let (min, max) = group.faces();
        let mut near = Vec4::ZERO;
        let mut far = Vec4::splat(limit);
        for a in 0..3 {
            let (lo, hi) = if INFLATED {
                (min[a] - self.inflate4, max[a] + self.inflate4)
            } else {
                (min[a], max[a])
            };
            let t1 = (lo - self.origin4[a]) * self.inv4[a];
            let t2 = (hi - self.origin4[a]) * self.inv4[a];
            near = near.max(t1.min(t2));
            far = far.min(t1.max(t2));
        }
        near.cmple(far).bitmask()
    }
}

impl Bvh {
    /// The closest live box hit by the segment `origin + t·dir`, `t ∈ [0, max_t]`, with its
    /// `t` in units of `dir` (0 when the origin is inside); ties go to the smaller key. `None`
    /// for a non-finite origin or direction, a NaN or negative `max_t`, or no hit.
    ///
    /// Children are visited nearer-entry first, and `max_t` shrinks to the best hit so far,
    /// so subtrees entered behind it are skipped (entered *at* it are still visited, for ties).
    #[must_use]
    pub fn cast_ray(&self, origin: Vec3, dir: Vec3, max_t: f32) -> Option<(ProxyKey, f32)> {
        if !ray_is_valid(origin, dir, max_t) {
            return None;
        }
        let inv = inverse_dir(dir);
        let mut hit = FirstHit::new(max_t);
        self.ray_candidates(origin, dir, max_t, 0.0, |key, aabb| {
            hit.offer(key, aabb.ray_entry(origin, inv, hit.limit()))
        });
        hit.best()
    }

    /// Calls `f(key, t)` for every live box hit by the segment `origin + t·dir`,
    /// `t ∈ [0, max_t]`, with its entry `t`, each once, in no particular order. Nothing for an
    /// invalid ray (as in [`Bvh::cast_ray`]).
    pub fn cast_ray_all(
        &self,
        origin: Vec3,
        dir: Vec3,
        max_t: f32,
        mut f: impl FnMut(ProxyKey, f32),
    ) {
        if !ray_is_valid(origin, dir, max_t) {
            return;
        }
        let inv = inverse_dir(dir);
        for (b, &key) in self.pending_boxes().iter().zip(self.pending_keys()) {
            if let Some(t) = b.aabb().ray_entry(origin, inv, max_t) {
                f(key, t);
            }
        }
        let _ = self.walk(
            |node| node.aabb().ray_entry(origin, inv, max_t).is_some(),
            |range| {
                for i in range {
                    let key = self.keys[i];
                    if !key.is_null()
                        && let Some(t) = self.boxes[i].aabb().ray_entry(origin, inv, max_t)
                    {
                        f(key, t);
                    }
                }
                ControlFlow::Continue(())
            },
        );
    }

    /// Calls `visit(key, aabb)` for every live box `aabb` that, grown by `inflate` on every
    /// side, the segment `origin + t·dir`, `t ∈ [0, best]` enters ([`Aabb::ray_entry`],
    /// touching counts), once each; `best` starts at `max_t` and becomes
    /// `min(best, returned value)` after each visit (a NaN return leaves it), so a box entered
    /// exactly at `best` is still visited. The pending boxes come first, then the tree, nearer
    /// child first. Nothing for a non-finite origin or direction, a NaN or negative `max_t`, or
    /// a NaN or negative `inflate`.
    pub(crate) fn ray_candidates(
        &self,
        origin: Vec3,
        dir: Vec3,
        max_t: f32,
        inflate: f32,
        visit: impl FnMut(ProxyKey, &Aabb) -> f32,
    ) {
        ray_walk([self], origin, dir, max_t, inflate, visit);
    }

    /// [`Bvh::ray_candidates`] over the boxes of two trees in one walk: both trees' pending
    /// boxes first, then their roots as the two children of a virtual root, nearer entry
    /// first (`a` on a tie), on one stack.
    pub(crate) fn ray_candidates_both(
        a: &Bvh,
        b: &Bvh,
        origin: Vec3,
        dir: Vec3,
        max_t: f32,
        inflate: f32,
        visit: impl FnMut(ProxyKey, &Aabb) -> f32,
    ) {
        ray_walk([a, b], origin, dir, max_t, inflate, visit);
    }
}

/// [`Bvh::ray_candidates`] over the boxes of `N` (one or two) trees in one walk: the
/// trees' roots are the children of a virtual root, entered nearer first (the first tree on a
/// tie), each depth-first on one stack of `(node, entry t)`. At an interior node the walk goes
/// on into the nearer child the segment enters by `best` (the first on a tie) and pushes the
/// farther one; a node (or root) whose entry lies behind `best` when its turn comes is
/// skipped. Each box of each tree is visited at most once (a tree's boxes lie in its leaves'
/// disjoint ranges), and one is skipped only if its entry, no smaller than its node's, lies
/// behind `best`.
#[inline(always)]
fn ray_walk<const N: usize>(
    trees: [&Bvh; N],
    origin: Vec3,
    dir: Vec3,
    max_t: f32,
    inflate: f32,
    visit: impl FnMut(ProxyKey, &Aabb) -> f32,
) {
    const { assert!(N == 1 || N == 2) };
    if !ray_is_valid(origin, dir, max_t) || inflate.is_nan() || inflate < 0.0 {
        return;
    }
    // Empty trees (a world of spheres alone) skip the segment's setup.
    if trees.iter().all(|t| t.boxes.is_empty()) {
        return;
    }
    // A ray's tests skip the growth by zero ([`Slab::group_mask`]), and a segment with no
    // zero direction component takes the NaN-free tests.
    let slab = Slab::new(origin, dir, inflate);
    match (inflate == 0.0, slab.finite) {
        (true, true) => ray_walk_in::<N, false, true>(trees, &slab, max_t, visit),
        (true, false) => ray_walk_in::<N, false, false>(trees, &slab, max_t, visit),
        (false, true) => ray_walk_in::<N, true, true>(trees, &slab, max_t, visit),
        (false, false) => ray_walk_in::<N, true, false>(trees, &slab, max_t, visit),
    }
}

/// [`ray_walk`] of a valid segment, with `INFLATED` false iff `slab.inflate` is 0 and
/// `FINITE` iff `slab.finite`.
#[inline(always)]
fn ray_walk_in<const N: usize, const INFLATED: bool, const FINITE: bool>(
    trees: [&Bvh; N],
    slab: &Slab,
    max_t: f32,
    mut visit: impl FnMut(ProxyKey, &Aabb) -> f32,
) {
    debug_assert!(FINITE == slab.finite && INFLATED == (slab.inflate != 0.0));
    let entry = |b: &SimdBox, limit: f32| slab.entry_or_miss::<INFLATED, FINITE>(b, limit);
    let mut best = max_t;
    let mut consider = |key: ProxyKey, b: &SimdBox, best: &mut f32| {
        if !key.is_null() && entry(b, *best).1 {
            *best = best.min(visit(key, &b.aabb()));
        }
    };
    for tree in trees {
        for (b, &key) in tree.pending_boxes().iter().zip(tree.pending_keys()) {
            consider(key, b, &mut best);
        }
    }
    // The trees the segment enters by `best`, nearer root first (the first tree on a tie):
    // a depth-first walk of a virtual root over them would finish the nearer one first.
    let mut roots = [(0, f32::INFINITY, false); N];
    for (k, tree) in trees.iter().enumerate() {
        if let Some(root) = tree.nodes.first() {
            let (t, enters) = entry(&root.bounds(), best);
            roots[k] = (k, t, enters);
        }
    }
    if let [first, second] = &mut roots[..]
        && second.1 < first.1
    {
        core::mem::swap(first, second);
    }
    let mut stack = RayStack::new();
    for (k, t_root, enters) in roots {
        // A hit in the first tree may lie before the second one's root.
        if !enters || t_root > best {
            continue;
        }
        // `% N`: an index into `trees` that needs no bounds check.
        let tree = trees[k % N];
        let nodes = &tree.nodes[..];
        // The node being entered: the nearer entered child of the last interior node, taken
        // without the stack's round trip, else the top of the stack not behind `best`.
        let mut next = Some((0, t_root));
        while let Some((n, _)) = next.take().or_else(|| stack.pop_before(best)) {
            let node = &nodes[n as usize];
            if node.is_leaf() {
                let range = node.range();
                match tree.lanes.leaf(range.start, range.len()) {
                    // Four boxes per test; each that passes is tested again (it may lie
                    // behind a hit found since).
                    Some(leaf) if FINITE => {
                        let mut m = 0u64;
                        for (j, group) in leaf.blocks.iter().enumerate() {
                            let hits = slab.group_mask::<INFLATED>(group, best);
                            m |= u64::from(hits) << (GROUP * j);
                        }
                        m &= leaf.valid;
                        let base = range.start - leaf.off;
                        while m != 0 {
                            let i = base + m.trailing_zeros() as usize;
                            m &= m - 1;
                            consider(tree.keys[i], &tree.boxes[i], &mut best);
                        }
                    }
                    _ => {
                        for i in range {
                            consider(tree.keys[i], &tree.boxes[i], &mut best);
                        }
                    }
                }
                continue;
            }
            // Nodes are read as one 16-byte load per corner (`Node::bounds`), whose fourth
            // lane the slab test ignores. The nearer entered child is entered next (`a` on a
            // tie), the farther one pushed. Which child comes next is a branch, not a select:
            // a predicted branch lets the next node's load start before both slab tests end.
            // (`next` carries the entry `t` too, as the stack's entries do; with the index
            // alone the compiler turns the match into selects.)
            let (a, b) = node.children(n);
            let (ta, a_in) = entry(&nodes[a as usize].bounds(), best);
            let (tb, b_in) = entry(&nodes[b as usize].bounds(), best);
            let (a, b) = ((a, ta), (b, tb));
            next = match (a_in, b_in) {
                (true, true) => {
                    let (near, far) = if tb < ta { (b, a) } else { (a, b) };
                    stack.push(far);
                    Some(near)
                }
                (true, false) => Some(a),
                (false, true) => Some(b),
                (false, false) => None,
            };
        }
    }
}

/// Entries [`RayStack`] keeps inline before it spills to the heap (as [`INLINE_STACK`]).
pub(super) const RAY_STACK: usize = INLINE_STACK;

/// The LIFO stack of `(node, entry t)` of [`ray_walk`], with [`RAY_STACK`] inline entries
/// and a heap `Vec` for the rest, so a walk does not allocate unless the trees are deeper
/// than that.
pub(super) struct RayStack {
    buf: [(u32, f32); RAY_STACK],
    len: usize,
    /// Entries pushed while `buf` was full; always newer than all of `buf`.
    spill: Vec<(u32, f32)>,
}

impl RayStack {
    pub(super) fn new() -> Self {
        RayStack {
            buf: [(0, 0.0); RAY_STACK],
            len: 0,
            spill: Vec::new(),
        }
    }

    #[inline(always)]
    pub(super) fn push(&mut self, x: (u32, f32)) {
        if let Some(slot) = self.buf.get_mut(self.len) {
            *slot = x;
            self.len += 1;
        } else {
            spill_push(&mut self.spill, x);
        }
    }

    /// Pops entries until one whose `t` is not behind `best`, and returns it.
    #[inline(always)]
    pub(super) fn pop_before(&mut self, best: f32) -> Option<(u32, f32)> {
        loop {
            // The spill is only ever non-empty while `buf` is full.
            let x = if self.len == RAY_STACK
                && let Some(x) = self.spill.pop()
            {
                x
            } else {
                self.len = self.len.checked_sub(1)?;
                *self.buf.get(self.len)?
            };
            if x.1 <= best {
                return Some(x);
            }
        }
    }
}

/// [`RayStack::push`] past the inline entries, out of the hot loop.
#[cold]
#[inline(never)]
fn spill_push(spill: &mut Vec<(u32, f32)>, x: (u32, f32)) {
    spill.push(x);
}
