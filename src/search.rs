//! What the structures' and the broadphase's searches share: how a sphere cast opens, the
//! running first hit of a cast, the slab test of one segment against many boxes, where a
//! k-nearest search starts and its expanding-radius loop, and the visitor of the plain queries.
//! Depends on `geom` and `pair` only.

use crate::geom::{self, Aabb, SimdBox};
use crate::pair::ProxyKey;
use core::ops::ControlFlow;
use glam::{Vec3, Vec3A, Vec4};

/// The visitor of the plain queries (the octree's, the BVHs' and the broadphase's): every
/// match, never a stop.
pub(crate) fn every(mut f: impl FnMut(ProxyKey)) -> impl FnMut(ProxyKey) -> ControlFlow<()> {
    move |key| {
        f(key);
        ControlFlow::Continue(())
    }
}

/// A nearest search's first radius beyond the searched objects' bounds, as a fraction of the
/// spacing `k` objects spread evenly over those bounds would have: below 1, a first round
/// usually finds `k` in a small region; a miss only doubles the radius.
const NEAREST_START: f32 = 0.5;

/// The smallest `(t, key)` offered so far, within `[0, max_t]`: a cast's answer, with ties
/// going to the smaller key.
#[derive(Clone, Copy, Debug)]
pub(crate) struct FirstHit {
    max_t: f32,
    best: Option<(ProxyKey, f32)>,
}

impl FirstHit {
    pub(crate) fn new(max_t: f32) -> Self {
        FirstHit { max_t, best: None }
    }

    /// How every sphere cast opens: `None` for a non-finite argument, a negative `radius` or a
    /// negative `max_t`; else the empty first hit and how far the candidates' boxes are grown:
    /// `radius` plus a relative pad, since the exact sphere tests work in `f64` and the box
    /// tests in `f32`.
    pub(crate) fn sphere_cast(
        center: Vec3,
        radius: f32,
        dir: Vec3,
        max_t: f32,
    ) -> Option<(Self, f32)> {
        if !geom::cast_is_valid(center, radius, dir, max_t) {
            return None;
        }
        let inflate = radius + geom::cast_pad(center, radius, dir, max_t);
        Some((FirstHit::new(max_t), inflate))
    }

    /// The `t` a later hit must not exceed: the best so far, else `max_t`.
    #[inline]
    pub(crate) fn limit(&self) -> f32 {
        self.best.map_or(self.max_t, |(_, t)| t)
    }

    /// Keeps `(key, t)` if it comes before the best so far; returns the new limit.
    #[inline]
    pub(crate) fn offer(&mut self, key: ProxyKey, t: Option<f32>) -> f32 {
        if let Some(t) = t
            && self.best.is_none_or(|(k, b)| (t, key) < (b, k))
        {
            self.best = Some((key, t));
        }
        self.limit()
    }

    pub(crate) fn best(&self) -> Option<(ProxyKey, f32)> {
        self.best
    }
}

/// One segment's slab test against many boxes, each grown by `inflate`: the same answer as
/// [`SimdBox::ray_entry`] (`is_some` and `t` alike, up to the sign of a zero `t`), cheaper
/// when no direction component is zero. Derivation: with `1 / dir` finite and nonzero on every
/// lane (a finite nonzero `dir` component has a finite nonzero inverse) and finite or infinite
/// but never NaN box corners, `(corner − origin) · inv` is never NaN (a NaN needs `0 · ∞` or
/// `∞ − ∞`, and a corner's difference with a finite origin can be `±∞` only times a nonzero
/// factor), so the NaN selects of the general test pick their own lanes and can be left out.
pub(crate) struct Slab {
    pub(crate) origin: Vec3A,
    pub(crate) inv: Vec3A,
    pub(crate) inflate: f32,
    /// No direction component is zero: the NaN-free test applies.
    pub(crate) finite: bool,
    /// `origin`, `inv` and `inflate` with each component in all four lanes, for
    /// the BVH's four-box leaf test.
    pub(crate) origin4: [Vec4; 3],
    pub(crate) inv4: [Vec4; 3],
    pub(crate) inflate4: Vec4,
}

impl Slab {
    pub(crate) fn new(origin: Vec3, dir: Vec3, inflate: f32) -> Self {
        let inv = Vec3A::from(geom::inverse_dir(dir));
        Slab {
            origin: origin.into(),
            inv,
            inflate,
            finite: inv.is_finite(),
            origin4: [0, 1, 2].map(|a| Vec4::splat(origin[a])),
            inv4: [0, 1, 2].map(|a| Vec4::splat(inv[a])),
            inflate4: Vec4::splat(inflate),
        }
    }

    /// The segment's entry `t` into `b` grown by `inflate`, if it enters it by `limit`.
    #[inline(always)]
    pub(crate) fn entry(&self, b: &SimdBox, limit: f32) -> Option<f32> {
        if !self.finite {
            return b
                .grown(self.inflate)
                .ray_entry(self.origin, self.inv, limit);
        }
        let (t, enters) = self.entry_or_miss::<true, true>(b, limit);
        enters.then_some(t)
    }

    /// The segment's entry `t` into the sphere's pruning box grown by `inflate`
    /// ([`geom::sphere_prune_box`]), if it enters it by `limit`: the growths are added to the
    /// radius before the corners are rounded, so the box is built once.
    #[inline(always)]
    pub(crate) fn sphere_entry(&self, center: Vec3, radius: f32, limit: f32) -> Option<f32> {
        let b = geom::sphere_prune_box(center, radius, self.inflate);
        if !self.finite {
            return b.ray_entry(self.origin, self.inv, limit);
        }
        let (t, enters) = self.finite_entry(&b, limit);
        enters.then_some(t)
    }

    /// [`Slab::entry`] of `b` by `limit` as its `t` and whether the segment enters (the `t`
    /// of a miss is unspecified). `FINITE` (iff [`Slab::finite`]) takes the NaN-free test,
    /// without a branch on the answer; `INFLATED` false skips the growth by zero.
    #[inline(always)]
    pub(crate) fn entry_or_miss<const INFLATED: bool, const FINITE: bool>(
        &self,
        b: &SimdBox,
        limit: f32,
    ) -> (f32, bool) {
        debug_assert!(FINITE == self.finite && (INFLATED || self.inflate == 0.0));
        if !FINITE {
            return self
                .entry(b, limit)
                .map_or((f32::INFINITY, false), |t| (t, true));
        }
        let b = if INFLATED { b.grown(self.inflate) } else { *b };
        self.finite_entry(&b, limit)
    }

    /// The NaN-free slab test of `b` itself, for a segment with no zero direction component
    /// (see [`Slab`]): its entry `t` by `limit` and whether it enters.
    #[inline(always)]
    fn finite_entry(&self, b: &SimdBox, limit: f32) -> (f32, bool) {
        let t1 = (b.min - self.origin) * self.inv;
        let t2 = (b.max - self.origin) * self.inv;
        // Never NaN (see [`Slab`]): plain compares clamp them.
        let near = t1.min(t2).max_element();
        let far = t1.max(t2).min_element();
        let near = if near > 0.0 { near } else { 0.0 };
        let far = if far < limit { far } else { limit };
        (near, near <= far)
    }
}

/// Where a search for the `k` nearest of `n` objects lying in `bounds` starts: the distance
/// from `point` to `bounds` plus [`NEAREST_START`] of the spacing `k` objects spread evenly
/// over them would have. Any start is exact (the loop widens until it has its answer); this
/// one only decides how many rounds that takes.
pub(crate) fn nearest_start(point: Vec3, bounds: &Aabb, k: usize, n: usize) -> f32 {
    let spread = (k as f32 / n as f32).min(1.0).cbrt();
    let spacing = NEAREST_START * bounds.extent().max_element().max(0.0) * spread;
    geom::point_aabb_distance(point, bounds) + spacing
}

/// Where a search for the `k` nearest objects of a structure that knows the cell its typical
/// object lives in (the octree's most populated level) starts: the distance from `point` to
/// `bounds` plus [`NEAREST_START`] of the edge of `k` such cells. Cells sized for their
/// objects hold about one each wherever the objects are, so this stays near the spacing
/// however much empty room the region around them has.
pub(crate) fn nearest_start_in_cells(point: Vec3, bounds: &Aabb, k: usize, cell: f32) -> f32 {
    let spacing = NEAREST_START * cell.max(0.0) * (k as f32).cbrt();
    geom::point_aabb_distance(point, bounds) + spacing
}

/// The `k` nearest of `n` objects by an expanding search, into `out` (cleared first): from
/// `radius`, each round has `collect(radius, out)` push `(key, exact distance)` for the
/// objects that may be within `radius` and are wanted (a superset is fine; every wanted one
/// within it must be there) and return how many objects it looked at, wanted or not; the
/// radius doubles until `k` pushed ones are within it, all `n` objects were looked at, or the
/// radius is infinite. An object not pushed is unwanted or farther than the radius, so the
/// first `k` pushed in `(distance, key)` order are the answer. Allocates only to grow `out`.
pub(crate) fn nearest_expanding(
    k: usize,
    n: usize,
    mut radius: f32,
    out: &mut Vec<(ProxyKey, f32)>,
    mut collect: impl FnMut(f32, &mut Vec<(ProxyKey, f32)>) -> usize,
) {
    loop {
        out.clear();
        let seen = collect(radius, out);
        let within = out.iter().filter(|&&(_, d)| d <= radius).count();
        if within >= k || seen >= n || radius == f32::INFINITY {
            break;
        }
        radius = (radius * 2.0).max(f32::MIN_POSITIVE);
    }
    out.sort_unstable_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
    out.truncate(k);
}
