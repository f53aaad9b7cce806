//! The exact shape tests the queries answer by (ray and sphere casts against spheres and
//! boxes, point distances, sphere contact), computed in `f64` from the `f32` inputs and rounded
//! once, and the pads the structures add so their `f32` pruning never drops a shape these
//! tests accept.

use super::{Aabb, SimdBox, check_aabb, check_sphere};
use glam::{DVec3, Vec3};

/// The smallest `t ∈ [0, max_t]` with `|origin + t·dir − center| ≤ radius`, or `None`.
/// `dir` need not be unit length (`t` is in units of `dir`); a zero `dir` hits only when the
/// origin is inside. An origin inside the sphere gives `t = 0`. Computed in `f64` from the
/// `f32` inputs and rounded once, in the cancellation-free form below.
///
/// The textbook discriminant `b² − a·c` (`a = |dir|²`, `b = m·dir`, `c = |m|² − r²`,
/// `m = origin − center`) subtracts two nearly equal squares for a ray grazing the sphere far
/// from its start: `b²` and `a·|m|²` agree in every bit the answer depends on, and the
/// difference left is rounding noise, in `f32` and in `f64` alike. Lagrange's identity
/// `|m|²·|dir|² − (m·dir)² = |m × dir|²` rewrites it as `a·r² − |m × dir|²`, a comparison of
/// the squared radius with the squared distance from the centre to the line, whose terms are
/// each computed to a few `f64` roundings of their own size (*Ray Tracing Gems*, ch. 7). `f64`
/// also keeps the fourth powers of subnormal and huge `f32` inputs inside its range, where
/// `f32` squares underflow to 0 or overflow to `∞`.
#[must_use]
pub fn ray_sphere(origin: Vec3, dir: Vec3, center: Vec3, radius: f32, max_t: f32) -> Option<f32> {
    let m = origin.as_dvec3() - center.as_dvec3();
    first_touch(m, dir.as_dvec3(), f64::from(radius)).and_then(|t| at_most(t, max_t))
}

/// Relative size of the pad the structures add to their pruning distances and ray inflations
/// for the queries that re-test exact shapes: far above the rounding of the `f32` node and
/// slab tests (a few `2⁻²⁴` of the coordinates involved), so a shape the exact test accepts is
/// never pruned by a node or candidate test that rounded the other way.
const QUERY_PAD: f32 = 1e-5;

/// The Euclidean distance from `p` to the closed box `b`, 0 when `p` is inside or on a face.
/// Computed in `f64` and rounded once (to `+∞` only past `f32::MAX`), so no intermediate
/// overflows, and it never decreases as `b` shrinks. An infinite face is fine; a NaN anywhere
/// or a non-finite `p` gives `+∞`, and an inverted box (such as [`Aabb::EMPTY`]) is at a
/// positive distance from every point.
///
/// Nothing cancels: each axis' gap is one subtraction of two `f32` values (exact in `f64`
/// unless their exponents differ by more than 29, and then correctly rounded), and the rest
/// sums non-negative squares, which `f64` neither underflows (the square of the smallest
/// subnormal `f32` is about `2e-90`) nor overflows.
#[must_use]
pub fn point_aabb_distance(p: Vec3, b: &Aabb) -> f32 {
    if !p.is_finite() || b.min.is_nan() || b.max.is_nan() {
        return f32::INFINITY;
    }
    let (p, lo, hi) = (p.as_dvec3(), b.min.as_dvec3(), b.max.as_dvec3());
    let gap = (lo - p).max(p - hi).max(DVec3::ZERO);
    gap.length() as f32
}

/// True if the solid spheres `(a, ra)` and `(b, rb)` touch or overlap: `|a − b| <= ra + rb`,
/// compared in `f64` (squares of `f32` values neither overflow nor lose the small terms there),
/// so that centres far apart are not taken for touching when the `f32` squares would overflow
/// to `+∞`. Finite inputs expected.
///
/// A comparison of two non-negative sums, not a difference: the answer can be wrong only for
/// spheres whose gap is below the `f64` rounding of the squares (`2⁻⁵²` of the distance),
/// far below the `f32` spacing of the inputs. On an axis where the spheres are aligned the
/// test is exact, which is what keeps it inside the boxes' overlap: `a.x + ra >= b.x − rb`
/// then holds, and rounding both sides to `f32` keeps it.
#[must_use]
pub fn spheres_touch(a: Vec3, ra: f32, b: Vec3, rb: f32) -> bool {
    let r = f64::from(ra) + f64::from(rb);
    (a.as_dvec3() - b.as_dvec3()).length_squared() <= r * r
}

/// The distance from `p` to the solid sphere, `max(|p − center| − radius, 0)`, computed in
/// `f64` and rounded once; `+∞` if an input is not finite or the radius is negative.
///
/// `|m| − r` (`m = p − center`) cancels for a point near the surface: `|m|` carries the
/// rounding of its square root, `2⁻⁵³·|m|`, which can be all of a small difference. The
/// product form `(|m|² − r²) / (|m| + r)` has no square root in the numerator: for `f32`
/// coordinates the differences, their squares and `r²` are exact in `f64` (up to 48 bits
/// each, unless the exponents are far apart), so the numerator is exact or nearly so and the
/// quotient carries a few relative roundings only.
#[must_use]
pub fn point_sphere_distance(p: Vec3, center: Vec3, radius: f32) -> f32 {
    if !(p.is_finite() && check_sphere(center, radius).is_ok()) {
        return f32::INFINITY;
    }
    let m2 = (p.as_dvec3() - center.as_dvec3()).length_squared();
    let r = f64::from(radius);
    let excess = m2 - r * r;
    if excess <= 0.0 {
        return 0.0;
    }
    (excess / (m2.sqrt() + r)) as f32
}

/// The first `t ∈ [0, max_t]` at which the sphere `center + t·dir`, `radius` touches the
/// sphere `other_center`, `other_radius` (centre distance `<= radius + other_radius`), `t` in
/// units of `dir`: 0 if they touch or overlap at the start, and for a zero `dir` either 0 or
/// `None`. `None` if they never touch in that range, if an input is not finite, or if a radius
/// or `max_t` is negative.
#[must_use]
pub fn sphere_cast_sphere(
    center: Vec3,
    radius: f32,
    dir: Vec3,
    max_t: f32,
    other_center: Vec3,
    other_radius: f32,
) -> Option<f32> {
    if !cast_is_valid(center, radius, dir, max_t)
        || check_sphere(other_center, other_radius).is_err()
    {
        return None;
    }
    let m = center.as_dvec3() - other_center.as_dvec3();
    let r = f64::from(radius) + f64::from(other_radius);
    first_touch(m, dir.as_dvec3(), r).and_then(|t| at_most(t, max_t))
}

/// The first `t ∈ [0, max_t]` at which the sphere `center + t·dir`, `radius` touches the closed
/// box `b` (some point of the box within `radius` of the centre: touching counts), `t` in units
/// of `dir`: 0 if they touch or overlap at the start, and for a zero `dir` either 0 or `None`.
/// Exact up to rounding, corners and edges included. `None` if they never touch in that range,
/// if an input is not finite, if `radius` or `max_t` is negative, or if `b` is inverted.
///
/// Ericson, *Real-Time Collision Detection* 5.5.7. The centres at which the sphere touches the
/// box form the box's Minkowski sum with the sphere: a box with rounded edges and corners,
/// the union of the three boxes `b` grown by `radius` along one axis only and the twelve
/// capsules of radius `radius` around the edges. It lies inside `b` grown by `radius` on every
/// side, so a ray missing that box misses it. Where the ray enters the grown box, the entry
/// point is outside `b`'s slab on zero, one, two or three axes. Zero (a start inside `b`) or
/// one: the point is on the rounded box itself (in `b` or on a face part), and nothing was
/// touched earlier. Two: the point is in an
/// edge's region, where the rounded box is that edge's capsule; a ray missing it can reach
/// the rest of the rounded box only through that capsule or through the corner spheres at its
/// ends, so the capsule decides. Three: a corner's region, and the ray can go on only through
/// the regions of the three edges meeting there, so their three capsules decide. All of it is
/// done in `f64` from the `f32` inputs, so no intermediate overflows or underflows.
///
/// Where it could cancel: the slab times are one difference and one quotient each (as in
/// [`Aabb::ray_entry`], no cancellation); the capsules' sides and end spheres are the same
/// first-touch test as [`ray_sphere`], whose discriminant is Lagrange's `a·r² − |m × d|²`,
/// not `b² − ac`. The entry point's region is read from a rounded point, so a path entering
/// within an `f64` rounding of an edge's region may be answered as a face (at `t0`), off by
/// that rounding.
#[must_use]
pub fn sphere_cast_aabb(center: Vec3, radius: f32, dir: Vec3, max_t: f32, b: &Aabb) -> Option<f32> {
    if !cast_is_valid(center, radius, dir, max_t) || check_aabb(b).is_err() {
        return None;
    }
    let (o, d, r) = (center.as_dvec3(), dir.as_dvec3(), f64::from(radius));
    let (lo, hi) = (b.min.as_dvec3(), b.max.as_dvec3());
    let (mut t0, mut t1) = (0.0f64, f64::from(max_t));
    for a in 0..3 {
        let (slab_lo, slab_hi) = (lo[a] - r, hi[a] + r);
        if d[a] == 0.0 {
            if o[a] < slab_lo || o[a] > slab_hi {
                return None;
            }
            continue;
        }
        let (ta, tb) = ((slab_lo - o[a]) / d[a], (slab_hi - o[a]) / d[a]);
        t0 = t0.max(ta.min(tb));
        t1 = t1.min(ta.max(tb));
        if t0 > t1 {
            return None;
        }
    }
    let p = o + d * t0;
    let below = p.cmplt(lo).bitmask();
    let above = p.cmpgt(hi).bitmask();
    // The corner of `b` nearest the entry point on the axes where it is outside the slab.
    let corner = DVec3::select(p.cmplt(lo), lo, hi);
    let t = match (below | above).count_ones() {
        0 | 1 => Some(t0),
        2 => {
            let axis = (!(below | above) & 7).trailing_zeros() as usize;
            capsule_touch(o, d, r, corner, axis, lo[axis], hi[axis])
        }
        _ => (0..3)
            .filter_map(|axis| capsule_touch(o, d, r, corner, axis, lo[axis], hi[axis]))
            .reduce(f64::min),
    }?;
    // The rounded box lies inside the grown box: nothing touches before `t0`.
    at_most(t.max(t0), max_t)
}

/// The first `t >= 0` at which `|m + t·d| <= r` (`m` is the start relative to the centre), in
/// `f64`. With `c = |m|² − r²`, `b = m·d`, `a = |d|²`, the roots of `a t² + 2 b t + c` are
/// `(−b ± √(b² − ac)) / a`. `c <= 0` touches at once; `b >= 0` never touches later (this
/// includes `d = 0`). The discriminant is taken as `a·r² − |m × d|²` (Lagrange's identity,
/// see [`ray_sphere`]): `b² − ac` cancels catastrophically for a grazing path that starts far
/// away, while each term here has its own magnitude's rounding only (a cross product's
/// components cancel only when `m` is nearly parallel to `d`, where `a·r²` dominates unless
/// `r` is tiny, and then the sign is that of a difference of two products of `f32`-derived
/// values, within a few `f64` roundings). The smaller root is computed as
/// `c / (−b + √disc)`, which does not cancel when `b < 0` (a path moving towards the centre,
/// the only case that can touch later). With `m` the `f64` difference of `f32` coordinates
/// (exact unless their exponents differ by more than 29), the answer is the exact one up to a
/// few `f64` roundings relative to `|m|` and `|d|`, far below the `f32` rounding of the result.
fn first_touch(m: DVec3, d: DVec3, r: f64) -> Option<f64> {
    let c = m.length_squared() - r * r;
    if c <= 0.0 {
        return Some(0.0);
    }
    let b = m.dot(d);
    if b >= 0.0 {
        return None;
    }
    let disc = d.length_squared() * (r * r) - m.cross(d).length_squared();
    (disc >= 0.0).then(|| c / (-b + disc.sqrt()))
}

/// The first `t >= 0` at which `o + t·d` is within `r` of the edge through `corner` along
/// `axis`, spanning `lo..=hi` on that axis: the finite cylinder's side (the infinite cylinder,
/// entered where the axis coordinate is in range) or either end sphere (which holds the
/// cylinder's end disk, so a ray entering through a disk touches the sphere no later).
fn capsule_touch(
    o: DVec3,
    d: DVec3,
    r: f64,
    corner: DVec3,
    axis: usize,
    lo: f64,
    hi: f64,
) -> Option<f64> {
    let mut m = o - corner;
    let mut dd = d;
    m[axis] = 0.0;
    dd[axis] = 0.0;
    let side = first_touch(m, dd, r).filter(|&t| (lo..=hi).contains(&(o[axis] + t * d[axis])));
    let end = |at: f64| {
        let mut c = corner;
        c[axis] = at;
        first_touch(o - c, d, r)
    };
    [side, end(lo), end(hi)]
        .into_iter()
        .flatten()
        .reduce(f64::min)
}

/// `t` rounded to `f32` if it is at most `max_t`.
fn at_most(t: f64, max_t: f32) -> Option<f32> {
    let t = t as f32;
    (t <= max_t).then_some(t)
}

/// True if a sphere cast's arguments are usable: finite centre and direction, finite radius
/// and `max_t`, both `>= 0`.
pub(crate) fn cast_is_valid(center: Vec3, radius: f32, dir: Vec3, max_t: f32) -> bool {
    check_sphere(center, radius).is_ok() && dir.is_finite() && max_t.is_finite() && max_t >= 0.0
}

/// What the structures add to `radius` when they look for the boxes a sphere cast (or a ray,
/// `radius = 0`) may touch, so that no box holding a touch the exact `f64` test finds is
/// pruned by the `f32` slab tests (and the `f32` boxes) that rounded the other way. `+∞` for a
/// cast too long for `f32`, which then tests every candidate.
///
/// Three terms. [`QUERY_PAD`] times the magnitude of the coordinates along the cast covers
/// the relative rounding of the box corners (`center ± radius`), of the slab differences and
/// of their products with `1 / dir`. A direction component below `2⁻¹²⁷` has an infinite
/// inverse, and the slab test takes the segment as not moving along that axis, though it
/// moves up to `2⁻¹²⁷·max_t`: `max_t · 2⁻¹²⁶` covers that, however small the component is
/// next to the others (the relative term would not). And a slab time in the subnormal range
/// rounds by up to `2⁻¹⁵⁰` absolutely, a distance of `|dir|·2⁻¹⁵⁰`: `|dir| · 2⁻¹²⁶` covers
/// that where the coordinates are too small for the relative term to.
pub(crate) fn cast_pad(center: Vec3, radius: f32, dir: Vec3, max_t: f32) -> f32 {
    let reach = dir.abs().max_element();
    (center.abs().max_element() + reach * max_t + radius) * QUERY_PAD
        + (max_t + reach) * f32::MIN_POSITIVE
}

/// The factor by which the queries grow a sphere's radius for the box they prune it by:
/// `1 + 2⁻²⁰`, so the radius grows by at least `2⁻²¹` of itself after rounding.
const SPHERE_PRUNE: f32 = 1.0 + 1.0 / (1u32 << 20) as f32;

/// The box the queries prune a sphere by before its exact `f64` test: `center ± radius`, the
/// radius grown by `2⁻²⁰` of itself. The `f64` sphere tests ([`first_touch`],
/// [`point_sphere_distance`], [`spheres_touch`]) are exact for a sphere moved by a few `2⁻⁵²`
/// of `|center − start|` and of `radius`. The query's pad ([`cast_pad`], [`distance_pad`])
/// covers what is relative to the query's own coordinates; this covers what is relative to
/// the radius, which is far larger for a huge sphere whose surface passes near a small query
/// (a sphere of radius `1e30` about `(1e30, 0, 0)` and a ray by the origin). The structures'
/// nodes hold this box: their slack exceeds `2⁻²⁰` of any radius they place.
/// `grow` is added to the grown radius (a cast's inflation), one rounding per corner.
#[inline]
pub(crate) fn sphere_prune_box(center: Vec3, radius: f32, grow: f32) -> SimdBox {
    SimdBox::from_center_radius(center, radius * SPHERE_PRUNE + grow)
}

/// What the structures add to `radius` when they look for the shapes within `radius` of `p`
/// ([`QUERY_PAD`] times the magnitude of the coordinates involved).
pub(crate) fn distance_pad(p: Vec3, radius: f32) -> f32 {
    (p.abs().max_element() + radius) * QUERY_PAD
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ray_sphere_cases() {
        let c = Vec3::new(5.0, 0.0, 0.0);
        assert_eq!(ray_sphere(Vec3::ZERO, Vec3::X, c, 1.0, 100.0), Some(4.0));
        assert_eq!(
            ray_sphere(Vec3::ZERO, Vec3::X * 2.0, c, 1.0, 100.0),
            Some(2.0)
        );
        assert_eq!(ray_sphere(Vec3::ZERO, Vec3::X, c, 1.0, 3.9), None);
        assert_eq!(ray_sphere(Vec3::ZERO, -Vec3::X, c, 1.0, 100.0), None);
        assert_eq!(ray_sphere(c, Vec3::X, c, 1.0, 100.0), Some(0.0));
        assert_eq!(ray_sphere(Vec3::ZERO, Vec3::ZERO, c, 1.0, 100.0), None);
        assert_eq!(ray_sphere(Vec3::ZERO, Vec3::Y, c, 1.0, 100.0), None);
    }
}
