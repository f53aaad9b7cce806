//! Box queries and ray casts against the current boxes (tree, then pending list). They take
//! `&self` and keep their stack inline, so they do not allocate unless the tree is deeper than
//! [`INLINE_STACK`].

use super::Bvh;
use super::node::{INLINE_STACK, Node, SmallStack};
use crate::geom::{Aabb, SimdBox, check_aabb, inverse_dir, ray_is_valid};
use crate::pair::ProxyKey;
use glam::Vec3;
use slotmap::Key;

impl Bvh {
    /// Calls `f` with the key of every live box that overlaps `aabb` (closed: touching
    /// counts), each once, in no particular order. A non-finite or inverted query box matches
    /// nothing, as in `Octree::query_aabb` and `BroadPhase::query_aabb`.
    pub fn query_aabb(&self, aabb: &Aabb, f: impl FnMut(ProxyKey)) {
        if check_aabb(aabb).is_ok() {
            self.query_aabb_unchecked(aabb, f);
        }
    }

    /// [`Bvh::query_aabb`] without the input check, for boxes the crate made itself: a sphere
    /// or body near `f32::MAX` has a box that overflows to ±∞ from finite input, and it must
    /// still find what it overlaps.
    pub(crate) fn query_aabb_unchecked(&self, aabb: &Aabb, mut f: impl FnMut(ProxyKey)) {
        let q = SimdBox::new(aabb);
        self.query_tree(&q, |i| f(self.keys[i]));
        for (b, &key) in self.pending_boxes().iter().zip(self.pending_keys()) {
            if b.overlaps(&q) {
                f(key);
            }
        }
    }

    /// The index of every tree primitive (tombstones excluded: their box is empty) whose
    /// box overlaps `aabb`.
    pub(super) fn query_tree(&self, aabb: &SimdBox, mut f: impl FnMut(usize)) {
        self.walk(
            |node| node.bounds().overlaps(aabb),
            |i| {
                if self.boxes[i].overlaps(aabb) {
                    f(i);
                }
            },
        );
    }

    /// Depth-first over the tree with the inline stack: enters every node that passes
    /// `enter` (children only through their parent) and calls `visit` with each primitive
    /// index of the leaves entered.
    fn walk(&self, mut enter: impl FnMut(&Node) -> bool, mut visit: impl FnMut(usize)) {
        if self.nodes.is_empty() {
            return;
        }
        let mut stack = SmallStack::<u32, INLINE_STACK>::new(0);
        stack.push(0);
        while let Some(n) = stack.pop() {
            let node = &self.nodes[n as usize];
            if !enter(node) {
                continue;
            }
            if node.is_leaf() {
                node.range().for_each(&mut visit);
            } else {
                let (a, b) = node.children(n);
                stack.push(b);
                stack.push(a);
            }
        }
    }

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
        let mut best: Option<(ProxyKey, f32)> = None;
        let mut limit = max_t;
        let mut consider = |key: ProxyKey, aabb: &Aabb, limit: &mut f32| {
            if key.is_null() {
                return;
            }
            if let Some(t) = aabb.ray_entry(origin, inv, *limit) {
                let better = match best {
                    None => true,
                    Some((k, bt)) => t < bt || (t == bt && key < k),
                };
                if better {
                    best = Some((key, t));
                    *limit = t;
                }
            }
        };
        for (b, &key) in self.pending_boxes().iter().zip(self.pending_keys()) {
            consider(key, &b.aabb(), &mut limit);
        }
        let Some(root) = self.nodes.first() else {
            return best;
        };
        let Some(t_root) = root.aabb().ray_entry(origin, inv, limit) else {
            return best;
        };
        let mut stack = SmallStack::<(u32, f32), INLINE_STACK>::new((0, 0.0));
        stack.push((0, t_root));
        while let Some((n, t_enter)) = stack.pop() {
            if t_enter > limit {
                continue;
            }
            let node = &self.nodes[n as usize];
            if node.is_leaf() {
                for i in node.range() {
                    consider(self.keys[i], &self.boxes[i].aabb(), &mut limit);
                }
                continue;
            }
            let (a, b) = node.children(n);
            let ta = self.nodes[a as usize].aabb().ray_entry(origin, inv, limit);
            let tb = self.nodes[b as usize].aabb().ray_entry(origin, inv, limit);
            match (ta, tb) {
                (Some(ta), Some(tb)) if tb < ta => {
                    stack.push((a, ta));
                    stack.push((b, tb));
                }
                (Some(ta), Some(tb)) => {
                    stack.push((b, tb));
                    stack.push((a, ta));
                }
                (Some(ta), None) => stack.push((a, ta)),
                (None, Some(tb)) => stack.push((b, tb)),
                (None, None) => {}
            }
        }
        best
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
        self.walk(
            |node| node.aabb().ray_entry(origin, inv, max_t).is_some(),
            |i| {
                let key = self.keys[i];
                if key.is_null() {
                    return;
                }
                if let Some(t) = self.boxes[i].aabb().ray_entry(origin, inv, max_t) {
                    f(key, t);
                }
            },
        );
    }

    pub(super) fn pending_boxes(&self) -> &[SimdBox] {
        &self.boxes[self.tree_len..]
    }

    pub(super) fn pending_keys(&self) -> &[ProxyKey] {
        &self.keys[self.tree_len..]
    }
}
