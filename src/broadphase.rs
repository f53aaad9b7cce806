//! `BroadPhase`: spheres and rigid bodies behind one set of keys, one sorted pair list per step,
//! and the pairs that started and stopped overlapping since the last step.

use crate::geom::{self, check_aabb, check_sphere};
use crate::pair::{self, Pair, ProxyKey};
use crate::{Aabb, Error, Vec3, brute};
use slotmap::SlotMap;

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
    /// A sphere, kept in the octree.
    Sphere {
        /// Centre in world space.
        center: Vec3,
        /// Radius, `>= 0`.
        radius: f32,
    },
    /// A rigid body given by its world AABB, kept in a BVH.
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

    fn is_static(&self) -> bool {
        matches!(
            self,
            Shape::Body {
                kind: BodyKind::Static,
                ..
            }
        )
    }
}

/// Settings of a [`BroadPhase`]. Every field has a default; see each field for its range.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Config {
    /// The region the octree subdivides, in metres. Spheres outside it are still kept and
    /// paired correctly, only less efficiently. Must be finite with `min < max`.
    pub bounds: Aabb,
    /// Subdivision levels of the octree below the root, `0..=octree::MAX_DEPTH`. The deepest
    /// cells should be a few sphere diameters wide.
    pub octree_depth: u32,
    /// Every box is grown by this many metres on each side before pairing; `>= 0`. With the
    /// default 0 the pair set equals the brute-force set exactly.
    pub margin: f32,
    /// The dynamic BVH is rebuilt when its SAH cost after a refit exceeds this many times its
    /// cost at build; finite, `>= 1`.
    pub rebuild_threshold: f32,
}

impl Default for Config {
    /// Bounds ±512 m, octree depth 7 (deepest cells 8 m), margin 0, rebuild threshold 1.5.
    fn default() -> Self {
        Self {
            bounds: Aabb::new(Vec3::splat(-512.0), Vec3::splat(512.0)),
            octree_depth: 7,
            margin: 0.0,
            rebuild_threshold: 1.5,
        }
    }
}

impl Config {
    /// `Ok` if every field is in its documented range, else the first offending field.
    pub fn validate(&self) -> Result<(), Error> {
        geom::check_bounds(&self.bounds)?;
        if self.octree_depth > crate::octree::MAX_DEPTH {
            return Err(Error::DepthOutOfRange(self.octree_depth));
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
        Ok(())
    }
}

/// The result of one [`BroadPhase::step`]: all three lists sorted by `(a, b)`.
#[derive(Clone, Copy, Debug)]
pub struct StepPairs<'a> {
    /// Every pair whose (margin-grown) boxes overlap now.
    pub pairs: &'a [Pair],
    /// Pairs in `pairs` that were not in the previous step's list.
    pub added: &'a [Pair],
    /// Pairs of the previous step's list that are not in `pairs` (including every pair of a
    /// proxy removed since).
    pub removed: &'a [Pair],
}

/// The broadphase of a physics step: insert spheres and bodies, move them, and call
/// [`BroadPhase::step`] once per frame for the overlapping pairs and the pair events.
#[derive(Clone, Debug)]
pub struct BroadPhase {
    config: Config,
    proxies: SlotMap<ProxyKey, Shape>,
    pairs: Vec<Pair>,
    prev: Vec<Pair>,
    added: Vec<Pair>,
    removed: Vec<Pair>,
    scratch: Vec<brute::Proxy>,
}

impl BroadPhase {
    /// A broadphase with `config`. Fields out of range are replaced by their nearest valid
    /// value (depth clamped, bad bounds by the default bounds, a bad margin by 0, a bad
    /// threshold by 1.5); use [`BroadPhase::try_new`] to be told instead.
    #[must_use]
    pub fn new(config: Config) -> Self {
        let d = Config::default();
        let fixed = Config {
            bounds: if geom::check_bounds(&config.bounds).is_ok() {
                config.bounds
            } else {
                d.bounds
            },
            octree_depth: config.octree_depth.min(crate::octree::MAX_DEPTH),
            margin: if config.margin.is_finite() && config.margin >= 0.0 {
                config.margin
            } else {
                0.0
            },
            rebuild_threshold: if config.rebuild_threshold.is_finite()
                && config.rebuild_threshold >= 1.0
            {
                config.rebuild_threshold
            } else {
                d.rebuild_threshold
            },
        };
        Self::build(fixed)
    }

    /// A broadphase with `config`, or the first field out of range.
    pub fn try_new(config: Config) -> Result<Self, Error> {
        config.validate()?;
        Ok(Self::build(config))
    }

    fn build(config: Config) -> Self {
        Self {
            config,
            proxies: SlotMap::with_key(),
            pairs: Vec::new(),
            prev: Vec::new(),
            added: Vec::new(),
            removed: Vec::new(),
            scratch: Vec::new(),
        }
    }

    /// The configuration in force (after [`BroadPhase::new`]'s corrections).
    #[must_use]
    pub fn config(&self) -> &Config {
        &self.config
    }

    /// Adds a sphere; it pairs from the next [`BroadPhase::step`] on. `Err` on a non-finite
    /// centre or radius or a negative radius. A sphere outside `Config::bounds` is accepted.
    pub fn insert_sphere(&mut self, center: Vec3, radius: f32) -> Result<ProxyKey, Error> {
        check_sphere(center, radius)?;
        Ok(self.proxies.insert(Shape::Sphere { center, radius }))
    }

    /// Adds a body by its world AABB. `Err` on a non-finite or inverted box.
    pub fn insert_body(&mut self, aabb: Aabb, kind: BodyKind) -> Result<ProxyKey, Error> {
        check_aabb(&aabb)?;
        Ok(self.proxies.insert(Shape::Body { aabb, kind }))
    }

    /// Moves or resizes a sphere. `Err(UnknownProxy)` for a stale key, `Err(WrongKind)` for a
    /// body's key, or a geometry error; on `Err` nothing changes.
    pub fn update_sphere(&mut self, key: ProxyKey, center: Vec3, radius: f32) -> Result<(), Error> {
        check_sphere(center, radius)?;
        match self.proxies.get_mut(key) {
            Some(shape @ Shape::Sphere { .. }) => {
                *shape = Shape::Sphere { center, radius };
                Ok(())
            }
            Some(Shape::Body { .. }) => Err(Error::WrongKind),
            None => Err(Error::UnknownProxy),
        }
    }

    /// Sets a body's world AABB (its kind stays). `Err(UnknownProxy)` for a stale key,
    /// `Err(WrongKind)` for a sphere's key, or a geometry error; on `Err` nothing changes.
    pub fn update_body(&mut self, key: ProxyKey, aabb: Aabb) -> Result<(), Error> {
        check_aabb(&aabb)?;
        match self.proxies.get_mut(key) {
            Some(Shape::Body { aabb: a, .. }) => {
                *a = aabb;
                Ok(())
            }
            Some(Shape::Sphere { .. }) => Err(Error::WrongKind),
            None => Err(Error::UnknownProxy),
        }
    }

    /// Removes a proxy; its pairs are reported in `removed` at the next step.
    /// `Err(UnknownProxy)` for a stale key.
    pub fn remove(&mut self, key: ProxyKey) -> Result<(), Error> {
        self.proxies
            .remove(key)
            .map(|_| ())
            .ok_or(Error::UnknownProxy)
    }

    /// Number of live proxies.
    #[must_use]
    pub fn len(&self) -> usize {
        self.proxies.len()
    }

    /// True if there are no proxies.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.proxies.is_empty()
    }

    /// The proxy's box as given by the user (without the margin), or `None` for a stale key.
    #[must_use]
    pub fn aabb(&self, key: ProxyKey) -> Option<Aabb> {
        self.proxies.get(key).map(Shape::aabb)
    }

    /// What the proxy is, or `None` for a stale key.
    #[must_use]
    pub fn shape(&self, key: ProxyKey) -> Option<Shape> {
        self.proxies.get(key).copied()
    }

    /// Computes this step's pairs and their difference with the previous step's.
    pub fn step(&mut self) -> StepPairs<'_> {
        core::mem::swap(&mut self.prev, &mut self.pairs);
        let margin = self.config.margin;
        self.scratch.clear();
        self.scratch
            .extend(self.proxies.iter().map(|(key, s)| brute::Proxy {
                key,
                aabb: s.aabb().grown(margin),
                is_static: s.is_static(),
            }));
        self.pairs = brute::sweep_pairs(&self.scratch);
        pair::diff(&self.prev, &self.pairs, &mut self.added, &mut self.removed);
        StepPairs {
            pairs: &self.pairs,
            added: &self.added,
            removed: &self.removed,
        }
    }

    /// Calls `f` with every proxy whose (margin-grown) box overlaps `aabb`; nothing for a
    /// non-finite or inverted query box.
    pub fn query_aabb(&self, aabb: &Aabb, mut f: impl FnMut(ProxyKey)) {
        if check_aabb(aabb).is_err() {
            return;
        }
        let margin = self.config.margin;
        for (key, s) in &self.proxies {
            if s.aabb().grown(margin).overlaps(aabb) {
                f(key);
            }
        }
    }

    /// The nearest proxy hit by the segment `origin + t·dir`, `t ∈ [0, max_t]`, with its `t`
    /// (in units of `dir`, which need not be unit length). Spheres are hit as spheres, bodies
    /// as their boxes; the margin is ignored. `None` for a non-finite ray or `max_t < 0`.
    #[must_use]
    pub fn cast_ray(&self, origin: Vec3, dir: Vec3, max_t: f32) -> Option<(ProxyKey, f32)> {
        if !geom::ray_is_valid(origin, dir, max_t) {
            return None;
        }
        let inv = geom::inverse_dir(dir);
        self.proxies
            .iter()
            .filter_map(|(key, s)| {
                let t = match *s {
                    Shape::Sphere { center, radius } => {
                        geom::ray_sphere(origin, dir, center, radius, max_t)
                    }
                    Shape::Body { aabb, .. } => aabb.ray_entry(origin, inv, max_t),
                };
                t.map(|t| (key, t))
            })
            .min_by(|x, y| x.1.total_cmp(&y.1).then(x.0.cmp(&y.0)))
    }
}
