//! Box, sphere, ray, sphere-cast and nearest queries against the current boxes (tree and
//! pending list), and the box-based candidate traversals the `BroadPhase` re-tests exactly.
//! They take `&self` and keep their stack inline, so they do not allocate unless the tree is
//! deeper than [`INLINE_STACK`], except [`Bvh::nearest`] for its result. The `_with` queries
//! stop as soon as their visitor returns [`ControlFlow::Break`], and say whether it did.
//! The rays and the ray candidates are in `ray`.

use super::Bvh;
use super::lanes::{Splat, bits};
use super::node::{INLINE_STACK, Node, SmallStack};
use crate::geom::{self, Aabb, SimdBox, check_aabb, check_sphere, point_aabb_distance};
use crate::pair::ProxyKey;
use crate::search::{FirstHit, every, nearest_expanding, nearest_start};
use core::ops::ControlFlow;
use glam::{Vec3, Vec3A};
use slotmap::Key;

/// Relative margin of [`near_filter`]'s squared radius: a few `f32` roundings of a sum of
/// three squares, with room to spare.
const NEAR_FILTER_MARGIN: f32 = 32.0 * f32::EPSILON;

/// A test in `f32` lanes that passes every box within `radius` of `p` by
/// [`point_aabb_distance`] (which rounds an `f64` distance once), and every box holding such a
/// box; it may pass a few slightly farther. Derivation: the per-axis gaps `max(min − p,
/// p − max, 0)` are correctly rounded subtractions, monotone in the corners, so a box holding
/// another has gaps no larger, and so no larger a sum of their squares (each operation rounds
/// monotonically); that sum is within a few roundings of the exact squared distance, which the
/// margin on `radius²` covers. An overflow to `+∞` only happens beyond every finite radius,
/// and an underflow only shrinks the sum.
fn near_filter(p: Vec3, radius: f32) -> impl Fn(&SimdBox) -> bool {
    let p = Vec3A::from(p);
    let r2 = radius * radius * (1.0 + NEAR_FILTER_MARGIN);
    move |b: &SimdBox| {
        let gap = (b.min - p).max(p - b.max).max(Vec3A::ZERO);
        gap.length_squared() <= r2
    }
}

impl Bvh {
    /// Calls `f` with the key of every live box that overlaps `aabb` (closed: touching
    /// counts), each once, in no particular order. A non-finite or inverted query box matches
    /// nothing, as in `Octree::query_aabb` and `BroadPhase::query_aabb`.
    pub fn query_aabb(&self, aabb: &Aabb, f: impl FnMut(ProxyKey)) {
        let _ = self.query_aabb_with(aabb, every(f));
    }

    /// [`Bvh::query_aabb`] with a visitor that can stop: the first [`ControlFlow::Break`]
    /// ends the query and is returned; `Continue` if every match was visited.
    pub fn query_aabb_with(
        &self,
        aabb: &Aabb,
        f: impl FnMut(ProxyKey) -> ControlFlow<()>,
    ) -> ControlFlow<()> {
        if check_aabb(aabb).is_err() {
            return ControlFlow::Continue(());
        }
        self.query_aabb_with_unchecked(aabb, f)
    }

    /// [`Bvh::query_aabb`] without the input check, for boxes the crate made itself: a sphere
    /// or body near `f32::MAX` has a box that overflows to ±∞ from finite input, and it must
    /// still find what it overlaps.
    pub(crate) fn query_aabb_unchecked(&self, aabb: &Aabb, f: impl FnMut(ProxyKey)) {
        let _ = self.query_aabb_with_unchecked(aabb, every(f));
    }

    /// [`Bvh::query_aabb_with`] without the input check.
    pub(crate) fn query_aabb_with_unchecked(
        &self,
        aabb: &Aabb,
        mut f: impl FnMut(ProxyKey) -> ControlFlow<()>,
    ) -> ControlFlow<()> {
        let q = SimdBox::new(aabb);
        self.query_tree_with(&q, |i| f(self.keys[i]))?;
        for (b, &key) in self.pending_boxes().iter().zip(self.pending_keys()) {
            if b.overlaps(&q) {
                f(key)?;
            }
        }
        ControlFlow::Continue(())
    }

    /// The index of every tree primitive (tombstones excluded: their box is empty) whose
    /// box overlaps `aabb`.
    pub(super) fn query_tree(&self, aabb: &SimdBox, mut f: impl FnMut(usize)) {
        let _ = self.query_tree_with(aabb, |i| {
            f(i);
            ControlFlow::Continue(())
        });
    }

    /// [`Bvh::query_tree`] until `f` breaks.
    fn query_tree_with(
        &self,
        aabb: &SimdBox,
        mut f: impl FnMut(usize) -> ControlFlow<()>,
    ) -> ControlFlow<()> {
        let q = Splat::of(aabb);
        self.walk(
            |node| node.bounds().overlaps(aabb),
            |range| match self.lanes.leaf(range.start, range.len()) {
                // Four boxes per test, the matches read from the set bits.
                Some(leaf) => {
                    let base = range.start - leaf.off;
                    bits(leaf.mask(&q)).try_for_each(|k| f(base + k))
                }
                None => range
                    .filter(|&i| self.boxes[i].overlaps(aabb))
                    .try_for_each(&mut f),
            },
        )
    }

    /// Depth-first over the tree with the inline stack: enters every node that passes
    /// `enter` (children only through their parent) and calls `visit` with the primitive
    /// range of each leaf entered. The first `Break` of `visit` ends the walk and is returned.
    pub(super) fn walk(
        &self,
        mut enter: impl FnMut(&Node) -> bool,
        mut visit: impl FnMut(core::ops::Range<usize>) -> ControlFlow<()>,
    ) -> ControlFlow<()> {
        let Some(root) = self.nodes.first() else {
            return ControlFlow::Continue(());
        };
        if !enter(root) {
            return ControlFlow::Continue(());
        }
        // Only entered nodes are pushed: children are tested before the push, not after the
        // pop, which saves the stack round trip of those that are not entered.
        let mut stack = SmallStack::<u32, INLINE_STACK>::new(0);
        stack.push(0);
        while let Some(n) = stack.pop() {
            let node = &self.nodes[n as usize];
            if node.is_leaf() {
                visit(node.range())?;
            } else {
                let (a, b) = node.children(n);
                if enter(&self.nodes[b as usize]) {
                    stack.push(b);
                }
                if enter(&self.nodes[a as usize]) {
                    stack.push(a);
                }
            }
        }
        ControlFlow::Continue(())
    }

    /// Calls `f(key, aabb)` for every live box `aabb` within `radius` of `p`
    /// (`point_aabb_distance` `<= radius`, so touching counts), once each, in no
    /// particular order. Nodes are pruned by the same distance, which never decreases as a box
    /// shrinks, so no box within `radius` is missed. Nothing for a non-finite `p` or a NaN or
    /// negative `radius`. The first `Break` of `f` ends it and is returned.
    pub(crate) fn within_distance(
        &self,
        p: Vec3,
        radius: f32,
        mut f: impl FnMut(ProxyKey, &Aabb) -> ControlFlow<()>,
    ) -> ControlFlow<()> {
        if !p.is_finite() || radius.is_nan() || radius < 0.0 {
            return ControlFlow::Continue(());
        }
        let may_be_near = near_filter(p, radius);
        let mut consider = |key: ProxyKey, b: &SimdBox| {
            if key.is_null() || !may_be_near(b) {
                return ControlFlow::Continue(());
            }
            let aabb = b.aabb();
            if point_aabb_distance(p, &aabb) <= radius {
                f(key, &aabb)
            } else {
                ControlFlow::Continue(())
            }
        };
        for (b, &key) in self.pending_boxes().iter().zip(self.pending_keys()) {
            consider(key, b)?;
        }
        self.walk(
            |node| may_be_near(&node.bounds()),
            |mut range| range.try_for_each(|i| consider(self.keys[i], &self.boxes[i])),
        )
    }

    /// Calls `f` with the key of every live box within `radius` of `center`
    /// (`point_aabb_distance` `<= radius`: the box overlaps the closed ball, touching
    /// counts), each once, in no particular order. Nothing for a non-finite `center` or
    /// `radius`, or a negative `radius`.
    pub fn query_sphere(&self, center: Vec3, radius: f32, f: impl FnMut(ProxyKey)) {
        let _ = self.query_sphere_with(center, radius, every(f));
    }

    /// [`Bvh::query_sphere`] with a visitor that can stop: the first [`ControlFlow::Break`]
    /// ends the query and is returned; `Continue` if every match was visited.
    pub fn query_sphere_with(
        &self,
        center: Vec3,
        radius: f32,
        mut f: impl FnMut(ProxyKey) -> ControlFlow<()>,
    ) -> ControlFlow<()> {
        if check_sphere(center, radius).is_err() {
            return ControlFlow::Continue(());
        }
        self.within_distance(center, radius, |key, _| f(key))
    }

    /// The first live box touched by the sphere `center + t·dir`, `radius`, `t ∈ [0, max_t]`,
    /// with its `t` in units of `dir` (0 if it touches at the start), per
    /// `sphere_cast_aabb` (exact: edges and corners are rounded); ties go to the smaller
    /// key. `None` if nothing is touched, or for a non-finite argument, a negative `radius` or
    /// a negative `max_t`.
    ///
    /// Candidates are the boxes grown by `radius` plus a relative pad (the exact test works in
    /// `f64`, the slab tests in `f32`), nearer first.
    #[must_use]
    pub fn cast_sphere(
        &self,
        center: Vec3,
        radius: f32,
        dir: Vec3,
        max_t: f32,
    ) -> Option<(ProxyKey, f32)> {
        let (mut hit, inflate) = FirstHit::sphere_cast(center, radius, dir, max_t)?;
        // Each candidate is tested up to `max_t`, not the best `t` so far: the exact test
        // compares its `f64` time with the limit before rounding it, so a tie at the best `t`
        // (rounded to `f32`) could be refused, and a smaller key lost.
        self.ray_candidates(center, dir, max_t, inflate, |key, aabb| {
            hit.offer(
                key,
                geom::sphere_cast_aabb(center, radius, dir, max_t, aabb),
            )
        });
        hit.best()
    }

    /// The `k` live boxes nearest `point` by `point_aabb_distance` (0 inside a box),
    /// with their distances, sorted by `(distance, key)`: the first `k` of all boxes in that
    /// order (all of them if there are fewer). Empty for `k == 0` or a non-finite `point`.
    ///
    /// An expanding search: starting from the distance to the boxes' bounds plus a part of the
    /// spacing `k` boxes spread evenly over those bounds would have, each round collects the boxes
    /// within the radius and doubles it until `k` are within it or every box was; a box not
    /// collected is farther than the radius, so the first `k` collected in `(distance, key)`
    /// order are the answer.
    #[must_use]
    pub fn nearest(&self, point: Vec3, k: usize) -> Vec<(ProxyKey, f32)> {
        let n = self.len();
        if k == 0 || n == 0 || !point.is_finite() {
            return Vec::new();
        }
        let start = nearest_start(point, &self.bounds(), k, n);
        let mut out = Vec::new();
        nearest_expanding(k, n, start, &mut out, |radius, out| {
            let _ = self.within_distance(point, radius, |key, aabb| {
                out.push((key, point_aabb_distance(point, aabb)));
                ControlFlow::Continue(())
            });
            out.len()
        });
        out
    }

    /// A box holding every live box (the root's and the pending boxes' union; it may hold
    /// removed ones too), or [`Aabb::EMPTY`] for a tree with none: where a nearest search
    /// starts.
    pub(crate) fn bounds(&self) -> Aabb {
        self.pending_boxes().iter().fold(
            self.nodes.first().map_or(Aabb::EMPTY, |r| r.aabb()),
            |u, b| u.union(&b.aabb()),
        )
    }

    pub(super) fn pending_boxes(&self) -> &[SimdBox] {
        &self.boxes[self.tree_len..]
    }

    pub(super) fn pending_keys(&self) -> &[ProxyKey] {
        &self.keys[self.tree_len..]
    }
}

#[cfg(test)]
mod tests {
    use super::super::ray::{RAY_STACK, RayStack};
    use super::*;
    use crate::bvh::BvhConfig;
    use crate::geom::inverse_dir;
    use crate::rng::Rng;
    use crate::test_geom::segment_in_box;
    use std::collections::BTreeMap;

    /// The distance from `p` to the box `lo..=hi`, in `f64`: `p` minus its clamp to the box.
    fn box_distance(p: Vec3, b: &Aabb) -> f64 {
        (0..3)
            .map(|a| {
                let x = f64::from(p[a]);
                let q = x.clamp(f64::from(b.min[a]), f64::from(b.max[a]));
                (x - q) * (x - q)
            })
            .sum::<f64>()
            .sqrt()
    }

    fn random_box(rng: &mut Rng) -> Aabb {
        let c = rng.vec3_in(Vec3::splat(-25.0), Vec3::splat(25.0));
        let half = match rng.below(8) {
            0 => Vec3::ZERO,
            1 => Vec3::new(rng.range(0.0, 10.0), 0.1, rng.range(0.0, 10.0)),
            _ => rng.vec3_in(Vec3::splat(0.05), Vec3::splat(2.0)),
        };
        Aabb::new(c - half, c + half)
    }

    /// A tree with a built part, pending inserts, tombstones and boxes updated since the last
    /// refit, with its own list of `(key, box)`.
    fn world(seed: u64) -> (Bvh, Vec<(ProxyKey, Aabb)>) {
        let mut rng = Rng::new(seed);
        let boxes: Vec<Aabb> = (0..300).map(|_| random_box(&mut rng)).collect();
        let config = BvhConfig {
            max_leaf_size: 4,
            ..BvhConfig::default()
        };
        let (mut bvh, keys) = Bvh::from_aabbs(config, &boxes).unwrap();
        let mut shapes: Vec<(ProxyKey, Aabb)> = keys.into_iter().zip(boxes).collect();
        for _ in 0..40 {
            let b = random_box(&mut rng);
            shapes.push((bvh.insert(b).unwrap(), b));
        }
        for _ in 0..30 {
            let i = rng.below(shapes.len() as u32) as usize;
            bvh.remove(shapes.swap_remove(i).0).unwrap();
        }
        for _ in 0..30 {
            let i = rng.below(shapes.len() as u32) as usize;
            let b = random_box(&mut rng);
            bvh.update(shapes[i].0, b).unwrap();
            shapes[i].1 = b;
        }
        (bvh, shapes)
    }

    #[test]
    fn ray_candidates_visit_every_hit_box_exactly_once() {
        let (bvh, shapes) = world(1);
        let mut rng = Rng::new(101);
        for q in 0..300 {
            let o = rng.vec3_in(Vec3::splat(-30.0), Vec3::splat(30.0));
            let d = match q % 7 {
                0 => Vec3::ZERO,
                1 => Vec3::Y * rng.range(-2.0, 2.0),
                _ => rng.vec3_in(Vec3::splat(-2.0), Vec3::splat(2.0)),
            };
            let max_t = rng.range(0.0, 40.0);
            let inflate = if q % 3 == 0 { 0.0 } else { rng.range(0.0, 3.0) };
            let mut seen = BTreeMap::new();
            bvh.ray_candidates(o, d, max_t, inflate, |key, aabb| {
                assert_eq!(Some(*aabb), bvh.aabb(key));
                *seen.entry(key).or_insert(0) += 1;
                max_t
            });
            assert!(seen.values().all(|&n| n == 1), "a box visited twice");
            let inv = inverse_dir(d);
            for &(key, b) in &shapes {
                let hit = b.grown(inflate).ray_entry(o, inv, max_t).is_some();
                assert_eq!(seen.contains_key(&key), hit, "query {q} key {key:?}");
                let m = Vec3::splat(inflate);
                let inside = segment_in_box(o, d, max_t, b.min - m, b.max + m);
                if inside.is_some_and(|(t0, t1)| t1 - t0 > 1e-3) {
                    assert!(hit, "query {q}: a box the segment crosses was skipped");
                }
                let near = segment_in_box(o, d, max_t, b.min - m - 1e-3, b.max + m + 1e-3);
                if near.is_none() {
                    assert!(!hit, "query {q}: a box the segment misses was visited");
                }
            }
        }
    }

    #[test]
    fn ray_candidates_shrink_to_the_returned_value_and_keep_ties() {
        let (mut bvh, mut shapes) = world(2);
        let twin = Aabb::new(Vec3::new(5.0, 0.5, -2.5), Vec3::new(6.0, 1.5, -1.5));
        for _ in 0..2 {
            shapes.push((bvh.insert(twin).unwrap(), twin));
        }
        bvh.rebuild();
        let mut rng = Rng::new(202);
        for q in 0..300 {
            let (o, d) = if q == 0 {
                (Vec3::new(-30.0, 1.0, -2.0), Vec3::X)
            } else {
                (
                    rng.vec3_in(Vec3::splat(-30.0), Vec3::splat(30.0)),
                    rng.vec3_in(Vec3::splat(-1.0), Vec3::splat(1.0)),
                )
            };
            let (max_t, inflate) = (60.0, 0.25);
            let inv = inverse_dir(d);
            let entry = |b: &Aabb| b.grown(inflate).ray_entry(o, inv, max_t);
            let mut seen = Vec::new();
            let mut last = f32::INFINITY;
            bvh.ray_candidates(o, d, max_t, inflate, |key, aabb| {
                seen.push(key);
                let t = entry(aabb).unwrap_or(f32::NAN);
                // No box entered behind the best so far is visited.
                assert!(
                    t <= last,
                    "query {q}: visited a box entered behind the best"
                );
                last = last.min(t);
                t
            });
            let best = shapes.iter().filter_map(|s| entry(&s.1)).reduce(f32::min);
            let Some(best) = best else {
                assert!(seen.is_empty());
                continue;
            };
            for (key, b) in &shapes {
                if entry(b) == Some(best) {
                    assert!(
                        seen.contains(key),
                        "query {q}: a tie at the best t was skipped"
                    );
                }
            }
            if q == 0 {
                assert!(shapes.iter().filter(|s| entry(&s.1) == Some(best)).count() >= 2);
            }
        }
    }

    #[test]
    fn within_distance_visits_every_near_box_exactly_once() {
        let (bvh, shapes) = world(3);
        let mut rng = Rng::new(303);
        for q in 0..300 {
            let p = rng.vec3_in(Vec3::splat(-30.0), Vec3::splat(30.0));
            let radius = match q % 5 {
                0 => 0.0,
                1 => rng.range(10.0, 40.0),
                _ => rng.range(0.0, 5.0),
            };
            let mut seen = BTreeMap::new();
            let _ = bvh.within_distance(p, radius, |key, aabb| {
                assert_eq!(Some(*aabb), bvh.aabb(key));
                *seen.entry(key).or_insert(0) += 1;
                ControlFlow::Continue(())
            });
            assert!(seen.values().all(|&n| n == 1), "a box visited twice");
            for (key, b) in &shapes {
                let near = point_aabb_distance(p, b) <= radius;
                assert_eq!(seen.contains_key(key), near, "query {q} key {key:?}");
                let (d, r) = (box_distance(p, b), f64::from(radius));
                if near {
                    assert!(d <= r + 1e-4, "query {q}: a box at {d} > {r} visited");
                } else {
                    assert!(d >= r - 1e-4, "query {q}: a box at {d} <= {r} skipped");
                }
            }
        }
    }

    #[test]
    fn candidate_traversals_refuse_bad_arguments() {
        let (bvh, _) = world(4);
        let mut n = 0;
        let nan = f32::NAN;
        for (o, d, max_t, inflate) in [
            (Vec3::new(nan, 0.0, 0.0), Vec3::X, 10.0, 0.0),
            (Vec3::ZERO, Vec3::new(0.0, f32::INFINITY, 0.0), 10.0, 0.0),
            (Vec3::ZERO, Vec3::X, nan, 0.0),
            (Vec3::ZERO, Vec3::X, -1.0, 0.0),
            (Vec3::ZERO, Vec3::X, 10.0, -1.0),
            (Vec3::ZERO, Vec3::X, 10.0, nan),
        ] {
            bvh.ray_candidates(o, d, max_t, inflate, |_, _| {
                n += 1;
                0.0
            });
        }
        for (p, radius) in [
            (Vec3::new(nan, 0.0, 0.0), 100.0),
            (Vec3::splat(f32::INFINITY), 100.0),
            (Vec3::ZERO, -1.0),
            (Vec3::ZERO, nan),
        ] {
            let _ = bvh.within_distance(p, radius, |_, _| {
                n += 1;
                ControlFlow::Continue(())
            });
        }
        assert_eq!(n, 0);
    }

    /// A box of the integer lattice in `[-6, 6]³` (faces shared between neighbours, rays
    /// along them graze), or a random one.
    fn lattice_or_random_box(rng: &mut Rng) -> Aabb {
        if rng.below(2) == 0 {
            let lo = Vec3::new(
                rng.below(12) as f32 - 6.0,
                rng.below(12) as f32 - 6.0,
                rng.below(12) as f32 - 6.0,
            );
            let size = Vec3::new(
                1.0 + rng.below(2) as f32,
                1.0 + rng.below(2) as f32,
                rng.below(3) as f32,
            );
            Aabb::new(lo, lo + size)
        } else {
            let c = rng.vec3_in(Vec3::splat(-6.0), Vec3::splat(6.0));
            let half = rng.vec3_in(Vec3::splat(0.05), Vec3::splat(1.5));
            Aabb::new(c - half, c + half)
        }
    }

    /// Two trees over one key space and the test's own record of every live box: `shape` 0
    /// fills both (built parts several leaves deep, pending inserts, removed and updated
    /// boxes, and twins: one box under a key in each tree), 1 leaves the second empty, 2
    /// gives the second only pending boxes, 3 leaves both empty.
    fn two_trees(seed: u64, shape: u32) -> ([Bvh; 2], BTreeMap<ProxyKey, Aabb>) {
        let mut rng = Rng::new(seed);
        let config = BvhConfig {
            max_leaf_size: 6,
            ..BvhConfig::default()
        };
        let mut trees = [Bvh::new(config).unwrap(), Bvh::new(config).unwrap()];
        let mut keys = slotmap::SlotMap::<ProxyKey, ()>::with_key();
        let mut model = BTreeMap::new();
        let mut owner = BTreeMap::new();
        let wanted = |t: usize| match shape {
            0 => true,
            1 | 2 => t == 0,
            _ => false,
        };
        let mut add = |trees: &mut [Bvh; 2], t: usize, b: Aabb, rng: &mut Rng| {
            let mut put = |t: usize| {
                let k = keys.insert(());
                trees[t].insert_keyed(k, b).unwrap();
                model.insert(k, b);
                owner.insert(k, t);
            };
            put(t);
            if rng.below(4) == 0 && wanted(1 - t) {
                put(1 - t);
            }
        };
        for _ in 0..200 {
            let t = rng.below(2) as usize;
            if wanted(t) {
                let b = lattice_or_random_box(&mut rng);
                add(&mut trees, t, b, &mut rng);
            }
        }
        for tree in &mut trees {
            tree.rebuild();
        }
        for _ in 0..30 {
            let t = rng.below(2) as usize;
            if wanted(t) || (shape == 2 && t == 1) {
                let b = lattice_or_random_box(&mut rng);
                add(&mut trees, t, b, &mut rng);
            }
        }
        let live: Vec<ProxyKey> = model.keys().copied().collect();
        for (j, &k) in live.iter().enumerate() {
            let t = owner[&k];
            if j % 9 == 0 {
                trees[t].remove(k).unwrap();
                model.remove(&k);
            } else if j % 7 == 0 {
                let b = lattice_or_random_box(&mut rng);
                trees[t].update(k, b).unwrap();
                model.insert(k, b);
            }
        }
        for tree in &trees {
            tree.validate();
        }
        (trees, model)
    }

    /// A segment that grazes lattice faces and edges (lattice origin, axis or lattice-diagonal
    /// direction), starts inside a box (its centre or a corner), has zero length (zero
    /// direction or `max_t`), starts outside everything (towards the boxes or away), or is
    /// random.
    fn hard_segment(rng: &mut Rng, q: u32, boxes: &[Aabb]) -> (Vec3, Vec3, f32) {
        let axis = [Vec3::X, Vec3::Y, Vec3::Z, Vec3::new(1.0, 1.0, 0.0)][rng.below(4) as usize];
        let sign = if rng.below(2) == 0 { 1.0 } else { -1.0 };
        let random_dir = |rng: &mut Rng| rng.vec3_in(Vec3::splat(-1.0), Vec3::splat(1.0));
        let max_t = match rng.below(4) {
            0 => f32::INFINITY,
            1 => rng.range(0.0, 6.0),
            _ => 30.0,
        };
        let lattice = |rng: &mut Rng| {
            Vec3::new(
                rng.below(14) as f32 - 7.0,
                rng.below(14) as f32 - 7.0,
                rng.below(14) as f32 - 7.0,
            )
        };
        match q % 5 {
            0 => (lattice(rng), axis * sign, max_t),
            1 if !boxes.is_empty() => {
                let b = boxes[rng.below(boxes.len() as u32) as usize];
                let o = if rng.below(2) == 0 { b.center() } else { b.min };
                (o, random_dir(rng), max_t)
            }
            2 => {
                let o = rng.vec3_in(Vec3::splat(-8.0), Vec3::splat(8.0));
                if rng.below(2) == 0 {
                    (o, Vec3::ZERO, max_t)
                } else {
                    (o, random_dir(rng), 0.0)
                }
            }
            3 => {
                let o = random_dir(rng).normalize_or(Vec3::X) * 40.0;
                let d = if rng.below(3) == 0 { o } else { -o };
                (o, d * 0.05, max_t)
            }
            _ => (
                rng.vec3_in(Vec3::splat(-8.0), Vec3::splat(8.0)),
                random_dir(rng),
                max_t,
            ),
        }
    }

    /// The walk over two trees (and over each alone) finds brute force's first hit, the
    /// same key and `t` (ties to the smaller key), for rays and grown boxes alike, visits
    /// each box at most once and only boxes the segment enters, whatever the trees hold.
    #[test]
    fn two_tree_walk_finds_brute_forces_first_hit() {
        for shape in 0..4 {
            let ([a, b], model) = two_trees(40 + u64::from(shape), shape);
            let boxes: Vec<Aabb> = model.values().copied().collect();
            let mut rng = Rng::new(404 + u64::from(shape));
            let mut hits = 0;
            for q in 0..600 {
                let (o, d, max_t) = hard_segment(&mut rng, q, &boxes);
                let inflate = if q % 3 == 0 { rng.range(0.0, 0.6) } else { 0.0 };
                let inv = inverse_dir(d);
                let entry = |b: &Aabb| b.grown(inflate).ray_entry(o, inv, max_t);
                let first = |keys: &mut dyn Iterator<Item = ProxyKey>| {
                    keys.filter_map(|k| Some((entry(&model[&k])?, k)))
                        .min_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)))
                };
                let walk = |trees: &[&Bvh]| {
                    let mut seen = BTreeMap::new();
                    let mut best: Option<(f32, ProxyKey)> = None;
                    let mut visit = |k: ProxyKey, aabb: &Aabb| {
                        assert_eq!(model.get(&k), Some(aabb), "query {q}: a stale box");
                        assert!(seen.insert(k, ()).is_none(), "query {q}: visited twice");
                        let t = entry(aabb);
                        assert!(t.is_some(), "query {q}: visited a box it misses");
                        let t = t.unwrap_or(f32::NAN);
                        if best.is_none_or(|(bt, bk)| (t, k) < (bt, bk)) {
                            best = Some((t, k));
                        }
                        t
                    };
                    match trees {
                        [one] => one.ray_candidates(o, d, max_t, inflate, &mut visit),
                        [x, y] => Bvh::ray_candidates_both(x, y, o, d, max_t, inflate, &mut visit),
                        _ => unreachable!(),
                    }
                    best
                };
                let want = first(&mut model.keys().copied());
                hits += usize::from(want.is_some());
                let ctx = format!("shape {shape} query {q}: {o} {d} {max_t} {inflate}");
                assert_eq!(walk(&[&a, &b]), want, "{ctx}");
                assert_eq!(walk(&[&b, &a]), want, "{ctx}, trees swapped");
                let only_a = first(&mut model.keys().copied().filter(|&k| a.contains(k)));
                assert_eq!(walk(&[&a]), only_a, "{ctx}, first tree alone");
            }
            // The worlds that have boxes are hit by most segments.
            assert_eq!(hits > 200, shape != 3, "shape {shape}: {hits} hits");
        }
    }

    /// The ray stack is LIFO across its spill to the heap, and `pop_before` skips (and
    /// drops) the entries behind `best`, ties kept.
    #[test]
    fn ray_stack_spills_in_order_and_skips_what_lies_behind() {
        let mut stack = RayStack::new();
        let n = RAY_STACK as u32 + 40;
        for i in 0..n {
            stack.push((i, (i % 10) as f32));
        }
        let mut popped = Vec::new();
        while let Some((i, t)) = stack.pop_before(4.0) {
            assert!(t <= 4.0);
            popped.push(i);
        }
        let want: Vec<u32> = (0..n).rev().filter(|i| i % 10 <= 4).collect();
        assert_eq!(popped, want);
        stack.push((7, 1.0));
        assert_eq!(stack.pop_before(1.0), Some((7, 1.0)));
        assert_eq!(stack.pop_before(f32::INFINITY), None);
    }

    /// A tree deeper than the inline stack (middle splits of exponentially spaced boxes peel
    /// one box per level): segments along the line from its small end push one farther child
    /// per level, so the walk spills, and still find brute force's first hit.
    #[test]
    fn deep_tree_rays_spill_and_equal_brute_force() {
        let boxes: Vec<Aabb> = (0..120)
            .map(|i| {
                let x = 2f32.powi(i - 20);
                Aabb::new(Vec3::new(x, 0.0, 0.0), Vec3::new(x * 1.5, 1.0, 1.0))
            })
            .collect();
        let config = BvhConfig {
            split: crate::bvh::SplitMethod::Middle,
            max_leaf_size: 1,
            ..BvhConfig::default()
        };
        let (bvh, keys) = Bvh::from_aabbs(config, &boxes).unwrap();
        assert!(bvh.stats().depth > RAY_STACK, "{}", bvh.stats().depth);
        let mut rng = Rng::new(9);
        for q in 0..200 {
            let along = if q % 2 == 0 { Vec3::X } else { -Vec3::X };
            let o = match q % 4 {
                0 => Vec3::new(-1.0, 0.5, 0.5),
                1 => Vec3::new(2f32.powi(101), 0.5, 0.5),
                _ => Vec3::new(2f32.powi(rng.below(100) as i32 - 20), 0.5, 0.5),
            };
            // Exactly along the line (the test for zero direction components), or off it
            // by too little to leave the boxes before the last (no zero component), or by
            // enough to leave them early.
            let off = [0.0, 1e-38, 1e-3][rng.below(3) as usize];
            let d = along + Vec3::new(0.0, rng.range(-off, off), rng.range(-off, off));
            let inv = inverse_dir(d);
            let want = keys
                .iter()
                .zip(&boxes)
                .filter_map(|(&k, b)| Some((k, b.ray_entry(o, inv, f32::INFINITY)?)))
                .min_by(|x, y| x.1.total_cmp(&y.1).then(x.0.cmp(&y.0)));
            assert_eq!(
                bvh.cast_ray(o, d, f32::INFINITY),
                want,
                "query {q}: {o} {d}"
            );
        }
    }
}
