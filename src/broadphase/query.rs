//! Box queries and ray casts of a [`BroadPhase`]: the structures find the proxies whose held
//! boxes (exact, or fat around the exact ones) the query meets, and each is re-tested against
//! its exact shape.

use super::{BroadPhase, Shape};
use crate::geom::{self, SimdBox, check_aabb};
use crate::search::{FirstHit, nearest_expanding};
use crate::{Aabb, ProxyKey, Vec3};

/// `nearest`'s first radius beyond the bounds, as a fraction of the spacing `k` proxies spread
/// evenly over the bounds would have: below 1, a first round usually finds `k` in a small
/// region; a miss only doubles the radius.
const NEAREST_START: f32 = 0.5;

impl BroadPhase {
    /// Calls `f` with every proxy whose (margin-grown) box overlaps `aabb`, each once, in no
    /// particular order; nothing for a non-finite or inverted query box.
    pub fn query_aabb(&self, aabb: &Aabb, mut f: impl FnMut(ProxyKey)) {
        if check_aabb(aabb).is_err() {
            return;
        }
        let q = SimdBox::new(aabb);
        let exact = &self.store.exact;
        let mut test = |k: ProxyKey| {
            if exact[crate::pair::slot(k) as usize].overlaps(&q) {
                f(k);
            }
        };
        self.octree.query_aabb_unchecked(aabb, &mut test);
        self.dynamic.query_aabb_unchecked(aabb, &mut test);
        self.statics.query_aabb_unchecked(aabb, &mut test);
    }

    /// The nearest proxy hit by the segment `origin + t·dir`, `t ∈ [0, max_t]`, with its `t`
    /// (in units of `dir`, which need not be unit length). Spheres are hit as spheres, bodies
    /// as their boxes, both as the user gave them (without the margin); ties go to the smaller
    /// key. `None` for a non-finite ray or `max_t < 0`.
    #[must_use]
    pub fn cast_ray(&self, origin: Vec3, dir: Vec3, max_t: f32) -> Option<(ProxyKey, f32)> {
        if !geom::ray_is_valid(origin, dir, max_t) {
            return None;
        }
        let inv = geom::inverse_dir(dir);
        self.first_hit(origin, dir, max_t, 0.0, |shape, limit| match shape {
            Shape::Sphere { center, radius } => {
                geom::ray_sphere(origin, dir, center, radius, limit)
            }
            Shape::Body { aabb, .. } => aabb.ray_entry(origin, inv, limit),
        })
    }

    /// The first proxy touched by the sphere `center + t·dir` of radius `radius`, for `t` in
    /// `[0, max_t]`, with its `t` in units of `dir` (0 if it touches at the start; touching
    /// counts). Shapes as the user gave them: spheres as spheres ([`geom::sphere_cast_sphere`]),
    /// bodies as their boxes ([`geom::sphere_cast_aabb`]); ties go to the smaller key. `None`
    /// for a non-finite argument, a negative radius or a negative `max_t`.
    #[must_use]
    pub fn cast_sphere(
        &self,
        center: Vec3,
        radius: f32,
        dir: Vec3,
        max_t: f32,
    ) -> Option<(ProxyKey, f32)> {
        if !geom::cast_is_valid(center, radius, dir, max_t) {
            return None;
        }
        let inflate = radius + geom::cast_pad(center, radius, dir, max_t);
        self.first_hit(center, dir, max_t, inflate, |shape, limit| match shape {
            Shape::Sphere {
                center: c,
                radius: r,
            } => geom::sphere_cast_sphere(center, radius, dir, limit, c, r),
            Shape::Body { aabb, .. } => geom::sphere_cast_aabb(center, radius, dir, limit, &aabb),
        })
    }

    /// The smallest `(t, key)` of `hit(shape, limit)` over the proxies whose held boxes, grown
    /// by `inflate`, the segment `origin + t·dir` meets before the best `t` so far: each
    /// structure is walked nearer subtrees first and prunes what lies behind that `t`.
    fn first_hit(
        &self,
        origin: Vec3,
        dir: Vec3,
        max_t: f32,
        inflate: f32,
        hit_of: impl Fn(Shape, f32) -> Option<f32>,
    ) -> Option<(ProxyKey, f32)> {
        let mut hit = FirstHit::new(max_t);
        let t_of = |key: ProxyKey, limit: f32| {
            hit_of(self.store.shape[crate::pair::slot(key) as usize], limit)
        };
        let limit = hit.limit();
        self.octree
            .ray_candidates(origin, dir, limit, inflate, |k, _| {
                hit.offer(k, t_of(k, hit.limit()))
            });
        let limit = hit.limit();
        self.dynamic
            .ray_candidates(origin, dir, limit, inflate, |k, _| {
                hit.offer(k, t_of(k, hit.limit()))
            });
        let limit = hit.limit();
        self.statics
            .ray_candidates(origin, dir, limit, inflate, |k, _| {
                hit.offer(k, t_of(k, hit.limit()))
            });
        hit.best()
    }

    /// Calls `f` with every proxy whose shape, as the user gave it, is within `radius` of
    /// `center` (touching counts): a sphere whose centre is within `radius + its radius`, a
    /// body whose box is within `radius`. Each once, in no particular order; nothing for a
    /// non-finite argument or a negative radius.
    pub fn query_sphere(&self, center: Vec3, radius: f32, mut f: impl FnMut(ProxyKey)) {
        if geom::check_sphere(center, radius).is_err() {
            return;
        }
        let reach = radius + geom::distance_pad(center, radius);
        self.within(center, reach, |key, shape| {
            let inside = match shape {
                Shape::Sphere {
                    center: c,
                    radius: r,
                } => (c - center).length_squared() <= (r + radius) * (r + radius),
                Shape::Body { aabb, .. } => geom::point_aabb_distance(center, &aabb) <= radius,
            };
            if inside {
                f(key);
            }
        });
    }

    /// The `k` proxies whose shapes, as the user gave them, are nearest `point` (distance 0
    /// inside: [`geom::point_sphere_distance`], [`geom::point_aabb_distance`]), with their
    /// distances, sorted by `(distance, key)`; all of them if there are fewer. Empty for
    /// `k == 0` or a non-finite `point`.
    ///
    /// An expanding search: from the distance to the octree's region plus the spacing `k`
    /// proxies spread evenly over it would have, each round takes every proxy whose held box
    /// is within the radius and doubles the radius until `k` of them are within it by their
    /// exact distance (or every proxy was seen). A proxy not seen is farther than the radius.
    #[must_use]
    pub fn nearest(&self, point: Vec3, k: usize) -> Vec<(ProxyKey, f32)> {
        let n = self.len();
        if k == 0 || n == 0 || !point.is_finite() {
            return Vec::new();
        }
        let bounds = self.octree.bounds();
        let spacing =
            NEAREST_START * bounds.extent().max_element() * (k as f32 / n as f32).min(1.0).cbrt();
        let start = geom::point_aabb_distance(point, &bounds) + spacing;
        nearest_expanding(k, n, start, |radius, out| {
            let reach = radius + geom::distance_pad(point, radius);
            self.within(point, reach, |key, shape| {
                let d = match shape {
                    Shape::Sphere { center, radius } => {
                        geom::point_sphere_distance(point, center, radius)
                    }
                    Shape::Body { aabb, .. } => geom::point_aabb_distance(point, &aabb),
                };
                out.push((key, d));
            });
        })
    }

    /// Calls `f(key, shape)` for every proxy whose held box is within `radius` of `p` (spheres:
    /// whose held box meets the cube `p ± radius`): a superset of the proxies whose shapes
    /// are, since a shape lies in its held box.
    fn within(&self, p: Vec3, radius: f32, mut f: impl FnMut(ProxyKey, Shape)) {
        let shape = |k: ProxyKey| self.store.shape[crate::pair::slot(k) as usize];
        self.octree.near(p, radius, |k| f(k, shape(k)));
        self.dynamic
            .within_distance(p, radius, |k, _| f(k, shape(k)));
        self.statics
            .within_distance(p, radius, |k, _| f(k, shape(k)));
    }
}
