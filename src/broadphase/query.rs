//! Box queries and ray casts of a [`BroadPhase`]: the structures find the proxies whose held
//! boxes (exact, or fat around the exact ones) the query meets, and each is re-tested against
//! its exact shape.

use super::{BroadPhase, Shape};
use crate::geom::{self, SimdBox, check_aabb};
use crate::{Aabb, ProxyKey, Vec3};

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
        let mut best: Option<(ProxyKey, f32)> = None;
        let mut test = |key: ProxyKey, _: f32| {
            let t = match self.store.shape[crate::pair::slot(key) as usize] {
                Shape::Sphere { center, radius } => {
                    geom::ray_sphere(origin, dir, center, radius, max_t)
                }
                Shape::Body { aabb, .. } => aabb.ray_entry(origin, inv, max_t),
            };
            if let Some(t) = t
                && best.is_none_or(|(k, b)| (t, key) < (b, k))
            {
                best = Some((key, t));
            }
        };
        self.octree.cast_ray_all_with(
            origin,
            dir,
            max_t,
            |c, r| Aabb::from_center_radius(c, r).ray_entry(origin, inv, max_t),
            &mut test,
        );
        self.dynamic.cast_ray_all(origin, dir, max_t, &mut test);
        self.statics.cast_ray_all(origin, dir, max_t, &mut test);
        best
    }
}
