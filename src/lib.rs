//! broadleaf: a broadphase for physics loops.
//!
//! Each physics step, a broadphase answers "which pairs of objects might touch?". broadleaf
//! answers it **exactly** — a pair is reported iff the two boxes overlap (closed intervals:
//! touching boxes overlap) — and reports the pairs that started and stopped overlapping since
//! the last step.
//!
//! # Which structure when
//! - **[`BroadPhase`]** — start here. One key space for spheres and rigid bodies: each sphere
//!   lives in an [`Octree`] ([`BroadPhase::octree`]), each body in a dynamic or a static
//!   [`Bvh`] ([`BroadPhase::bvh`]), all under the broadphase's keys. One sorted pair list per
//!   [`BroadPhase::step`], plus `added` / `removed` events, collision groups
//!   ([`CollisionGroups`]), and queries of the shapes as given: boxes, spheres, rays, sphere
//!   casts and the nearest proxies. It adapts by itself to how much of the world moves: each
//!   step runs the cheaper of [two passes](BroadPhase#the-passes-and-the-incremental-regime);
//!   [`BroadPhase::stats`] says which ran. Nothing in [`Config`] needs tuning for speed.
//! - **[`Octree`]** — many moving spheres, on their own. A top-down preallocated octree
//!   (Ericson, *Real-Time Collision Detection* 7.3), and a move that keeps the node costs one
//!   store. [`Octree::growing`] (the [`BroadPhase`]'s) follows its spheres: its region and
//!   depth are derived from them and re-rooted when they leave, so no world is outside it;
//!   [`Octree::new`] subdivides a region you give, for good. Two [`Placement`]s: `Strict` (the standalone
//!   default) keeps a sphere in the deepest node whose split planes it does not straddle;
//!   `Loose` (RTCD 7.3.6, looseness 2; the [`BroadPhase`] default) puts every sphere at the
//!   level its radius fits (for a fixed region, give a depth whose deepest cells are about a
//!   sphere's diameter).
//! - **[`Bvh`]** — rigid bodies of any shape and size, given by their world AABBs, on their own.
//!   A binned-SAH bounding-volume hierarchy in a flat depth-first array, refitted bottom-up and
//!   rebuilt when its quality degrades. Use it for static geometry queries too.
//! - **[`brute`]** — the O(n²) reference every test compares against; use it to check your own
//!   scenes.
//!
//! # The frame loop
//! ```
//! use broadleaf::{Aabb, BodyKind, BroadPhase, Config, Vec3};
//!
//! let mut bp = BroadPhase::new(Config::default());
//! let floor = Aabb::new(Vec3::new(-50.0, -1.0, -50.0), Vec3::new(50.0, 0.0, 50.0));
//! let floor = bp.insert_body(floor, BodyKind::Static)?;
//! let ball = bp.insert_sphere(Vec3::new(0.0, 2.0, 0.0), 0.5)?;
//!
//! for frame in 0..120 {
//!     let y = 2.0 - 0.02 * frame as f32;             // the physics moves the ball
//!     bp.update_sphere(ball, Vec3::new(0.0, y, 0.0), 0.5)?;
//!     bp.step();
//!     for pair in bp.added() {
//!         // narrow phase: a new contact candidate (pair.a < pair.b), its shapes at hand
//!         assert_eq!((pair.a, pair.b), (floor.min(ball), floor.max(ball)));
//!         assert!(bp.shape(pair.b).is_some());
//!     }
//! }
//! # Ok::<(), broadleaf::Error>(())
//! ```
//!
//! # Queries
//! Every query comes in two forms. The plain one ([`BroadPhase::query_aabb`],
//! [`BroadPhase::query_sphere`], [`BroadPhase::cast_ray`], [`BroadPhase::cast_sphere`],
//! [`BroadPhase::nearest`]) sees every proxy. The engine's one ([`BroadPhase::query_aabb_with`],
//! [`BroadPhase::query_sphere_with`], [`BroadPhase::cast_ray_with`],
//! [`BroadPhase::cast_sphere_with`], [`BroadPhase::nearest_into`]) takes a [`QueryFilter`]
//! (collision groups, a key to exclude, a predicate), gives casts the nearest hit the filter
//! passes, lets a visitor stop with [`ControlFlow::Break`](core::ops::ControlFlow), and fills
//! a buffer of the caller's instead of allocating. Both are exact, as the shapes were given.
//!
//! An update only stores the new shape; [`BroadPhase::step`] moves the proxies in the
//! structures, all at once and in slot order. Queries between an update and the next step
//! still see every latest shape: the structures skip the proxies updated since the last step
//! and the query tests those proxies' new shapes one by one, so it costs one test per proxy
//! updated since then (nothing once the step has run). Query after the step where you can.
//! One kind of update is applied at once: in the incremental regime (see [`BroadPhase`]), a
//! proxy that stays in its fat box and moves too little to change any pair (a resting ball
//! sent again) needs nothing of the step, and its update applies it, while the updates since
//! the last step come in ascending key order (the order `ProxyKey`s sort in; in another
//! order the step applies them in slot order, which costs less than the scattered reads the
//! calls would make); queries see it as they see any applied proxy. An engine that sends a
//! settling world every frame gains by sending its batch sorted by key.
//! [`Octree`] and [`Bvh`] have the stopping form too, without a filter (`query_aabb_with`,
//! `query_sphere_with`).
//! ```
//! use broadleaf::{BroadPhase, Config, QueryFilter, Vec3};
//! use core::ops::ControlFlow;
//!
//! let mut bp = BroadPhase::new(Config::default());
//! let me = bp.insert_sphere(Vec3::ZERO, 1.0)?;
//! let other = bp.insert_sphere(Vec3::new(1.5, 0.0, 0.0), 1.0)?;
//! let not_me = QueryFilter::new().exclude(me);
//! // Is anything but me within 2 m? Stop at the first.
//! let mut found = None;
//! let flow = bp.query_sphere_with(Vec3::ZERO, 2.0, &not_me, |key| {
//!     found = Some(key);
//!     ControlFlow::Break(())
//! });
//! assert!(flow.is_break() && found == Some(other));
//! let mut near = Vec::with_capacity(16);            // reused from call to call
//! bp.nearest_into(Vec3::ZERO, 4, &not_me, &mut near);
//! assert_eq!(near, [(other, 0.5)]);
//! # Ok::<(), broadleaf::Error>(())
//! ```
//!
//! # Guarantees
//! - **Exact pairs.** With `Config::margin == 0` the pair set equals [`brute::pairs`] over
//!   the current boxes: nothing missed, nothing extra. A margin grows every box first. Static
//!   bodies never pair with each other, nor two proxies whose [`CollisionGroups`] do not
//!   allow it (bevy_rapier's rule).
//! - **Deterministic.** [`BroadPhase::pairs`], [`BroadPhase::added`] and [`BroadPhase::removed`] are sorted by `(a, b)` with keys ordered
//!   by slot; the same operations in the same order give bit-identical lists on every run.
//! - **Bad input is refused, never half-applied.** NaN or infinite coordinates, a negative
//!   radius, an inverted box or a stale key give an [`Error`] and leave the structure exactly
//!   as it was. No position is outside: the octree's region follows the spheres.
//! - **No allocation per step** in steady state: every buffer is kept and reused, and lists
//!   that swing from step to step grow ahead of their peaks.
//!
//! # Keys
//! [`ProxyKey`] is a slotmap key: a removed proxy's key is refused forever after
//! ([`Error::UnknownProxy`]). Keys carry no instance tag, so a key of *another* broadphase is
//! refused only if it names no live proxy here; keep keys with the instance that issued them.
//!
//! # Features
//! - `rapier`: interop with rapier3d 0.36 (`broadleaf::rapier`): mirror a collider set into a
//!   `BroadPhase` and compare pair sets with rapier's broadphase.
//! - `profiler`: `rapier` with rapier's timing counters, for the comparisons that time it.
//! - `fixtures`: benchmark and test support (`broadleaf::fixtures`: scenes, a small physics
//!   loop, rapier worlds); not part of the broadphase.
//! - `parallel`: [`BroadPhase::step`] runs on rayon's current thread pool (the one a caller's
//!   `ThreadPool::install` runs in, else the global pool), with the same `pairs`, `added`,
//!   `removed` and keys at any thread count, bit for bit. It splits only with more than one
//!   thread and at least 10 000 spheres or 16 384 dynamic bodies; outside the incremental
//!   regime the whole step is then one job on the pool (a caller outside the pool hands it
//!   over once, and each split phase starts on a worker already awake). The octree's pass
//!   splits in chunks, the BVH passes hand their subtree pairs to tasks, the pair sort and the
//!   event diff split by key range; the incremental pass stays serial. The step's first act,
//!   applying the updates, splits its spheres over the pool under the same conditions when at
//!   least one proxy in eight was updated: each task computes its spheres' boxes and
//!   placements and stores those that stay in their octree node; the relinks and the bodies'
//!   leaves stay serial. On one thread it allocates nothing per step in steady state; with
//!   more, rarely (per-task lists growing to a new peak, and, for a caller outside the pool,
//!   rayon's job queue about once in 63 steps).
//! - `serde`: [`BroadPhase`] implements serde's `Serialize` and `Deserialize`, for snapshots
//!   in any serde format. A snapshot holds the [`Config`], the step clock, every slot's
//!   version with each live proxy's shape and [`CollisionGroups`], the free and quarantined
//!   slots in order, and the previous step's pairs; the octree, the BVHs, fat boxes and
//!   candidates are derived state, rebuilt on load (the first step after it runs a full
//!   pass). A restored broadphase continues bit-identically: the same later operations give
//!   the same keys and the same `pairs`, `added` and `removed`. A snapshot is checked as
//!   input: a damaged one gives a deserialisation error naming what is wrong, or, if it is
//!   still consistent (say, an edited coordinate), a broadphase whose invariants hold; never a
//!   panic.
#![forbid(unsafe_code)]
#![warn(missing_docs)]

mod broadphase;
pub mod brute;
pub mod bvh;
mod error;
#[cfg(feature = "fixtures")]
pub mod fixtures;
#[doc(hidden)]
pub mod geom;
pub mod octree;
pub mod pair;
mod radix;
#[cfg(feature = "rapier")]
pub mod rapier;
#[cfg(any(test, feature = "fixtures"))]
mod rng;
mod search;
mod sweep;
#[cfg(test)]
mod test_geom;

pub use broadphase::{
    BodyKind, BroadPhase, CollisionGroups, Config, Pass, Passes, QueryFilter, QueryPredicate,
    Shape, StepStats,
};
pub use bvh::{Bvh, BvhConfig, SplitMethod};
pub use error::{BatchError, Error};
pub use geom::Aabb;
pub use glam::Vec3;
pub use octree::{Octree, Placement};
pub use pair::{Pair, ProxyKey};

/// The README's code blocks, compiled and run as doctests.
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
struct ReadmeDoctests;
