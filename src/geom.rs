//! Axis-aligned boxes, the SIMD box of the hot loops, the ray–box slab test, and the input
//! checks every entry point runs before it touches a structure; the exact shape tests are in
//! `exact` (re-exported here).

use crate::error::Error;
use glam::{Vec3, Vec3A};

mod exact;
pub use exact::*;

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
