//! broadleaf: a broadphase for physics loops.
#![forbid(unsafe_code)]
#![warn(missing_docs)]

mod broadphase;
pub mod brute;
pub mod bvh;
mod error;
pub mod geom;
pub mod octree;
pub mod pair;
pub mod scene;
pub mod sim;

pub use broadphase::{BodyKind, BroadPhase, Config, Shape, StepPairs};
pub use error::Error;
pub use geom::Aabb;
pub use glam::Vec3;
pub use pair::{Pair, ProxyKey};
