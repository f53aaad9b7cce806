//! `BroadPhase`: spheres and rigid bodies behind one set of keys, one sorted pair list per step,
//! and the pairs that started and stopped overlapping since the last step.

mod cache;

use crate::bvh::{Bvh, BvhConfig};
use crate::geom::SimdBox as PrimBox;
use crate::geom::{self, check_aabb, check_sphere};
use crate::octree::{Octree, Placement};
use crate::pair::{self, Pair, PairSorter, ProxyKey};
use crate::{Aabb, BatchError, Error, Vec3};
use cache::PairCache;
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

    /// The box the broadphase pairs: a sphere's `center ± (radius + margin)`, a body's box
    /// grown by `margin` on every side (faces that overflow stay at `±f32::MAX`, which
    /// overlaps exactly what `±∞` would). (For a sphere this is not always bit-equal to
    /// `aabb().grown(margin)`, which rounds twice.)
    #[must_use]
    pub fn grown_aabb(&self, margin: f32) -> Aabb {
        match *self {
            Shape::Sphere { center, radius } => Aabb::from_center_radius(center, radius + margin),
            Shape::Body { aabb, .. } => finite_grown(&aabb, margin),
        }
    }
}

/// Settings of a [`BroadPhase`]. Every field has a default; see each field for its range.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Config {
    /// The region the octree subdivides, in metres. Spheres outside it are still kept and
    /// paired correctly, only less efficiently. Must be finite with `min < max`.
    pub bounds: Aabb,
    /// Subdivision levels of the octree below the root, `0..=octree::MAX_DEPTH`. With
    /// [`Placement::Strict`] the deepest cells should be about two sphere diameters wide
    /// ([`crate::octree::depth_for`]), with [`Placement::Loose`] about one
    /// ([`crate::octree::depth_for_loose`]).
    pub octree_depth: u32,
    /// How the octree places spheres: [`Placement::Strict`] (the default, RTCD 7.3) or
    /// [`Placement::Loose`] (loose octree, looseness 2; usually faster for many similar moving
    /// spheres).
    pub octree_placement: Placement,
    /// Every box is grown by this many metres on each side before pairing; `>= 0`. With the
    /// default 0 the pair set equals the brute-force set exactly.
    pub margin: f32,
    /// The dynamic BVH is rebuilt when its SAH cost after a refit exceeds this many times its
    /// cost at build; finite, `>= 1`.
    pub rebuild_threshold: f32,
    /// The pair cache's skin in metres, finite and `>= 0`; 0 (the default) turns the cache
    /// off. With a skin the structures hold every box grown by it (a "fat" box, placed
    /// again only when the exact box leaves it), the broadphase keeps the pairs of fat
    /// boxes as candidates, and each step re-tests only the candidates' exact boxes. The
    /// pairs stay exact (the same lists as without the cache); what changes is the cost.
    /// Worth it when most objects move less than the skin per step (resting piles, stacks,
    /// slow crowds); for objects that cross their skin every few steps it is slower. Try 2–5 %
    /// of the typical object size (0.05 m was best for the 1 m spheres of the `pile` scene).
    pub skin: f32,
}

impl Default for Config {
    /// Bounds ±512 m, octree depth 7 (deepest cells 8 m), strict placement, margin 0, rebuild
    /// threshold 1.5, no pair cache (skin 0).
    fn default() -> Self {
        Self {
            bounds: Aabb::new(Vec3::splat(-512.0), Vec3::splat(512.0)),
            octree_depth: 7,
            octree_placement: Placement::Strict,
            margin: 0.0,
            rebuild_threshold: 1.5,
            skin: 0.0,
        }
    }
}

impl Config {
    /// `Ok` if every field is in its documented range, else the first offending field.
    pub fn validate(&self) -> Result<(), Error> {
        geom::check_bounds(&self.bounds)?;
        if self.octree_depth > crate::octree::MAX_DEPTH {
            return Err(Error::DepthOutOfRange {
                depth: self.octree_depth,
                max: crate::octree::MAX_DEPTH,
            });
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
    /// Every proxy as the user gave it (no margin); the key space of the whole broadphase.
    proxies: SlotMap<ProxyKey, Shape>,
    /// Spheres, stored with `radius + margin` (plus the skin with a pair cache).
    octree: Octree,
    /// Dynamic bodies, stored grown by the margin (plus the skin with a pair cache);
    /// refitted every step (with a pair cache: in a step after a change).
    dynamic: Bvh,
    /// Static bodies, stored grown like the dynamic ones; refitted only in a step after a
    /// change.
    statics: Bvh,
    /// True when a static body was inserted, updated or removed since the last step.
    statics_changed: bool,
    /// True when a dynamic body's stored box changed, or one was inserted or removed, since
    /// the last step.
    dynamic_changed: bool,
    /// The pair cache, with `Config::skin > 0`.
    cache: Option<PairCache>,
    pairs: Vec<Pair>,
    prev: Vec<Pair>,
    added: Vec<Pair>,
    removed: Vec<Pair>,
    /// Buffers of the pair sort.
    sorter: PairSorter,
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
            octree_placement: config.octree_placement,
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
            skin: if config.skin.is_finite() && config.skin >= 0.0 {
                config.skin
            } else {
                0.0
            },
        };
        Self::build(fixed)
    }

    /// A broadphase with `config`, or the first field out of range.
    pub fn try_new(config: Config) -> Result<Self, Error> {
        config.validate()?;
        Ok(Self::build(config))
    }

    /// Builds from a validated config: every structure's constructor succeeds on it.
    fn build(config: Config) -> Self {
        // Fuller leaves than the standalone default (8, traversal cost 4): the pair passes
        // are the hot path here, and a leaf's all-pairs loop is cheaper than the node pairs
        // it replaces (bodies 10k step: about 325 -> 310 ns/object, wall-clock medians).
        let bvh_config = BvhConfig {
            rebuild_threshold: config.rebuild_threshold,
            max_leaf_size: 16,
            traversal_cost: 8.0,
            ..BvhConfig::default()
        };
        let octree =
            Octree::with_placement(config.bounds, config.octree_depth, config.octree_placement);
        let (dynamic, statics) = (Bvh::new(bvh_config), Bvh::new(bvh_config));
        let (Ok(octree), Ok(dynamic), Ok(statics)) = (octree, dynamic, statics) else {
            unreachable!("Config::validate checks every field the structures check");
        };
        Self {
            config,
            proxies: SlotMap::with_key(),
            octree,
            dynamic,
            statics,
            statics_changed: false,
            dynamic_changed: false,
            cache: (config.skin > 0.0).then(|| PairCache::new(config.skin)),
            pairs: Vec::new(),
            prev: Vec::new(),
            added: Vec::new(),
            removed: Vec::new(),
            sorter: PairSorter::new(),
        }
    }

    /// The octree holding the spheres (radii grown by the margin): for stats and debug views.
    #[must_use]
    pub fn octree(&self) -> &Octree {
        &self.octree
    }

    /// The BVH holding the dynamic bodies (boxes grown by the margin).
    #[must_use]
    pub fn dynamic_bvh(&self) -> &Bvh {
        &self.dynamic
    }

    /// The BVH holding the static bodies (boxes grown by the margin).
    #[must_use]
    pub fn static_bvh(&self) -> &Bvh {
        &self.statics
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
        let key = self.proxies.insert(Shape::Sphere { center, radius });
        let grown = radius + self.config.margin;
        let stored = fat_radius(grown, self.cache.as_ref().map_or(0.0, PairCache::skin));
        self.octree
            .insert_keyed(key, center, stored)
            .inspect_err(|_| {
                self.proxies.remove(key);
            })?;
        if let Some(cache) = &mut self.cache {
            let exact = PrimBox::from_center_radius(center, grown);
            cache.insert(key, exact, &Aabb::from_center_radius(center, stored));
        }
        Ok(key)
    }

    /// Adds a body by its world AABB. `Err` on a non-finite or inverted box.
    pub fn insert_body(&mut self, aabb: Aabb, kind: BodyKind) -> Result<ProxyKey, Error> {
        check_aabb(&aabb)?;
        let key = self.proxies.insert(Shape::Body { aabb, kind });
        let exact = finite_grown(&aabb, self.config.margin);
        let stored = match &self.cache {
            Some(cache) => finite_grown(&exact, cache.skin()),
            None => exact,
        };
        let tree = match kind {
            BodyKind::Dynamic => {
                self.dynamic_changed = true;
                &mut self.dynamic
            }
            BodyKind::Static => {
                self.statics_changed = true;
                &mut self.statics
            }
        };
        tree.insert_keyed(key, stored).inspect_err(|_| {
            self.proxies.remove(key);
        })?;
        if let Some(cache) = &mut self.cache {
            cache.insert(key, PrimBox::new(&exact), &stored);
        }
        Ok(key)
    }

    /// Moves or resizes a sphere. `Err(UnknownProxy)` for a stale key, `Err(WrongKind)` for a
    /// body's key, or a geometry error; on `Err` nothing changes.
    #[inline]
    pub fn update_sphere(&mut self, key: ProxyKey, center: Vec3, radius: f32) -> Result<(), Error> {
        // The coordinates cross the call in registers: a `Vec3` argument went through memory,
        // and reading it back stalled on store forwarding (a quarter of this call's time in a
        // resting pile, perf).
        self.update_sphere_xyz(key, center.x, center.y, center.z, radius)
    }

    /// [`BroadPhase::update_sphere`] with the centre as three scalars.
    fn update_sphere_xyz(
        &mut self,
        key: ProxyKey,
        x: f32,
        y: f32,
        z: f32,
        radius: f32,
    ) -> Result<(), Error> {
        let center = Vec3::new(x, y, z);
        check_sphere(center, radius)?;
        match self.proxies.get_mut(key) {
            Some(Shape::Sphere {
                center: c,
                radius: r,
            }) => {
                let grown = radius + self.config.margin;
                match &mut self.cache {
                    // No margin: the sphere just checked is the one the octree stores.
                    None if self.config.margin == 0.0 => {
                        self.octree.update_checked(key, center, radius)?;
                    }
                    None => self.octree.update(key, center, grown)?,
                    Some(cache) => {
                        let exact = PrimBox::from_center_radius(center, grown);
                        if cache.needs_new_fat(key, &exact) {
                            let stored = fat_radius(grown, cache.skin());
                            self.octree.update(key, center, stored)?;
                            cache.refat(key, exact, &Aabb::from_center_radius(center, stored));
                        } else {
                            cache.set_exact(key, exact);
                        }
                    }
                }
                // Field by field: writing a whole new `Shape` went through the stack and
                // stalled on store forwarding (a third of this function's time, perf).
                (*c, *r) = (center, radius);
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
            Some(Shape::Body { aabb: a, kind }) => {
                let margin = self.config.margin;
                let tree = match kind {
                    BodyKind::Dynamic => &mut self.dynamic,
                    BodyKind::Static => &mut self.statics,
                };
                match &mut self.cache {
                    // No margin: the box just checked is the one the tree stores.
                    None if margin == 0.0 => tree.update_checked(key, &aabb)?,
                    None => tree.update(key, finite_grown(&aabb, margin))?,
                    Some(cache) => {
                        let exact = finite_grown(&aabb, margin);
                        let lanes = PrimBox::new(&exact);
                        if cache.needs_new_fat(key, &lanes) {
                            let stored = finite_grown(&exact, cache.skin());
                            tree.update(key, stored)?;
                            cache.refat(key, lanes, &stored);
                        } else {
                            cache.set_exact(key, lanes);
                            *a = aabb;
                            return Ok(());
                        }
                    }
                }
                match kind {
                    BodyKind::Dynamic => self.dynamic_changed = true,
                    BodyKind::Static => self.statics_changed = true,
                }
                *a = aabb;
                Ok(())
            }
            Some(Shape::Sphere { .. }) => Err(Error::WrongKind),
            None => Err(Error::UnknownProxy),
        }
    }

    /// Moves or resizes many spheres at once: `(key, center, radius)` per entry. The whole batch
    /// is checked first; on the first bad entry (non-finite, negative radius, stale key, a
    /// body's key) nothing is applied and the error names the entry. A key given twice is
    /// fine: the last entry wins.
    pub fn update_spheres(&mut self, updates: &[(ProxyKey, Vec3, f32)]) -> Result<(), BatchError> {
        for (index, &(key, center, radius)) in updates.iter().enumerate() {
            self.check_sphere_update(key, center, radius)
                .map_err(|error| BatchError { index, error })?;
        }
        for &(key, center, radius) in updates {
            let applied = self.update_sphere(key, center, radius);
            debug_assert!(applied.is_ok(), "a checked entry was refused");
        }
        Ok(())
    }

    /// Sets many bodies' boxes at once: `(key, aabb)` per entry. The whole batch is checked
    /// first; on the first bad entry (non-finite or inverted box, stale key, a sphere's key)
    /// nothing is applied and the error names the entry. A key given twice is fine: the last
    /// entry wins.
    pub fn update_bodies(&mut self, updates: &[(ProxyKey, Aabb)]) -> Result<(), BatchError> {
        for (index, (key, aabb)) in updates.iter().enumerate() {
            self.check_body_update(*key, aabb)
                .map_err(|error| BatchError { index, error })?;
        }
        for (key, aabb) in updates {
            let applied = self.update_body(*key, *aabb);
            debug_assert!(applied.is_ok(), "a checked entry was refused");
        }
        Ok(())
    }

    /// What [`BroadPhase::update_sphere`] would refuse, without changing anything.
    fn check_sphere_update(&self, key: ProxyKey, center: Vec3, radius: f32) -> Result<(), Error> {
        check_sphere(center, radius)?;
        match self.proxies.get(key) {
            Some(Shape::Sphere { .. }) => Ok(()),
            Some(Shape::Body { .. }) => Err(Error::WrongKind),
            None => Err(Error::UnknownProxy),
        }
    }

    /// What [`BroadPhase::update_body`] would refuse, without changing anything.
    fn check_body_update(&self, key: ProxyKey, aabb: &Aabb) -> Result<(), Error> {
        check_aabb(aabb)?;
        match self.proxies.get(key) {
            Some(Shape::Body { .. }) => Ok(()),
            Some(Shape::Sphere { .. }) => Err(Error::WrongKind),
            None => Err(Error::UnknownProxy),
        }
    }

    /// Removes a proxy; its pairs are reported in `removed` at the next step.
    /// `Err(UnknownProxy)` for a stale key.
    pub fn remove(&mut self, key: ProxyKey) -> Result<(), Error> {
        let shape = self.proxies.get(key).ok_or(Error::UnknownProxy)?;
        match *shape {
            Shape::Sphere { .. } => self.octree.remove(key)?,
            Shape::Body {
                kind: BodyKind::Dynamic,
                ..
            } => {
                self.dynamic.remove(key)?;
                self.dynamic_changed = true;
            }
            Shape::Body {
                kind: BodyKind::Static,
                ..
            } => {
                self.statics.remove(key)?;
                self.statics_changed = true;
            }
        }
        if let Some(cache) = &mut self.cache {
            cache.remove(key);
        }
        self.proxies.remove(key);
        Ok(())
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

    /// Every live proxy with its shape as the user gave it, in slot order.
    pub fn iter(&self) -> impl Iterator<Item = (ProxyKey, Shape)> + '_ {
        self.proxies.iter().map(|(key, shape)| (key, *shape))
    }

    /// Computes this step's pairs and their difference with the previous step's.
    ///
    /// The pair set is the union of four disjoint parts, each found once: sphere×sphere (the
    /// octree's walk), dynamic×dynamic (the dynamic tree against itself), dynamic×static (tree
    /// against tree) and sphere×body (the smaller side queried against the larger). It is then
    /// sorted, and merged against the previous step's list for `added` / `removed`. Steady
    /// state allocates nothing: every list is kept and reused.
    pub fn step(&mut self) -> StepPairs<'_> {
        if self.cache.is_some() {
            self.step_cached();
        } else {
            self.dynamic.refit();
            self.dynamic_changed = false;
            if self.statics_changed {
                self.statics.refit();
                self.statics_changed = false;
            }
            core::mem::swap(&mut self.prev, &mut self.pairs);
            self.pairs.clear();
            structure_pairs(
                &mut self.octree,
                &mut self.dynamic,
                &self.statics,
                &mut self.pairs,
            );
            self.sorter.sort(&mut self.pairs);
            debug_assert!(
                self.pairs.windows(2).all(|w| w[0] < w[1]),
                "a pair found twice"
            );
            pair::diff(&self.prev, &self.pairs, &mut self.added, &mut self.removed);
        }
        StepPairs {
            pairs: &self.pairs,
            added: &self.added,
            removed: &self.removed,
        }
    }

    /// [`BroadPhase::step`] with the pair cache: bring the candidates up to date for the
    /// proxies marked since the last step, then filter them by their exact boxes.
    fn step_cached(&mut self) {
        let Self {
            cache: Some(cache),
            proxies,
            octree,
            dynamic,
            statics,
            ..
        } = self
        else {
            return;
        };
        if core::mem::take(&mut self.dynamic_changed) {
            dynamic.refit();
        }
        if core::mem::take(&mut self.statics_changed) {
            statics.refit();
        }
        core::mem::swap(&mut self.prev, &mut self.pairs);
        let marked = cache.dirty().len();
        // Re-querying one proxy costs a few times its share of a full pair pass.
        let full = marked.saturating_mul(8) > proxies.len();
        let mut fresh = core::mem::take(&mut cache.fresh);
        fresh.clear();
        if full {
            structure_pairs(octree, dynamic, statics, &mut fresh);
            self.sorter.sort(&mut fresh);
        } else {
            // The candidates `(x, k)`, `x < k`, of each marked key `k`: every `x` whose fat
            // box overlaps the one `k` had when they were found (an unmarked `x` still has
            // its box then; a marked one drops its own range `(x, ..)`).
            let mut stale = core::mem::take(&mut cache.stale);
            stale.clear();
            for (key, old) in cache.marked_with_old_fat() {
                // A removed key's kind is gone: its static neighbours are searched too.
                let is_static = proxies.get(key).is_some_and(Shape::is_static);
                query_stored(octree, dynamic, statics, old, is_static, |other| {
                    if other < key {
                        stale.push(Pair { a: other, b: key });
                    }
                });
            }
            cache.stale = stale;
            for &key in cache.dirty() {
                let Some(shape) = proxies.get(key) else {
                    continue; // removed since it was marked
                };
                let fat = &cache.fat(key);
                query_stored(octree, dynamic, statics, fat, shape.is_static(), |other| {
                    if other != key {
                        fresh.push(Pair::new(key, other));
                    }
                });
            }
        }
        cache.fresh = fresh;
        cache.step(
            full,
            &self.prev,
            &mut self.pairs,
            &mut self.added,
            &mut self.removed,
        );
    }

    /// Calls `f` with every proxy whose (margin-grown) box overlaps `aabb`, each once, in no
    /// particular order; nothing for a non-finite or inverted query box.
    pub fn query_aabb(&self, aabb: &Aabb, mut f: impl FnMut(ProxyKey)) {
        if check_aabb(aabb).is_err() {
            return;
        }
        match &self.cache {
            None => {
                self.octree.query_aabb(aabb, &mut f);
                self.dynamic.query_aabb(aabb, &mut f);
                self.statics.query_aabb(aabb, &mut f);
            }
            Some(cache) => {
                // The structures hold fat boxes: each hit is re-tested with its exact box.
                let mut exact = |key: ProxyKey| {
                    if cache.exact(key).overlaps(aabb) {
                        f(key);
                    }
                };
                self.octree.query_aabb(aabb, &mut exact);
                self.dynamic.query_aabb(aabb, &mut exact);
                self.statics.query_aabb(aabb, &mut exact);
            }
        }
    }

    /// The nearest proxy hit by the segment `origin + t·dir`, `t ∈ [0, max_t]`, with its `t`
    /// (in units of `dir`, which need not be unit length). Spheres are hit as spheres, bodies
    /// as their boxes, both as the user gave them (without the margin); ties go to the smaller
    /// key. `None` for a non-finite ray or `max_t < 0`.
    #[must_use]
    pub fn cast_ray(&self, origin: Vec3, dir: Vec3, max_t: f32) -> Option<(ProxyKey, f32)> {
        if !geom::ray_is_valid(origin, dir, max_t) {
            return None;
        }
        let closer = |best: Option<(ProxyKey, f32)>, hit: Option<(ProxyKey, f32)>| match (best, hit)
        {
            (Some(b), Some(h)) if (h.1, h.0) < (b.1, b.0) => Some(h),
            (None, h) => h,
            (b, _) => b,
        };
        if self.config.margin == 0.0 && self.cache.is_none() {
            // The structures hold the exact shapes: their closest-hit searches answer directly.
            let mut best = self.octree.cast_ray(origin, dir, max_t);
            for tree in [&self.dynamic, &self.statics] {
                let limit = best.map_or(max_t, |b| b.1);
                best = closer(best, tree.cast_ray(origin, dir, limit));
            }
            return best;
        }
        // Grown (or fat) shapes: every hit is a candidate, re-tested against the exact shape.
        let inv = geom::inverse_dir(dir);
        let mut best = None;
        let mut exact = |key: ProxyKey, _: f32| {
            let t = match self.proxies.get(key) {
                Some(&Shape::Sphere { center, radius }) => {
                    geom::ray_sphere(origin, dir, center, radius, max_t)
                }
                Some(Shape::Body { aabb, .. }) => aabb.ray_entry(origin, inv, max_t),
                None => None,
            };
            best = closer(best, t.map(|t| (key, t)));
        };
        if self.cache.is_some() {
            // A fat sphere holds the exact sphere's box, not always its ball.
            self.octree
                .cast_ray_all_boxes(origin, dir, max_t, &mut exact);
        } else {
            self.octree.cast_ray_all(origin, dir, max_t, &mut exact);
        }
        self.dynamic.cast_ray_all(origin, dir, max_t, &mut exact);
        self.statics.cast_ray_all(origin, dir, max_t, &mut exact);
        best
    }

    /// Checks every internal invariant (each structure's `validate`, and that every proxy is
    /// in exactly the structure its kind says, with its margin-grown box); panics with a
    /// message on the first broken one. For tests: O(n).
    pub fn validate(&self) {
        self.octree.validate();
        self.dynamic.validate();
        self.statics.validate();
        let margin = self.config.margin;
        let (mut spheres, mut dynamic, mut statics) = (0, 0, 0);
        for (key, shape) in &self.proxies {
            let (tree_box, count) = match shape {
                Shape::Sphere { .. } => (self.octree.aabb(key), &mut spheres),
                Shape::Body {
                    kind: BodyKind::Dynamic,
                    ..
                } => (self.dynamic.aabb(key), &mut dynamic),
                Shape::Body {
                    kind: BodyKind::Static,
                    ..
                } => (self.statics.aabb(key), &mut statics),
            };
            *count += 1;
            let exact = shape.grown_aabb(margin);
            let want = match &self.cache {
                None => exact,
                Some(cache) => {
                    assert_eq!(cache.exact(key), exact, "proxy {key:?}: cached box stale");
                    let fat = cache.fat(key);
                    assert!(fat.contains(&exact), "proxy {key:?} outside its fat box");
                    fat
                }
            };
            assert_eq!(tree_box, Some(want), "proxy {key:?} ({shape:?}) misfiled");
        }
        if let Some(cache) = &self.cache {
            cache.validate(|key| self.proxies.contains_key(key), &self.pairs);
            if cache.dirty().is_empty() {
                // Complete: every pair of overlapping fat boxes is a candidate.
                for (key, shape) in &self.proxies {
                    let (octree, dynamic, statics) = (&self.octree, &self.dynamic, &self.statics);
                    let fat = &cache.fat(key);
                    query_stored(octree, dynamic, statics, fat, shape.is_static(), |other| {
                        if other != key {
                            let pair = Pair::new(key, other);
                            assert!(cache.is_candidate(&pair), "cache: {pair:?} missing");
                        }
                    });
                }
            }
        }
        assert_eq!(spheres, self.octree.len(), "octree holds unknown spheres");
        assert_eq!(
            dynamic,
            self.dynamic.len(),
            "dynamic tree holds unknown bodies"
        );
        assert_eq!(
            statics,
            self.statics.len(),
            "static tree holds unknown bodies"
        );
    }
}

/// Every pair of boxes the structures hold (static×static excepted), each once, unsorted:
/// sphere×sphere (the octree's walk), dynamic×dynamic (the dynamic tree against itself),
/// dynamic×static (tree against tree) and sphere×body (the smaller side queried against the
/// larger).
fn structure_pairs(octree: &mut Octree, dynamic: &mut Bvh, statics: &Bvh, pairs: &mut Vec<Pair>) {
    octree.pairs_into(pairs);
    dynamic.for_each_pair(|a, b| pairs.push(Pair::new(a, b)));
    dynamic.for_each_pair_with(statics, |a, b| pairs.push(Pair::new(a, b)));
    let bodies = dynamic.len() + statics.len();
    if bodies <= octree.len() {
        for tree in [&*dynamic, statics] {
            tree.for_each(|body, aabb| {
                octree.query_aabb_unchecked(&aabb, |sphere| pairs.push(Pair::new(sphere, body)));
            });
        }
    } else {
        octree.for_each(|sphere, aabb| {
            for tree in [&*dynamic, statics] {
                tree.query_aabb_unchecked(&aabb, |body| pairs.push(Pair::new(sphere, body)));
            }
        });
    }
}

/// Calls `f` with every proxy whose stored box overlaps `aabb`, in the octree and both trees;
/// the static tree is skipped for a static querier (`static_querier`), which never pairs
/// with a static body.
fn query_stored(
    octree: &Octree,
    dynamic: &Bvh,
    statics: &Bvh,
    aabb: &Aabb,
    static_querier: bool,
    mut f: impl FnMut(ProxyKey),
) {
    octree.query_aabb_unchecked(aabb, &mut f);
    dynamic.query_aabb_unchecked(aabb, &mut f);
    if !static_querier {
        statics.query_aabb_unchecked(aabb, &mut f);
    }
}

/// `aabb` grown by `margin`, with coordinates that overflowed clamped to `±f32::MAX`, so the
/// BVH (which holds finite boxes only) accepts it. Overlaps are unchanged: no box the
/// broadphase tests has a minimum of `+∞` or a maximum of `−∞`, so a face at `±∞` and one at
/// `±f32::MAX` overlap the same boxes.
fn finite_grown(aabb: &Aabb, margin: f32) -> Aabb {
    let g = aabb.grown(margin);
    Aabb {
        min: g.min.max(Vec3::splat(-f32::MAX)),
        max: g.max.min(Vec3::splat(f32::MAX)),
    }
}

/// A sphere's fat radius: `grown + skin`, at most `f32::MAX` (still `>= grown`, so the fat
/// box holds the exact one) when `grown` is finite.
fn fat_radius(grown: f32, skin: f32) -> f32 {
    if grown.is_finite() {
        (grown + skin).min(f32::MAX)
    } else {
        grown
    }
}
