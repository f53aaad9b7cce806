//! Box, sphere, ray, sphere-cast and nearest queries of a [`BroadPhase`], and the
//! [`QueryFilter`] an engine's queries pass: the structures find the proxies whose held boxes
//! (exact, or fat around the exact ones) the query meets, each is re-tested against its exact
//! shape, and only then offered to the filter. Slots updated since the last step are held by
//! the structures at their last applied boxes: the queries skip them there and test their
//! latest shapes in a scan of the stale slots (see [`super::apply`]), so a query sees every
//! update at once and costs `O(stale)` more until the next step.
//!
//! Each query comes twice: the plain form (`query_aabb`, `cast_ray`, `nearest`, …) sees every
//! proxy and visits every match; the `_with` form (`query_aabb_with`, `cast_ray_with`,
//! `nearest_into`, …) takes a [`QueryFilter`], and its visitor returns a [`ControlFlow`] whose
//! `Break` ends the query at once.

use super::{BroadPhase, CollisionGroups, Shape};
use crate::bvh::Bvh;
use crate::geom::{self, SimdBox, check_aabb};
use crate::search::{FirstHit, every, nearest_expanding, nearest_start};
use crate::{Aabb, ProxyKey, Vec3};
use core::ops::ControlFlow;

/// The predicate of a [`QueryFilter`]: true to let the proxy `key` of this shape through.
pub type QueryPredicate<'a> = &'a dyn Fn(ProxyKey, &Shape) -> bool;

/// Which proxies a query may report, like rapier's `QueryFilter`: a proxy passes if it is not
/// `exclude`, its groups and `groups` allow each other ([`CollisionGroups::allows`]), and
/// `predicate` accepts it. The default passes every proxy.
///
/// ```
/// use broadleaf::{BroadPhase, CollisionGroups, Config, QueryFilter, Vec3};
///
/// let mut bp = BroadPhase::new(Config::default());
/// let player = bp.insert_sphere(Vec3::ZERO, 0.5)?;
/// let wall = bp.insert_sphere(Vec3::new(5.0, 0.0, 0.0), 1.0)?;
/// let ghost = bp.insert_sphere(Vec3::new(2.0, 0.0, 0.0), 0.5)?;
/// bp.set_groups(ghost, CollisionGroups { memberships: 0b10, filter: u32::MAX })?;
///
/// // A ray from the player skips the player itself and what is not in group 1.
/// let solid = CollisionGroups { memberships: u32::MAX, filter: 0b01 };
/// let filter = QueryFilter::new().exclude(player).groups(solid);
/// let hit = bp.cast_ray_with(Vec3::ZERO, Vec3::X, 100.0, &filter);
/// assert_eq!(hit, Some((wall, 4.0)));
///
/// // A predicate sees the key and the shape: skip the small ones.
/// let big = |_, shape: &broadleaf::Shape| shape.aabb().extent().x > 1.5;
/// let filter = QueryFilter::new().predicate(&big);
/// let hit = bp.cast_ray_with(Vec3::new(-3.0, 0.0, 0.0), Vec3::X, 100.0, &filter);
/// assert_eq!(hit, Some((wall, 7.0)));
/// # Ok::<(), broadleaf::Error>(())
/// ```
#[derive(Clone, Copy, Default)]
pub struct QueryFilter<'a> {
    /// Only proxies whose groups and these allow each other; `None`: any groups.
    pub groups: Option<CollisionGroups>,
    /// This proxy is never reported (a ray from a player skips the player).
    pub exclude: Option<ProxyKey>,
    /// Only proxies for which this returns true. It is called only for proxies that pass the
    /// query's exact geometric test and the other two rules; a `nearest` search may call it
    /// again for the same proxy as its radius grows.
    pub predicate: Option<QueryPredicate<'a>>,
}

impl<'a> QueryFilter<'a> {
    /// The filter that passes every proxy.
    #[must_use]
    pub fn new() -> Self {
        Self::default()
    }

    /// Only proxies whose groups and `groups` allow each other.
    #[must_use]
    pub fn groups(mut self, groups: CollisionGroups) -> Self {
        self.groups = Some(groups);
        self
    }

    /// Never reports `key`.
    #[must_use]
    pub fn exclude(mut self, key: ProxyKey) -> Self {
        self.exclude = Some(key);
        self
    }

    /// Only proxies for which `predicate(key, shape)` is true.
    #[must_use]
    pub fn predicate(mut self, predicate: QueryPredicate<'a>) -> Self {
        self.predicate = Some(predicate);
        self
    }
}

impl core::fmt::Debug for QueryFilter<'_> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("QueryFilter")
            .field("groups", &self.groups)
            .field("exclude", &self.exclude)
            .field(
                "predicate",
                &self.predicate.map(|_| "Fn(ProxyKey, &Shape) -> bool"),
            )
            .finish()
    }
}

impl BroadPhase {
    /// True if `filter` passes the live proxy `key` in `slot`: the cheap rules first, the
    /// user's predicate last.
    #[inline]
    fn passes(&self, filter: &QueryFilter<'_>, key: ProxyKey, slot: usize) -> bool {
        filter.exclude != Some(key)
            && filter
                .groups
                .is_none_or(|g| g.allows(self.store.group(slot)))
            && filter
                .predicate
                .is_none_or(|p| p(key, &self.store.shape[slot]))
    }

    /// Calls `f` with every proxy whose (margin-grown) box overlaps `aabb`, each once, in no
    /// particular order; nothing for a non-finite or inverted query box.
    pub fn query_aabb(&self, aabb: &Aabb, f: impl FnMut(ProxyKey)) {
        let _ = self.query_aabb_with(aabb, &QueryFilter::new(), every(f));
    }

    /// [`BroadPhase::query_aabb`] for the proxies `filter` passes, until `f` returns
    /// [`ControlFlow::Break`]: that ends the query and is returned (`Continue` if every match
    /// was visited).
    pub fn query_aabb_with(
        &self,
        aabb: &Aabb,
        filter: &QueryFilter<'_>,
        mut f: impl FnMut(ProxyKey) -> ControlFlow<()>,
    ) -> ControlFlow<()> {
        if check_aabb(aabb).is_err() {
            return ControlFlow::Continue(());
        }
        let q = SimdBox::new(aabb);
        // Outside the incremental regime the structures hold the exact boxes, which their
        // walks have tested; inside it they hold fat ones, and the regime the exact boxes.
        let exact = self.regime.as_ref().map(|r| &r.exact[..]);
        let mut test = |k: ProxyKey| {
            let s = crate::pair::slot(k) as usize;
            if !self.is_stale(s)
                && exact.is_none_or(|e| e[s].overlaps(&q))
                && self.passes(filter, k, s)
            {
                f(k)
            } else {
                ControlFlow::Continue(())
            }
        };
        self.octree.query_aabb_with_unchecked(aabb, &mut test)?;
        self.dynamic.query_aabb_with_unchecked(aabb, &mut test)?;
        self.statics.query_aabb_with_unchecked(aabb, &mut test)?;
        self.for_each_stale(|s| {
            let k = self.store.key(s as u32);
            if self.exact_box(&self.store.shape[s]).overlaps(&q) && self.passes(filter, k, s) {
                f(k)
            } else {
                ControlFlow::Continue(())
            }
        })
    }

    /// The nearest proxy hit by the segment `origin + t·dir`, `t ∈ [0, max_t]`, with its `t`
    /// (in units of `dir`, which need not be unit length). Spheres are hit as spheres, bodies
    /// as their boxes, both as the user gave them (without the margin); ties go to the smaller
    /// key. `None` for a non-finite ray or `max_t < 0`.
    #[must_use]
    pub fn cast_ray(&self, origin: Vec3, dir: Vec3, max_t: f32) -> Option<(ProxyKey, f32)> {
        self.cast_ray_with(origin, dir, max_t, &QueryFilter::new())
    }

    /// [`BroadPhase::cast_ray`] among the proxies `filter` passes: the nearest hit that
    /// passes (ties to the smaller key), whatever it rejected in front of it.
    #[must_use]
    pub fn cast_ray_with(
        &self,
        origin: Vec3,
        dir: Vec3,
        max_t: f32,
        filter: &QueryFilter<'_>,
    ) -> Option<(ProxyKey, f32)> {
        if !geom::ray_is_valid(origin, dir, max_t) {
            return None;
        }
        let inv = geom::inverse_dir(dir);
        let hit = FirstHit::new(max_t);
        // Spheres are re-tested in `f64` ([`geom::ray_sphere`]), so their `f32` boxes are
        // padded; a body's exact test is the slab test its box is pruned by, unpadded.
        let inflate = (geom::cast_pad(origin, 0.0, dir, max_t), 0.0);
        self.first_hit(
            hit,
            origin,
            dir,
            inflate,
            filter,
            |shape, limit| match *shape {
                Shape::Sphere { center, radius } => {
                    geom::ray_sphere(origin, dir, center, radius, limit)
                }
                Shape::Body { aabb, .. } => aabb.ray_entry(origin, inv, limit),
            },
        )
    }

    /// The first proxy touched by the sphere `center + t·dir` of radius `radius`, for `t` in
    /// `[0, max_t]`, with its `t` in units of `dir` (0 if it touches at the start; touching
    /// counts). Shapes as the user gave them: spheres as spheres (`sphere_cast_sphere`),
    /// bodies as their boxes (`sphere_cast_aabb`); ties go to the smaller key. `None`
    /// for a non-finite argument, a negative radius or a negative `max_t`.
    #[must_use]
    pub fn cast_sphere(
        &self,
        center: Vec3,
        radius: f32,
        dir: Vec3,
        max_t: f32,
    ) -> Option<(ProxyKey, f32)> {
        self.cast_sphere_with(center, radius, dir, max_t, &QueryFilter::new())
    }

    /// [`BroadPhase::cast_sphere`] among the proxies `filter` passes: the first touch that
    /// passes (ties to the smaller key), whatever it rejected in front of it.
    #[must_use]
    pub fn cast_sphere_with(
        &self,
        center: Vec3,
        radius: f32,
        dir: Vec3,
        max_t: f32,
        filter: &QueryFilter<'_>,
    ) -> Option<(ProxyKey, f32)> {
        let (hit, inflate) = FirstHit::sphere_cast(center, radius, dir, max_t)?;
        self.first_hit(
            hit,
            center,
            dir,
            (inflate, inflate),
            filter,
            |shape, limit| match *shape {
                Shape::Sphere {
                    center: c,
                    radius: r,
                } => geom::sphere_cast_sphere(center, radius, dir, limit, c, r),
                Shape::Body { aabb, .. } => {
                    geom::sphere_cast_aabb(center, radius, dir, limit, &aabb)
                }
            },
        )
    }

    /// The smallest `(t, key)` of `hit_of(shape, limit)` over the proxies `filter` passes whose
    /// held boxes, grown by `inflate` (the spheres', the bodies'), the segment `origin + t·dir` meets before the best `t`
    /// so far: each structure is walked nearer subtrees first and prunes what lies behind
    /// that `t`, the two BVHs in one walk ([`Bvh::ray_candidates_both`]), so that a hit in
    /// either prunes the other. A rejected proxy does not shorten the segment.
    fn first_hit(
        &self,
        mut hit: FirstHit,
        origin: Vec3,
        dir: Vec3,
        (sphere_inflate, body_inflate): (f32, f32),
        filter: &QueryFilter<'_>,
        hit_of: impl Fn(&Shape, f32) -> Option<f32>,
    ) -> Option<(ProxyKey, f32)> {
        let t_of = |key: ProxyKey, limit: f32| {
            let s = crate::pair::slot(key) as usize;
            if self.is_stale(s) {
                return None;
            }
            let t = hit_of(&self.store.shape[s], limit)?;
            self.passes(filter, key, s).then_some(t)
        };
        // Each candidate is tested up to `max_t`, not the best `t` so far: a sphere test
        // compares its `f64` time with the limit before rounding it, so a tie at the best `t`
        // (rounded to `f32`) could be refused, and a smaller key lost. The walks still prune
        // by the best `t`.
        let max_t = hit.limit();
        // A world of bodies alone skips the octree's setup.
        if !self.octree.is_empty() {
            self.octree
                .ray_candidates(origin, dir, max_t, sphere_inflate, |k, _| {
                    hit.offer(k, t_of(k, max_t))
                });
        }
        let limit = hit.limit();
        Bvh::ray_candidates_both(
            &self.dynamic,
            &self.statics,
            origin,
            dir,
            limit,
            body_inflate,
            |k, _| hit.offer(k, t_of(k, max_t)),
        );
        // The stale slots the structures skipped, at their latest shapes.
        let _ = self.for_each_stale(|s| {
            let k = self.store.key(s as u32);
            let t = hit_of(&self.store.shape[s], max_t);
            hit.offer(k, t.filter(|_| self.passes(filter, k, s)));
            ControlFlow::Continue(())
        });
        hit.best()
    }

    /// Calls `f` with every proxy whose shape, as the user gave it, is within `radius` of
    /// `center` (touching counts): a sphere whose centre is within `radius + its radius`, a
    /// body whose box is within `radius`. Each once, in no particular order; nothing for a
    /// non-finite argument or a negative radius.
    pub fn query_sphere(&self, center: Vec3, radius: f32, f: impl FnMut(ProxyKey)) {
        let _ = self.query_sphere_with(center, radius, &QueryFilter::new(), every(f));
    }

    /// [`BroadPhase::query_sphere`] for the proxies `filter` passes, until `f` returns
    /// [`ControlFlow::Break`]: that ends the query and is returned (`Continue` if every match
    /// was visited).
    pub fn query_sphere_with(
        &self,
        center: Vec3,
        radius: f32,
        filter: &QueryFilter<'_>,
        mut f: impl FnMut(ProxyKey) -> ControlFlow<()>,
    ) -> ControlFlow<()> {
        if geom::check_sphere(center, radius).is_err() {
            return ControlFlow::Continue(());
        }
        let reach = radius + geom::distance_pad(center, radius);
        self.within(center, reach, |key, s| {
            let inside = match self.store.shape[s] {
                Shape::Sphere {
                    center: c,
                    radius: r,
                } => geom::spheres_touch(c, r, center, radius),
                Shape::Body { aabb, .. } => geom::point_aabb_distance(center, &aabb) <= radius,
            };
            if inside && self.passes(filter, key, s) {
                f(key)
            } else {
                ControlFlow::Continue(())
            }
        })
    }

    /// The `k` proxies whose shapes, as the user gave them, are nearest `point` (distance 0
    /// inside: `point_sphere_distance`, `point_aabb_distance`), with their
    /// distances, sorted by `(distance, key)`; all of them if there are fewer. Empty for
    /// `k == 0` or a non-finite `point`. Allocates its result; [`BroadPhase::nearest_into`]
    /// fills a buffer of the caller's instead.
    #[must_use]
    pub fn nearest(&self, point: Vec3, k: usize) -> Vec<(ProxyKey, f32)> {
        let mut out = Vec::new();
        self.nearest_into(point, k, &QueryFilter::new(), &mut out);
        out
    }

    /// [`BroadPhase::nearest`] among the proxies `filter` passes, into `out` (cleared first).
    /// It allocates only to grow `out`, which also holds each round's candidates: a buffer
    /// kept across calls stops allocating once it has held the largest round.
    ///
    /// An expanding search: from the distance to the octree's region plus a part of the
    /// spacing `k` proxies spread evenly over it would have (or over the octree's typical
    /// cells, if that is less), each round takes every proxy
    /// whose held box is within the radius and doubles the radius until `k` that pass the
    /// filter are within it by their exact distance (or every proxy was seen). A proxy not
    /// seen is farther than the radius.
    pub fn nearest_into(
        &self,
        point: Vec3,
        k: usize,
        filter: &QueryFilter<'_>,
        out: &mut Vec<(ProxyKey, f32)>,
    ) {
        out.clear();
        let n = self.len();
        if k == 0 || n == 0 || !point.is_finite() {
            return;
        }
        let start = nearest_start(point, &self.occupied_bounds(), k, n)
            .min(self.octree.nearest_start(point, k));
        nearest_expanding(k, n, start, out, |radius, out| {
            let reach = radius + geom::distance_pad(point, radius);
            let mut seen = 0;
            let _ = self.within(point, reach, |key, s| {
                seen += 1;
                let d = match self.store.shape[s] {
                    Shape::Sphere { center, radius } => {
                        geom::point_sphere_distance(point, center, radius)
                    }
                    Shape::Body { aabb, .. } => geom::point_aabb_distance(point, &aabb),
                };
                if self.passes(filter, key, s) {
                    out.push((key, d));
                }
                ControlFlow::Continue(())
            });
            seen
        });
    }

    /// Where the proxies lie, for where a nearest search starts: the octree's region if it
    /// holds spheres (a sphere outside it only costs the search more rounds), joined with the
    /// bounds of both trees' boxes.
    fn occupied_bounds(&self) -> Aabb {
        let spheres = if self.octree.is_empty() {
            Aabb::EMPTY
        } else {
            self.octree.bounds()
        };
        spheres
            .union(&self.dynamic.bounds())
            .union(&self.statics.bounds())
    }

    /// Calls `f(key, slot)` for every proxy whose held box is within `radius` of `p`
    /// (spheres: whose held box meets the cube `p ± radius`): a superset of the proxies whose
    /// shapes are, since a shape lies in its held box. The first `Break` of `f` ends it.
    fn within(
        &self,
        p: Vec3,
        radius: f32,
        mut f: impl FnMut(ProxyKey, usize) -> ControlFlow<()>,
    ) -> ControlFlow<()> {
        let mut fresh = |k: ProxyKey| {
            let s = crate::pair::slot(k) as usize;
            if self.is_stale(s) {
                ControlFlow::Continue(())
            } else {
                f(k, s)
            }
        };
        self.octree.near(p, radius, &mut fresh)?;
        self.dynamic.within_distance(p, radius, |k, _| fresh(k))?;
        self.statics.within_distance(p, radius, |k, _| fresh(k))?;
        // The stale slots the structures skipped, whose latest box (a sphere's pruning box, as
        // the octree's) meets the cube `p ± radius`.
        let cube = SimdBox::new(&Aabb {
            min: p - Vec3::splat(radius),
            max: p + Vec3::splat(radius),
        });
        self.for_each_stale(|s| {
            let held = match self.store.shape[s] {
                Shape::Sphere { center, radius } => geom::sphere_prune_box(center, radius, 0.0),
                Shape::Body { aabb, .. } => SimdBox::new(&aabb),
            };
            if held.overlaps(&cube) {
                f(self.store.key(s as u32), s)
            } else {
                ControlFlow::Continue(())
            }
        })
    }
}
