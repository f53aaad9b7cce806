//! The one error type of the crate: every refusal names what was wrong and the value that was.

use core::fmt;
use glam::Vec3;

/// Why an operation was refused. When a function returns `Err`, the structure it was called on
/// is exactly as it was before the call.
#[derive(Clone, Copy, Debug, PartialEq)]
#[non_exhaustive]
pub enum Error {
    /// A coordinate or a radius was NaN or infinite; `what` names the argument.
    NonFinite {
        /// The argument that held the bad value, e.g. `"center"` or `"aabb.min"`.
        what: &'static str,
        /// The offending vector (a radius is reported in `x`).
        value: Vec3,
    },
    /// A sphere radius below zero.
    NegativeRadius(f32),
    /// An AABB with `min > max` on some axis.
    InvertedAabb {
        /// The box's `min` corner as given.
        min: Vec3,
        /// The box's `max` corner as given.
        max: Vec3,
    },
    /// The key names no live proxy of this structure: removed, never issued, or from another
    /// instance whose slot this instance does not hold.
    UnknownProxy,
    /// The key names a live proxy of another kind, e.g. `update_sphere` on a body.
    WrongKind,
    /// An octree depth deeper than the deepest the octree supports.
    DepthOutOfRange {
        /// The depth given.
        depth: u32,
        /// The deepest depth accepted ([`octree::MAX_DEPTH`](crate::octree::MAX_DEPTH)).
        max: u32,
    },
    /// World bounds that are not finite or have no volume.
    InvalidBounds {
        /// The bounds' `min` corner as given.
        min: Vec3,
        /// The bounds' `max` corner as given.
        max: Vec3,
    },
    /// A configuration value outside its documented range; `what` names the field.
    InvalidConfig {
        /// The field, e.g. `"margin"`.
        what: &'static str,
        /// The value given.
        value: f32,
    },
    /// No room for another entry: an `Octree` holds `u32::MAX - 1` spheres, a `Bvh`
    /// `u32::MAX - 1` boxes (removed ones count until its next rebuild), or a `BroadPhase`
    /// has `2^31` slots and none free to reuse.
    Full,
    /// Two slices that pair up entry by entry differ in length (e.g. the keys and the centres
    /// of [`BroadPhase::update_centers`](crate::BroadPhase::update_centers)).
    LengthMismatch {
        /// The length of the first slice (the keys).
        keys: usize,
        /// The length of the second slice (the values).
        values: usize,
    },
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Error::NonFinite { what, value } => {
                write!(f, "{what} is not finite: {value}")
            }
            Error::NegativeRadius(r) => write!(f, "radius is negative: {r}"),
            Error::InvertedAabb { min, max } => {
                write!(f, "aabb is inverted (min > max): min {min}, max {max}")
            }
            Error::UnknownProxy => write!(f, "key names no live proxy of this structure"),
            Error::WrongKind => write!(f, "key names a proxy of another kind"),
            Error::DepthOutOfRange { depth, max } => {
                write!(f, "octree depth {depth} is out of range 0..={max}")
            }
            Error::InvalidBounds { min, max } => {
                write!(
                    f,
                    "bounds must be finite with min < max: min {min}, max {max}"
                )
            }
            Error::InvalidConfig { what, value } => {
                write!(f, "config field {what} is out of range: {value}")
            }
            Error::Full => write!(f, "structure is full (index space exhausted)"),
            Error::LengthMismatch { keys, values } => {
                write!(f, "{keys} keys but {values} values")
            }
        }
    }
}

impl std::error::Error for Error {}

/// A refused batch ([`BroadPhase::update_spheres`](crate::BroadPhase::update_spheres),
/// [`BroadPhase::update_centers`](crate::BroadPhase::update_centers),
/// [`BroadPhase::update_bodies`](crate::BroadPhase::update_bodies),
/// [`BroadPhase::insert_spheres`](crate::BroadPhase::insert_spheres)): the first bad entry's
/// index and why (for slices of different lengths, the first index only one of them has). When a batch is refused, nothing of it was applied.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BatchError {
    /// Index of the first refused entry in the batch.
    pub index: usize,
    /// Why that entry was refused.
    pub error: Error,
}

impl fmt::Display for BatchError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "batch entry {}: {}", self.index, self.error)
    }
}

impl std::error::Error for BatchError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        Some(&self.error)
    }
}
