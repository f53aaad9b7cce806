//! [`Config`]: the settings of a [`BroadPhase`](super::BroadPhase), their defaults and checks.

use crate::bvh::BvhConfig;
use crate::geom;
use crate::octree::Placement;
use crate::{Aabb, Error};

/// Settings of a [`BroadPhase`](super::BroadPhase). Every field has a default, and the defaults are the fast
/// choice for every kind of world: nothing here needs tuning for speed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Config {
    /// A hint of the region the spheres will occupy, in metres (finite, `min < max`), or
    /// `None` (the default): the octree's region follows the spheres either way
    /// ([`Octree::growing`](crate::Octree::growing)), and its depth follows their radii. A
    /// right hint spares the re-roots of a world that spreads into it; a wrong one costs at
    /// most a re-root (a hint too wide for the spheres' cells, or far from them, is ignored).
    pub bounds: Option<Aabb>,
    /// Which node of the octree a sphere lives in ([`Placement`]).
    pub octree_placement: Placement,
    /// Every box is grown by this many metres on each side before pairing; `>= 0`. With the
    /// default 0 the pair set equals the brute-force set exactly.
    pub margin: f32,
    /// The dynamic bodies' BVH is rebuilt when its SAH cost after a refit exceeds this many
    /// times its cost at its last build; finite, `>= 1`.
    pub rebuild_threshold: f32,
    /// A fixed skin in metres (finite, `>= 0`) instead of the adaptive one; 0 (the
    /// default) lets every proxy's skin follow how far it moves per step. The pairs are the
    /// same either way; only the cost changes.
    pub skin: f32,
    /// Which passes a step may run: [`Passes::Adaptive`] (the default) picks the cheaper one
    /// each step; the others force one, for comparisons and tests.
    pub passes: Passes,
}

/// Which passes [`BroadPhase::step`](super::BroadPhase::step) may run. The pair lists are the same whichever runs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Passes {
    /// Each step runs whichever pass (see
    /// [`BroadPhase`](super::BroadPhase#the-passes-and-the-incremental-regime)) its work
    /// estimate says is cheaper: a world where few proxies move, or a sparse one in motion,
    /// runs the incremental pass; a dense world in motion runs the full pass; a world at rest
    /// runs none.
    #[default]
    Adaptive,
    /// Every step runs the full pass (no fat boxes, no candidates).
    Full,
    /// Every step after the first runs the incremental pass.
    Incremental,
}

impl Default for Config {
    /// No region hint, loose placement, margin 0, rebuild threshold 1.5, adaptive skins
    /// (skin 0), adaptive passes.
    fn default() -> Self {
        Self {
            bounds: None,
            octree_placement: Placement::Loose,
            margin: 0.0,
            rebuild_threshold: 1.5,
            skin: 0.0,
            passes: Passes::Adaptive,
        }
    }
}

impl Config {
    /// `Ok` if every field is in its documented range, else the first offending field.
    pub fn validate(&self) -> Result<(), Error> {
        if let Some(hint) = &self.bounds {
            geom::check_bounds(hint)?;
        }
        if !(self.margin.is_finite() && self.margin >= 0.0) {
            return Err(Error::InvalidConfig {
                what: "margin",
                value: self.margin,
            });
        }
        if !(self.rebuild_threshold.is_finite() && self.rebuild_threshold >= 1.0) {
            return Err(Error::InvalidConfig {
                what: "rebuild_threshold",
                value: self.rebuild_threshold,
            });
        }
        if !(self.skin.is_finite() && self.skin >= 0.0) {
            return Err(Error::InvalidConfig {
                what: "skin",
                value: self.skin,
            });
        }
        Ok(())
    }

    /// The configuration of both BVHs: much fuller leaves than the standalone default, since
    /// the pair passes are the hot path and a leaf pair's bit-mask kernel (up to 64 boxes a
    /// side) is cheaper than the node pairs it replaces.
    pub(super) fn bvh_config(&self) -> BvhConfig {
        BvhConfig {
            rebuild_threshold: self.rebuild_threshold,
            max_leaf_size: BVH_LEAF_SIZE,
            traversal_cost: BVH_TRAVERSAL_COST,
            ..BvhConfig::default()
        }
    }
}

/// The broadphase's BVHs' largest leaf, in boxes (`BvhConfig::max_leaf_size`).
const BVH_LEAF_SIZE: u32 = 32;
/// The broadphase's BVHs' node visit cost, in box tests (`BvhConfig::traversal_cost`): high
/// enough that SAH fills leaves up to [`BVH_LEAF_SIZE`].
const BVH_TRAVERSAL_COST: f32 = 16.0;
