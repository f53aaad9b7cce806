//! Box queries and ray casts of a [`BroadPhase`]: the grid's clean entries by column, the
//! dirty ones (moved since the last build) one by one, each hit re-tested against the exact
//! shape.

use super::grid::STATIC_BIT;
use super::store::flag;
use super::{BroadPhase, Shape};
use crate::geom::{self, SimdBox, check_aabb};
use crate::{Aabb, ProxyKey, Vec3};
use glam::Vec3A;

impl BroadPhase {
    /// Calls `f` with every proxy whose (margin-grown) box overlaps `aabb`, each once, in no
    /// particular order; nothing for a non-finite or inverted query box.
    pub fn query_aabb(&self, aabb: &Aabb, mut f: impl FnMut(ProxyKey)) {
        if check_aabb(aabb).is_err() {
            return;
        }
        let q = SimdBox::new(aabb);
        let (flags, exact) = (&self.store.flags, &self.store.exact);
        self.grid.query(&q, |w| {
            let s = (w & !STATIC_BIT) as usize;
            if flags[s] & (flag::DIRTY | flag::GONE) == 0 && exact[s].overlaps(&q) {
                f(self.store.key(s as u32));
            }
        });
        for &s in &self.dirty {
            let s = s as usize;
            if flags[s] & flag::GONE == 0 && exact[s].overlaps(&q) {
                f(self.store.key(s as u32));
            }
        }
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
        let test = |s: usize, best: &mut Option<(ProxyKey, f32)>| {
            let t = match self.store.shape[s] {
                Shape::Sphere { center, radius } => {
                    geom::ray_sphere(origin, dir, center, radius, max_t)
                }
                Shape::Body { aabb, .. } => aabb.ray_entry(origin, inv, max_t),
            };
            if let Some(t) = t {
                let key = self.store.key(s as u32);
                if best.is_none_or(|(k, b)| (t, key) < (b, k)) {
                    *best = Some((key, t));
                }
            }
        };
        let flags = &self.store.flags;
        for &s in &self.dirty {
            if flags[s as usize] & flag::GONE == 0 {
                test(s as usize, &mut best);
            }
        }
        let (o, d) = (Vec3A::from(origin), Vec3A::from(dir));
        self.grid.ray_candidates(o, d, max_t, |w| {
            let s = (w & !STATIC_BIT) as usize;
            if flags[s] & (flag::DIRTY | flag::GONE) == 0 {
                test(s, &mut best);
            }
            best.map_or(max_t, |b| b.1)
        });
        best
    }
}
