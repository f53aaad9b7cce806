//! The top-down preallocated octree for moving spheres (Ericson, *Real-Time Collision
//! Detection* 7.3).

/// The deepest octree accepted by `Octree::new`: levels `0..=MAX_DEPTH`.
pub const MAX_DEPTH: u32 = 10;
