//! What a proxy is ([`Shape`], [`BodyKind`]) and whom it may pair with ([`CollisionGroups`]).

use super::fat;
use crate::{Aabb, Vec3};

/// Whether a body moves. Static bodies never pair with each other.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum BodyKind {
    /// A moving body: its box is expected to change every step.
    Dynamic,
    /// A body that does not move (walls, floors, terrain); it may still be updated, at the
    /// price of a rebuild of the static tree.
    Static,
}

/// What a proxy is. `Sphere` boxes are `center ± radius`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Shape {
    /// A sphere.
    Sphere {
        /// Centre in world space.
        center: Vec3,
        /// Radius, `>= 0`.
        radius: f32,
    },
    /// A rigid body given by its world AABB.
    Body {
        /// The body's world box.
        aabb: Aabb,
        /// Dynamic or static.
        kind: BodyKind,
    },
}

impl Shape {
    /// The box as the user gave it (no margin).
    #[must_use]
    pub fn aabb(&self) -> Aabb {
        match *self {
            Shape::Sphere { center, radius } => Aabb::from_center_radius(center, radius),
            Shape::Body { aabb, .. } => aabb,
        }
    }

    /// True for a static body: two of them never pair.
    #[must_use]
    pub fn is_static(&self) -> bool {
        matches!(
            self,
            Shape::Body {
                kind: BodyKind::Static,
                ..
            }
        )
    }

    /// The box the broadphase pairs: a sphere's `center ± (radius + margin)` (a radius sum
    /// that overflows stays at `f32::MAX`), a body's box grown by `margin` on every side
    /// (faces that overflow stay at `±f32::MAX`, which overlaps exactly what `±∞` would).
    /// (For a sphere this is not always bit-equal to `aabb().grown(margin)`, which rounds
    /// twice.)
    #[must_use]
    pub fn grown_aabb(&self, margin: f32) -> Aabb {
        fat::grown(*self, margin).aabb.aabb()
    }
}

/// Which proxies may pair: a pair is reported only if
/// `a.memberships & b.filter != 0 && b.memberships & a.filter != 0` (bevy_rapier's rule).
/// The default is every group in both masks, so every pair is allowed.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct CollisionGroups {
    /// The groups this proxy belongs to, one bit each.
    pub memberships: u32,
    /// The groups this proxy may pair with.
    pub filter: u32,
}

impl Default for CollisionGroups {
    fn default() -> Self {
        Self::ALL
    }
}

impl CollisionGroups {
    /// Member of every group, pairs with every group.
    pub const ALL: CollisionGroups = CollisionGroups {
        memberships: u32::MAX,
        filter: u32::MAX,
    };

    /// True if proxies with `self` and `other` may pair.
    #[inline]
    #[must_use]
    pub fn allows(self, other: CollisionGroups) -> bool {
        self.memberships & other.filter != 0 && other.memberships & self.filter != 0
    }
}

/// Writes a sphere's new centre and radius into its shape. They arrive as values and are
/// written field by field: a whole `Shape` built on the stack and copied with wide loads
/// stalls on the store forwarding of its narrow stores.
#[inline]
pub(super) fn write_sphere(shape: &mut Shape, center: Vec3, radius: f32) {
    match shape {
        Shape::Sphere {
            center: c,
            radius: r,
        } => (*c, *r) = (center, radius),
        other => *other = Shape::Sphere { center, radius },
    }
}
