//! Axis-aligned boxes, the ray–box slab test, ray–sphere, and the input checks every entry
//! point runs before it touches a structure.

use crate::error::Error;
use glam::{Vec3, Vec3A};

/// A closed axis-aligned box: a point on a face is inside, and boxes that touch overlap.
///
/// The fields are public; a box with `min > max` on some axis is *inverted* and every entry
/// point of the crate refuses it with [`Error::InvertedAabb`].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Aabb {
    /// The corner with the smallest coordinates.
    pub min: Vec3,
    /// The corner with the largest coordinates.
    pub max: Vec3,
}

impl Aabb {
    /// The box spanned by `min` and `max`, unchecked; see [`Aabb::try_new`].
    #[must_use]
    pub const fn new(min: Vec3, max: Vec3) -> Self {
        Self { min, max }
    }

    /// The box spanned by `min` and `max`, or `Err` if a coordinate is not finite or
    /// `min > max` on some axis.
    pub fn try_new(min: Vec3, max: Vec3) -> Result<Self, Error> {
        let aabb = Self { min, max };
        check_aabb(&aabb)?;
        Ok(aabb)
    }

    /// The box `center ± radius`: the AABB of a sphere. Unchecked; a negative radius gives an
    /// inverted box.
    #[must_use]
    pub fn from_center_radius(center: Vec3, radius: f32) -> Self {
        Self {
            min: center - Vec3::splat(radius),
            max: center + Vec3::splat(radius),
        }
    }

    /// The box `center ± half_extents`. Unchecked.
    #[must_use]
    pub fn from_center_half_extents(center: Vec3, half_extents: Vec3) -> Self {
        Self {
            min: center - half_extents,
            max: center + half_extents,
        }
    }

    /// An inverted box that is the identity of [`Aabb::union`]: `EMPTY.union(b) == b`.
    pub const EMPTY: Self = Self {
        min: Vec3::splat(f32::INFINITY),
        max: Vec3::splat(f32::NEG_INFINITY),
    };

    /// The midpoint of the box.
    #[must_use]
    pub fn center(&self) -> Vec3 {
        (self.min + self.max) * 0.5
    }

    /// `max - min`: the box's size along each axis (negative for an inverted box).
    #[must_use]
    pub fn extent(&self) -> Vec3 {
        self.max - self.min
    }

    /// True if the closed boxes share at least one point; touching boxes overlap.
    #[must_use]
    #[inline]
    pub fn overlaps(&self, other: &Aabb) -> bool {
        SimdBox::new(self).overlaps(&SimdBox::new(other))
    }

    /// True if `other` lies inside `self` (faces may coincide).
    #[must_use]
    #[inline]
    pub fn contains(&self, other: &Aabb) -> bool {
        SimdBox::new(self).contains(&SimdBox::new(other))
    }

    /// True if the point lies inside the closed box.
    #[must_use]
    pub fn contains_point(&self, p: Vec3) -> bool {
        self.min.cmple(p).all() && p.cmple(self.max).all()
    }

    /// The smallest box containing both.
    #[must_use]
    #[inline]
    pub fn union(&self, other: &Aabb) -> Aabb {
        Aabb {
            min: self.min.min(other.min),
            max: self.max.max(other.max),
        }
    }

    /// The box grown by `margin` on every side (shrunk for a negative margin).
    #[must_use]
    pub fn grown(&self, margin: f32) -> Aabb {
        Aabb {
            min: self.min - Vec3::splat(margin),
            max: self.max + Vec3::splat(margin),
        }
    }

    /// The surface area `2(xy + yz + zx)`; 0 for a point, and 0 for an inverted box (such as
    /// [`Aabb::EMPTY`]) so that SAH sums stay finite.
    #[must_use]
    #[inline]
    pub fn surface_area(&self) -> f32 {
        SimdBox::new(self).surface_area()
    }

    /// True if every coordinate is finite.
    #[must_use]
    pub fn is_finite(&self) -> bool {
        self.min.is_finite() && self.max.is_finite()
    }

    /// The ray's entry parameter into the closed box, if the segment `origin + t·dir`,
    /// `t ∈ [0, max_t]` meets it; `0` when the origin is inside. `inv_dir` is `1 / dir`
    /// component-wise (an infinite component for an axis the ray does not move along).
    ///
    /// The slab test: on each axis the ray is inside the slab for `t` between
    /// `(min − o)/d` and `(max − o)/d`; the segment meets the box iff the latest entry is not
    /// after the earliest exit. A zero direction component gives `±∞` (the ray is inside or
    /// outside that slab for all `t`), or `0 · ∞ = NaN` when the origin lies exactly on a face
    /// of that slab; such a NaN is replaced by `−∞` for the entry and `+∞` for the exit, so a
    /// ray sliding along a face hits the closed box. (glam's `min`/`max` are comparisons, so
    /// an unreplaced NaN would propagate and turn a miss into a hit.) The result is monotone:
    /// a box containing another is entered no later and left no earlier.
    ///
    /// Nothing cancels: each slab time is one subtraction and one product, each rounded once
    /// and monotone in the corner, and the answer only compares them; no difference of nearly
    /// equal products is formed. It is a function of the floats given (`inv_dir` is already
    /// rounded) and the crate's one definition of a ray meeting a box: a body's cast answers
    /// with it, and the BVH prunes by the same operations on boxes holding their children's,
    /// which by the monotony never prunes a box this enters. (Spheres are tested in `f64`
    /// instead, by [`ray_sphere`], and their boxes pruned with a pad.)
    #[must_use]
    #[inline]
    pub fn ray_entry(&self, origin: Vec3, inv_dir: Vec3, max_t: f32) -> Option<f32> {
        SimdBox::new(self).ray_entry(origin.into(), inv_dir.into(), max_t)
    }

    /// The ray's exit parameter from the box, capped at `max_t`, for a ray that
    /// [`Aabb::ray_entry`] says enters it (same lanes and NaN rules).
    pub(crate) fn ray_exit(&self, origin: Vec3, inv_dir: Vec3, max_t: f32) -> f32 {
        let t1 = (self.min - origin) * inv_dir;
        let t2 = (self.max - origin) * inv_dir;
        let (n1, n2) = (t1.is_nan_mask(), t2.is_nan_mask());
        let far = Vec3::select(n1, Vec3::INFINITY, t1).max(Vec3::select(n2, Vec3::INFINITY, t2));
        far.min_element().min(max_t)
    }
}

/// A box in SIMD lanes, 32 bytes: the crate's one box type for hot loops. Two of them are
/// tested for overlap with two 4-lane compares and no branch.
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(C)]
pub(crate) struct SimdBox {
    pub(crate) min: Vec3A,
    pub(crate) max: Vec3A,
}

impl SimdBox {
    /// The empty box (`min = +∞`, `max = −∞`): it overlaps nothing.
    pub(crate) const EMPTY: SimdBox = SimdBox {
        min: Vec3A::INFINITY,
        max: Vec3A::NEG_INFINITY,
    };

    #[inline]
    pub(crate) fn new(aabb: &Aabb) -> Self {
        SimdBox {
            min: aabb.min.into(),
            max: aabb.max.into(),
        }
    }

    /// The box `center ± radius`, lane for lane the same floats as
    /// [`Aabb::from_center_radius`].
    #[inline]
    pub(crate) fn from_center_radius(center: Vec3, radius: f32) -> Self {
        let (c, r) = (Vec3A::from(center), Vec3A::splat(radius));
        SimdBox {
            min: c - r,
            max: c + r,
        }
    }

    /// True if `other` lies inside `self` (faces may coincide).
    #[inline]
    pub(crate) fn contains(&self, other: &SimdBox) -> bool {
        (self.min.cmple(other.min) & other.max.cmple(self.max)).all()
    }

    /// `max - min` per axis.
    #[inline]
    pub(crate) fn extent(&self) -> Vec3A {
        self.max - self.min
    }

    #[inline]
    pub(crate) fn aabb(&self) -> Aabb {
        Aabb::new(self.min.into(), self.max.into())
    }

    /// [`Aabb::ray_entry`] in vector lanes (the same floats lane for lane): the slab test with
    /// its NaN rule, for the traversals that test many boxes against one ray.
    #[inline]
    pub(crate) fn ray_entry(&self, origin: Vec3A, inv_dir: Vec3A, max_t: f32) -> Option<f32> {
        let t1 = (self.min - origin) * inv_dir;
        let t2 = (self.max - origin) * inv_dir;
        let (n1, n2) = (t1.is_nan_mask(), t2.is_nan_mask());
        let near = Vec3A::select(n1, Vec3A::NEG_INFINITY, t1).min(Vec3A::select(
            n2,
            Vec3A::NEG_INFINITY,
            t2,
        ));
        let far =
            Vec3A::select(n1, Vec3A::INFINITY, t1).max(Vec3A::select(n2, Vec3A::INFINITY, t2));
        let t_near = near.max_element().max(0.0);
        let t_far = far.min_element().min(max_t);
        (t_near <= t_far).then_some(t_near)
    }

    /// This box grown by `margin` on every side, as [`Aabb::grown`] grows it.
    #[inline]
    pub(crate) fn grown(&self, margin: f32) -> SimdBox {
        let m = Vec3A::splat(margin);
        SimdBox {
            min: self.min - m,
            max: self.max + m,
        }
    }

    /// True if the closed boxes share at least one point; touching boxes overlap. Two
    /// vector compares and one branch.
    #[inline]
    pub(crate) fn overlaps(&self, other: &SimdBox) -> bool {
        (self.min.cmple(other.max) & other.min.cmple(self.max)).all()
    }

    /// The smallest box containing both, as [`Aabb::union`]; [`SimdBox::EMPTY`] is its identity.
    #[inline]
    pub(crate) fn union(&self, other: &SimdBox) -> SimdBox {
        SimdBox {
            min: self.min.min(other.min),
            max: self.max.max(other.max),
        }
    }

    /// The smallest box containing `self` and the point `p`.
    #[inline]
    pub(crate) fn union_point(&self, p: Vec3A) -> SimdBox {
        SimdBox {
            min: self.min.min(p),
            max: self.max.max(p),
        }
    }

    /// `min + max`: twice the centre, exact where the centre would round.
    #[inline]
    pub(crate) fn center2(&self) -> Vec3A {
        self.min + self.max
    }

    /// The surface area, as [`Aabb::surface_area`]: 0 for a point and for an inverted box.
    #[inline]
    pub(crate) fn surface_area(&self) -> f32 {
        let d = self.extent().max(Vec3A::ZERO);
        2.0 * (d.x * d.y + d.y * d.z + d.z * d.x)
    }
}

const _: () = assert!(core::mem::size_of::<SimdBox>() == 32);

/// The bits of `f` as an integer whose unsigned order is [`f32::total_cmp`]'s order: positive
/// floats (sign bit 0) order like their bits, so setting the sign bit puts them above every
/// negative one; negative floats order reversed, which inverting all their bits undoes. `-0.0`
/// maps just below `0.0`; map `f + 0.0` (which is `0.0` for both zeros) where they must tie.
#[must_use]
#[inline]
pub(crate) fn ordered_bits(f: f32) -> u32 {
    let bits = f.to_bits();
    bits ^ (((bits as i32 >> 31) as u32) | 0x8000_0000)
}

/// The float [`ordered_bits`] maps to `k`: the sign bit set marks a positive float, whose bits
/// are `k` without it; else every bit was inverted.
#[must_use]
#[inline]
pub(crate) fn from_ordered_bits(k: u32) -> f32 {
    f32::from_bits(if k >> 31 == 1 { k & !(1 << 31) } else { !k })
}

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

/// `1 / dir` per component, with `±∞` for zero components (sign kept from `-0.0`).
#[must_use]
pub fn inverse_dir(dir: Vec3) -> Vec3 {
    Vec3::ONE / dir
}

/// Checks a sphere given by the user: finite centre, finite non-negative radius. The common
/// case, all good, is one vector test; a bad sphere is then named field by field.
#[inline]
pub(crate) fn check_sphere(center: Vec3, radius: f32) -> Result<(), Error> {
    let v = glam::Vec4::from((center, radius));
    if v.is_finite_mask().all() && radius >= 0.0 {
        return Ok(());
    }
    name_sphere_error(center, radius)
}

/// The error [`check_sphere`] gives a sphere that fails it.
#[cold]
fn name_sphere_error(center: Vec3, radius: f32) -> Result<(), Error> {
    if !center.is_finite() {
        return Err(Error::NonFinite {
            what: "center",
            value: center,
        });
    }
    if !radius.is_finite() {
        return Err(Error::NonFinite {
            what: "radius",
            value: Vec3::new(radius, 0.0, 0.0),
        });
    }
    if radius < 0.0 {
        return Err(Error::NegativeRadius(radius));
    }
    Ok(())
}

/// Checks a box given by the user: finite corners, `min <= max` on every axis.
#[inline]
pub(crate) fn check_aabb(aabb: &Aabb) -> Result<(), Error> {
    let (min, max) = (glam::Vec3A::from(aabb.min), glam::Vec3A::from(aabb.max));
    if (min.is_finite_mask() & max.is_finite_mask() & min.cmple(max)).all() {
        return Ok(());
    }
    name_aabb_error(aabb)
}

/// The error [`check_aabb`] reports for a box it refused.
#[cold]
fn name_aabb_error(aabb: &Aabb) -> Result<(), Error> {
    if !aabb.min.is_finite() {
        return Err(Error::NonFinite {
            what: "aabb.min",
            value: aabb.min,
        });
    }
    if !aabb.max.is_finite() {
        return Err(Error::NonFinite {
            what: "aabb.max",
            value: aabb.max,
        });
    }
    if !aabb.min.cmple(aabb.max).all() {
        return Err(Error::InvertedAabb {
            min: aabb.min,
            max: aabb.max,
        });
    }
    Ok(())
}

/// Checks world bounds: finite, and `min < max` on every axis (a cell needs volume).
pub(crate) fn check_bounds(bounds: &Aabb) -> Result<(), Error> {
    if bounds.is_finite() && bounds.min.cmplt(bounds.max).all() {
        Ok(())
    } else {
        Err(Error::InvalidBounds {
            min: bounds.min,
            max: bounds.max,
        })
    }
}

/// Checks a ray given by the user: finite origin and direction, `max_t` not NaN and `>= 0`.
/// Returns `false` for a ray that can hit nothing (caller answers `None`), never panics.
pub(crate) fn ray_is_valid(origin: Vec3, dir: Vec3, max_t: f32) -> bool {
    origin.is_finite() && dir.is_finite() && max_t >= 0.0
}

use glam::DVec3;

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
    fn touching_boxes_overlap() {
        let a = Aabb::new(Vec3::ZERO, Vec3::ONE);
        let b = Aabb::new(Vec3::new(1.0, 0.0, 0.0), Vec3::new(2.0, 1.0, 1.0));
        let c = Aabb::new(Vec3::new(1.0001, 0.0, 0.0), Vec3::new(2.0, 1.0, 1.0));
        assert!(a.overlaps(&b) && b.overlaps(&a));
        assert!(!a.overlaps(&c) && !c.overlaps(&a));
    }

    #[test]
    fn union_and_area() {
        let a = Aabb::new(Vec3::ZERO, Vec3::ONE);
        let b = Aabb::new(Vec3::splat(2.0), Vec3::splat(3.0));
        let u = a.union(&b);
        assert_eq!(u, Aabb::new(Vec3::ZERO, Vec3::splat(3.0)));
        assert_eq!(Aabb::EMPTY.union(&a), a);
        assert_eq!(a.surface_area(), 6.0);
        assert_eq!(Aabb::EMPTY.surface_area(), 0.0);
    }

    #[test]
    fn slab_test_hits_misses_and_slides_along_faces() {
        let b = Aabb::new(Vec3::ZERO, Vec3::ONE);
        let o = Vec3::new(-1.0, 0.5, 0.5);
        let d = Vec3::X;
        assert_eq!(b.ray_entry(o, inverse_dir(d), 10.0), Some(1.0));
        assert_eq!(b.ray_entry(o, inverse_dir(d), 0.5), None);
        assert_eq!(b.ray_entry(o, inverse_dir(-d), 10.0), None);
        // Origin inside.
        assert_eq!(
            b.ray_entry(Vec3::splat(0.5), inverse_dir(d), 1.0),
            Some(0.0)
        );
        // Sliding exactly along the face y = 1 (closed box: a hit).
        let face = Vec3::new(-1.0, 1.0, 0.5);
        assert_eq!(b.ray_entry(face, inverse_dir(d), 10.0), Some(1.0));
        let low_face = Vec3::new(-1.0, 0.0, 0.5);
        assert_eq!(b.ray_entry(low_face, inverse_dir(-d), 10.0), None);
        assert_eq!(b.ray_entry(low_face, inverse_dir(d), 10.0), Some(1.0));
        // On the plane of one face but outside the box on another axis: a miss (a NaN from
        // 0 · ∞ must not leak through glam's comparison-based min/max and make this a hit).
        let outside = Aabb::new(Vec3::new(-2.0, -4.0, 1.0), Vec3::new(-1.0, 0.0, 5.0));
        assert_eq!(
            outside.ray_entry(Vec3::new(13.0, 3.0, 5.0), inverse_dir(d), 23.0),
            None
        );
    }

    #[test]
    fn ordered_bits_order_like_total_cmp() {
        let xs = [
            f32::NEG_INFINITY,
            -f32::MAX,
            -3.5e30,
            -2.5,
            -1.0,
            -f32::MIN_POSITIVE,
            -1e-45,
            -0.0,
            0.0,
            1e-45,
            f32::MIN_POSITIVE,
            0.25,
            1.0,
            2.5,
            7.0e20,
            f32::MAX,
            f32::INFINITY,
        ];
        for x in xs {
            assert_eq!(from_ordered_bits(ordered_bits(x)).to_bits(), x.to_bits());
            for y in xs {
                assert_eq!(
                    ordered_bits(x).cmp(&ordered_bits(y)),
                    x.total_cmp(&y),
                    "{x} {y}"
                );
            }
        }
        assert_eq!(ordered_bits(-0.0 + 0.0), ordered_bits(0.0));
    }

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

    #[test]
    fn checks_refuse_bad_values() {
        assert!(check_sphere(Vec3::ZERO, 0.0).is_ok());
        assert_eq!(
            check_sphere(Vec3::ZERO, -1.0),
            Err(Error::NegativeRadius(-1.0))
        );
        assert!(matches!(
            check_sphere(Vec3::new(f32::NAN, 0.0, 0.0), 1.0),
            Err(Error::NonFinite { what: "center", .. })
        ));
        assert!(matches!(
            check_sphere(Vec3::ZERO, f32::INFINITY),
            Err(Error::NonFinite { what: "radius", .. })
        ));
        assert!(matches!(
            Aabb::try_new(Vec3::ONE, Vec3::ZERO),
            Err(Error::InvertedAabb { .. })
        ));
        assert!(matches!(
            Aabb::try_new(Vec3::ZERO, Vec3::splat(f32::INFINITY)),
            Err(Error::NonFinite {
                what: "aabb.max",
                ..
            })
        ));
        assert!(!ray_is_valid(Vec3::ZERO, Vec3::X, f32::NAN));
        assert!(!ray_is_valid(Vec3::ZERO, Vec3::X, -1.0));
    }
}
