//! The broadphase's own structures hold what it says they hold: after every `step()` of random
//! operation sequences (insert sphere / dynamic body / static body, move, teleport, resize,
//! remove, steps where most things move), under Configs crossing both placements, margins 0 and 0.1, skins 0 and 0.05, rebuild thresholds 1, 1.5 and 4, and
//! each `Passes`:
//! - every live sphere is in `octree()` under its key and in neither BVH, every body in the
//!   BVH of its kind only, removed keys in none, and the lengths are the live counts;
//! - every stored box covers the shape grown by the margin (it may be larger: fat boxes);
//! - `octree().stats().per_level` is the histogram of `level_of` over the live spheres, and
//!   `overflow` is at most `per_level[0]`;
//! - `octree()` has the Config's placement, a cubic region (it follows the spheres: derived
//!   state, read from the tree) and a depth up to `MAX_DEPTH`, each BVH its rebuild threshold;
//! - with `Passes::Full` (the octree then holds exactly `center ± (radius + margin)`) every
//!   sphere's level is the one the test derives from the placement rule with its own
//!   arithmetic over the tree's current region and depth (strict: the deepest level whose cell
//!   grid has the box's two corners in one cell; loose: the deepest level whose cells, along
//!   the region's shortest axis, are at least the diameter), spheres that do not fit are at level 0 and counted in `overflow`; cases
//!   within 1e-3 cell of a deciding plane or cell size are skipped. Under any `Passes`, a
//!   strict sphere is no deeper than its exact box allows and at the level its stored box
//!   gives;
//! - `step()`'s lists equal the model's brute force (`tests/common`) and its set differences.

mod common;

use broadleaf::octree::MAX_DEPTH;
use broadleaf::{Aabb, BodyKind, BroadPhase, Config, Passes, Placement, ProxyKey, Vec3};
use common::{Model, ModelShape, Rng};

/// Where the spheres live (and the Config's region hint): off the origin and longer on x than
/// on z than on y.
const BOUNDS: Aabb = Aabb {
    min: Vec3::new(-30.0, -14.0, -22.0),
    max: Vec3::new(34.0, 18.0, 26.0),
};

/// How close (in cells of the level in question, or relative to a cell size) a case may come
/// to a deciding plane or size before the test leaves it unchecked: float rounding in the
/// crate's cell map must not decide the expected answer.
const CLEAR: f64 = 1e-3;

/// Proxies inserted before the first step; the population then drifts between `LOW` and
/// `HIGH`.
const INITIAL: usize = 220;
const LOW: usize = 160;
const HIGH: usize = 300;
/// Steps per Config.
const STEPS: usize = 120;

/// The root's split planes: the bounds' midplanes.
fn mid() -> Vec3 {
    (BOUNDS.min + BOUNDS.max) * 0.5
}

/// A centre: mostly inside the bounds, sometimes exactly on one of the root's split planes,
/// sometimes outside the bounds on one axis.
fn random_center(rng: &mut Rng) -> Vec3 {
    let mut c = rng.vec3_in(BOUNDS.min, BOUNDS.max);
    let axis = rng.below(3);
    match rng.below(20) {
        0..=14 => {}
        15..=16 => c[axis] = mid()[axis],
        _ => {
            let out = rng.range(0.5, 20.0);
            c[axis] = if rng.chance(0.5) {
                BOUNDS.max[axis] + out
            } else {
                BOUNDS.min[axis] - out
            };
        }
    }
    c
}

/// A radius, log-uniform over 1 mm – 8 m (so every level of a depth-10 tree gets spheres),
/// now and then 8–16 m (the loose root's only) or larger than half the bounds' shortest side
/// (too big for a loose root).
fn random_radius(rng: &mut Rng) -> f32 {
    match rng.below(100) {
        0..=1 => rng.range(17.0, 20.0),
        2..=4 => rng.range(8.0, 16.0),
        _ => 1e-3 * 8000f32.powf(rng.unit()),
    }
}

fn random_shape(rng: &mut Rng) -> ModelShape {
    let c = random_center(rng);
    match rng.below(20) {
        0..=11 => ModelShape::Sphere {
            center: c,
            radius: random_radius(rng),
        },
        12..=16 => ModelShape::body(c, rng.vec3_in(Vec3::splat(0.05), Vec3::splat(3.0)), false),
        _ => ModelShape::body(c, rng.vec3_in(Vec3::splat(0.05), Vec3::splat(3.0)), true),
    }
}

/// `inner` lies in the closed box `outer`.
fn covers(outer: &Aabb, inner: &Aabb) -> bool {
    (0..3).all(|a| outer.min[a] <= inner.min[a] && inner.max[a] <= outer.max[a])
}

/// Where a coordinate lies along `axis` of `region`, as a fraction: 0 at `min`, 1 at `max`.
fn fraction(x: f32, axis: usize, region: &Aabb) -> f64 {
    let (lo, hi) = (f64::from(region.min[axis]), f64::from(region.max[axis]));
    (f64::from(x) - lo) / (hi - lo)
}

/// True if `t` (in cells of some level) is within `CLEAR` of a cell boundary.
fn near_integer(t: f64) -> bool {
    (t - t.round()).abs() < CLEAR
}

/// Where placement puts a sphere, as the test derives it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Expected {
    level: u32,
    overflow: bool,
}

/// Strict placement of a box in an octree over `region` of `depth`, from the definition: a box
/// that leaves the bounds is overflow at level 0; otherwise its level is the deepest `L` whose
/// grid of `2^L` cells per axis has the box's two corners in the same cell on every axis.
/// `None` if a face is within `CLEAR` deepest cell of the bounds, or a corner within `CLEAR`
/// level-`L` cell of a level-`L` plane for a level up to one below the answer.
fn strict_placement(b: &Aabb, region: &Aabb, depth: u32) -> Option<Expected> {
    let deepest = f64::from(1u32 << depth);
    let (mut lo, mut hi) = ([0.0; 3], [0.0; 3]);
    for a in 0..3 {
        lo[a] = fraction(b.min[a], a, region);
        hi[a] = fraction(b.max[a], a, region);
        for t in [lo[a] * deepest, hi[a] * deepest] {
            if t.abs() < CLEAR || (t - deepest).abs() < CLEAR {
                return None;
            }
        }
    }
    if (0..3).any(|a| lo[a] < 0.0 || hi[a] > 1.0) {
        return Some(Expected {
            level: 0,
            overflow: true,
        });
    }
    let same_cell = |l: u32| {
        let n = f64::from(1u32 << l);
        (0..3).all(|a| (lo[a] * n).floor() == (hi[a] * n).floor())
    };
    let mut level = 0;
    while level < depth && same_cell(level + 1) {
        level += 1;
    }
    for l in 1..=(level + 1).min(depth) {
        let n = f64::from(1u32 << l);
        if (0..3).any(|a| near_integer(lo[a] * n) || near_integer(hi[a] * n)) {
            return None;
        }
    }
    Some(Expected {
        level,
        overflow: false,
    })
}

/// Loose placement of a sphere of centre `c` and (margin-grown) radius `r` in an octree over
/// `region` of `depth`: a centre outside the bounds, or a diameter above the bounds' shortest
/// side, is overflow at level 0; otherwise the level is the deepest `L <= depth` whose cell
/// edge along the shortest axis (`shortest / 2^L`) is at least the diameter. `None` if the
/// centre is within `CLEAR` deepest cell of a face of the bounds, or the diameter within
/// `CLEAR` (relative) of a cell edge.
fn loose_placement(c: Vec3, r: f32, region: &Aabb, depth: u32) -> Option<Expected> {
    let deepest = f64::from(1u32 << depth);
    let mut outside = false;
    for a in 0..3 {
        let t = fraction(c[a], a, region) * deepest;
        if (t.abs() < CLEAR) || ((t - deepest).abs() < CLEAR) {
            return None;
        }
        outside |= t < 0.0 || t > deepest;
    }
    let extent = region.max - region.min;
    let shortest = (0..3)
        .map(|a| f64::from(extent[a]))
        .fold(f64::INFINITY, f64::min);
    let diameter = 2.0 * f64::from(r);
    let edge = |l: u32| shortest / f64::from(1u32 << l);
    if (0..=depth).any(|l| (diameter - edge(l)).abs() <= CLEAR * edge(l)) {
        return None;
    }
    if outside || diameter > edge(0) {
        return Some(Expected {
            level: 0,
            overflow: true,
        });
    }
    let level = (0..=depth)
        .rev()
        .find(|&l| edge(l) >= diameter)
        .unwrap_or(0);
    Some(Expected {
        level,
        overflow: false,
    })
}

/// How many clear placement cases of each kind a run checked, so a run that checked none of a
/// kind it should reach fails.
#[derive(Debug, Default)]
struct Tally {
    /// Inside the bounds, at level 0 with a tree deeper than 0 (strict: straddlers of a root
    /// plane; loose: big spheres).
    root_inside: usize,
    /// At the deepest level of a tree deeper than 0.
    deepest: usize,
    /// Overflow.
    overflow: usize,
    /// Skipped as too close to call.
    skipped: usize,
}

/// One broadphase, its model, and the keys it removed.
struct World {
    config: Config,
    bp: BroadPhase,
    model: Model,
    rng: Rng,
    removed: Vec<ProxyKey>,
    tally: Tally,
}

impl World {
    fn new(config: Config, seed: u64) -> Self {
        Self {
            config,
            bp: BroadPhase::new(config),
            model: Model::new(config.margin),
            rng: Rng::new(seed),
            removed: Vec::new(),
            tally: Tally::default(),
        }
    }

    fn insert(&mut self) {
        let shape = random_shape(&mut self.rng);
        self.model.insert(&mut self.bp, shape);
    }

    fn pick(&mut self) -> Option<(ProxyKey, ModelShape)> {
        let keys = self.model.keys();
        if keys.is_empty() {
            return None;
        }
        let key = keys[self.rng.below(keys.len())];
        Some((key, self.model.shapes[&key]))
    }

    /// One random operation: insert, move, teleport, resize or remove.
    fn operate(&mut self) {
        let n = self.model.shapes.len();
        let op = if n < LOW {
            0
        } else if n > HIGH {
            9
        } else {
            self.rng.below(10)
        };
        if op <= 1 {
            self.insert();
            return;
        }
        let Some((key, shape)) = self.pick() else {
            return;
        };
        let rng = &mut self.rng;
        let next = match op {
            2..=5 => {
                let len = 1e-3 * 2000f32.powf(rng.unit());
                shape.moved(rng.offset(len))
            }
            6 => shape.teleported(random_center(rng)),
            7 | 8 => {
                let size = match shape {
                    ModelShape::Sphere { .. } => random_radius(rng),
                    ModelShape::Body { .. } => rng.range(0.05, 3.0),
                };
                shape.placed(shape.center() + rng.offset(0.1), size)
            }
            _ => {
                self.model.remove(&mut self.bp, key);
                self.removed.push(key);
                return;
            }
        };
        self.model.update(&mut self.bp, key, next);
    }

    /// Moves most of the spheres and dynamic bodies a little: the step that follows has most
    /// things moved (the adaptive choice's other side), and many spheres cross planes.
    fn move_most(&mut self) {
        for key in self.model.keys() {
            let shape = self.model.shapes[&key];
            if !shape.is_static() && self.rng.chance(0.7) {
                let d = self.rng.offset(0.3);
                self.model.update(&mut self.bp, key, shape.moved(d));
            }
        }
    }

    fn step(&mut self, context: &str) {
        self.model.check_step(&mut self.bp, context);
        self.check_structures(context);
    }

    /// Every check on `octree()` and `bvh(kind)` of the module docs.
    fn check_structures(&mut self, context: &str) {
        let World {
            bp,
            config,
            model,
            removed,
            tally,
            ..
        } = self;
        let margin = config.margin;
        let (oct, dynamic, fixed) = (
            bp.octree(),
            bp.bvh(BodyKind::Dynamic),
            bp.bvh(BodyKind::Static),
        );
        let (region, depth) = (oct.bounds(), oct.depth());
        assert!(depth <= MAX_DEPTH, "{context}: octree depth {depth}");
        assert_eq!(
            oct.placement(),
            config.octree_placement,
            "{context}: placement"
        );
        assert!(oct.is_growing(), "{context}: the octree's region is fixed");
        let side = region.extent();
        assert!(
            region.is_finite() && side.x > 0.0 && side.x == side.y && side.y == side.z,
            "{context}: the octree's region {region:?} is not a cube"
        );
        for (kind, bvh) in [("dynamic", dynamic), ("static", fixed)] {
            assert_eq!(
                bvh.config().rebuild_threshold,
                config.rebuild_threshold,
                "{context}: {kind} bvh rebuild threshold"
            );
        }

        let (mut spheres, mut dynamics, mut statics) = (0, 0, 0);
        let mut histogram = [0u32; 11];
        let (mut overflow_sure, mut overflow_maybe) = (0u32, 0u32);
        for key in model.keys() {
            let shape = model.shapes[&key];
            let want = shape.pair_box(margin);
            match shape {
                ModelShape::Sphere { center, radius } => {
                    spheres += 1;
                    assert!(
                        oct.contains(key) && !dynamic.contains(key) && !fixed.contains(key),
                        "{context}: sphere {key:?} is not in the octree alone"
                    );
                    let stored = oct.aabb(key).expect("a live sphere has a box");
                    assert!(
                        covers(&stored, &want),
                        "{context}: sphere {key:?}'s octree box {stored:?} misses {want:?}"
                    );
                    let level = oct.level_of(key).expect("a live sphere has a level");
                    assert!(level <= depth, "{context}: level {level}");
                    histogram[level as usize] += 1;
                    let sphere = Placed {
                        key,
                        center,
                        r: radius + margin,
                        exact: want,
                        stored,
                        level,
                    };
                    match check_level(config, (&region, depth), tally, &sphere, context) {
                        Some(true) => overflow_sure += 1,
                        Some(false) => {}
                        None => overflow_maybe += 1,
                    }
                }
                ModelShape::Body { is_static, .. } => {
                    let (mine, other, kind) = if is_static {
                        statics += 1;
                        (fixed, dynamic, "static")
                    } else {
                        dynamics += 1;
                        (dynamic, fixed, "dynamic")
                    };
                    assert!(
                        mine.contains(key) && !other.contains(key) && !oct.contains(key),
                        "{context}: {kind} body {key:?} is not in the {kind} bvh alone"
                    );
                    let stored = mine.aabb(key).expect("a live body has a box");
                    assert!(
                        covers(&stored, &want),
                        "{context}: {kind} body {key:?}'s box {stored:?} misses {want:?}"
                    );
                }
            }
        }
        assert_eq!(oct.len(), spheres, "{context}: octree len");
        assert_eq!(dynamic.len(), dynamics, "{context}: dynamic bvh len");
        assert_eq!(fixed.len(), statics, "{context}: static bvh len");
        for &key in removed.iter() {
            assert!(
                !oct.contains(key) && !dynamic.contains(key) && !fixed.contains(key),
                "{context}: removed {key:?} is still held"
            );
            assert_eq!(oct.aabb(key), None, "{context}: removed {key:?} has a box");
            assert_eq!(
                oct.level_of(key),
                None,
                "{context}: removed {key:?} has a level"
            );
        }

        let stats = oct.stats();
        assert_eq!(
            stats.per_level.iter().map(|&n| n as usize).sum::<usize>(),
            oct.len(),
            "{context}: per_level sums to {:?}, not len",
            stats.per_level
        );
        assert_eq!(
            stats.per_level, histogram,
            "{context}: per_level is not the histogram of level_of"
        );
        assert!(
            stats.overflow <= stats.per_level[0],
            "{context}: overflow {} above per_level[0] {}",
            stats.overflow,
            stats.per_level[0]
        );
        if config.passes == Passes::Full {
            assert!(
                overflow_sure <= stats.overflow && stats.overflow <= overflow_sure + overflow_maybe,
                "{context}: overflow {}, the test counts {overflow_sure} sure and \
                 {overflow_maybe} unsure",
                stats.overflow
            );
        }
    }
}

/// One sphere as the test computes it and as the octree holds it.
struct Placed {
    key: ProxyKey,
    center: Vec3,
    /// `radius + margin`.
    r: f32,
    /// `center ± r`, computed by the test.
    exact: Aabb,
    /// `octree().aabb(key)`.
    stored: Aabb,
    /// `octree().level_of(key)`.
    level: u32,
}

/// Checks one sphere's level against the placement rule (module docs) and returns whether it
/// overflows, `None` if that is too close to call (or not derivable under this `Passes`).
fn check_level(
    config: &Config,
    (region, depth): (&Aabb, u32),
    tally: &mut Tally,
    s: &Placed,
    context: &str,
) -> Option<bool> {
    let full = config.passes == Passes::Full;
    let Placed {
        key,
        center,
        r,
        exact,
        stored,
        level,
    } = *s;
    if full {
        assert_eq!(
            stored, exact,
            "{context}: with Passes::Full the octree holds sphere {key:?} as \
             center ± (radius + margin)"
        );
    }
    let expected = match config.octree_placement {
        Placement::Strict => {
            if !full {
                // A box at least as large as the exact one is placed no deeper than the exact
                // one, and where its own corners say.
                if let Some(e) = strict_placement(&exact, region, depth) {
                    assert!(
                        level <= e.level,
                        "{context}: sphere {key:?} at level {level}, deeper than its exact box \
                         {exact:?} allows ({})",
                        e.level
                    );
                }
                if let Some(e) = strict_placement(&stored, region, depth) {
                    assert_eq!(
                        level, e.level,
                        "{context}: sphere {key:?} (stored box {stored:?}) by the strict rule"
                    );
                }
                return None;
            }
            strict_placement(&exact, region, depth)
        }
        Placement::Loose => {
            if !full {
                return None;
            }
            loose_placement(center, r, region, depth)
        }
    };
    let Some(e) = expected else {
        tally.skipped += 1;
        return None;
    };
    assert_eq!(
        level, e.level,
        "{context}: sphere {key:?} at {center:?} radius+margin {r} (box {exact:?}) by the {:?} \
         rule",
        config.octree_placement
    );
    if e.overflow {
        tally.overflow += 1;
    } else if depth > 0 && level == 0 {
        tally.root_inside += 1;
    } else if depth > 0 && level == depth {
        tally.deepest += 1;
    }
    Some(e.overflow)
}

/// The runs' Configs for one `Passes` (`p` its index): both placements, both margins, with and
/// without a region hint, with skins and thresholds crossed so that every value of each comes
/// up.
fn configs(passes: Passes, p: usize) -> Vec<Config> {
    const THRESHOLDS: [f32; 3] = [1.0, 1.5, 4.0];
    (0..16)
        .map(|j| Config {
            bounds: [None, Some(BOUNDS)][j % 2],
            octree_placement: [Placement::Strict, Placement::Loose][j / 4 % 2],
            margin: [0.0, 0.1][j / 8],
            skin: [0.0, 0.05][(j / 2 + j / 8 + p) % 2],
            rebuild_threshold: THRESHOLDS[(j + p) % 3],
            passes,
        })
        .collect()
}

/// Random operation sequences under each of `passes`' Configs, every check after every step.
fn run(passes: Passes, p: usize) {
    for (j, config) in configs(passes, p).into_iter().enumerate() {
        let mut w = World::new(config, 0x5eed_0000 + (p * 16 + j) as u64);
        let name = format!("{config:?}");
        for _ in 0..INITIAL {
            w.insert();
        }
        w.step(&format!("{name}, first step"));
        for s in 0..STEPS {
            if w.rng.chance(0.1) {
                w.move_most();
            }
            for _ in 0..1 + w.rng.below(12) {
                w.operate();
            }
            w.step(&format!("{name}, step {s}"));
        }
        if passes == Passes::Full {
            expect_reached(&w, &name);
        }
    }
}

/// The clear cases the run was built to reach were checked at least once (overflow is not
/// among them: the region follows the spheres, so a sphere is outside it only between a
/// teleport and the next re-root).
fn expect_reached(w: &World, name: &str) {
    let (c, t) = (&w.config, &w.tally);
    if c.octree_placement == Placement::Strict {
        assert!(t.root_inside > 0, "{name}: no level-0 case inside: {t:?}");
    }
    assert!(
        t.deepest > 0,
        "{name}: no deepest-level case checked: {t:?}"
    );
}

#[test]
fn structures_hold_the_proxies_under_adaptive_passes() {
    run(Passes::Adaptive, 0);
}

#[test]
fn structures_hold_the_proxies_and_place_them_by_the_rule_under_full_passes() {
    run(Passes::Full, 1);
}

#[test]
fn structures_hold_the_proxies_under_incremental_passes() {
    run(Passes::Incremental, 2);
}

/// The test's own placement arithmetic on hand-made cases, so the runs above rest on it.
#[test]
fn the_tests_placement_rules_on_known_cases() {
    let m = mid();
    // Strict, depth 3 (cells 8 × 4 × 6 m): a box across the root's x plane is at level 0.
    let across = Aabb::new(m - Vec3::new(0.5, -1.0, -1.0), m + Vec3::new(0.5, 2.0, 2.0));
    assert_eq!(
        strict_placement(&across, &BOUNDS, 3),
        Some(Expected {
            level: 0,
            overflow: false
        })
    );
    // A small box well inside a deepest cell is at the depth.
    // (Inside deepest cell (16, 32, 21) of a depth-10 tree, 0.3 cell or more from its faces.)
    let c = Vec3::new(-28.97, -12.98, -20.99);
    let small = Aabb::new(c - 0.005, c + 0.005);
    assert_eq!(
        strict_placement(&small, &BOUNDS, 3).map(|e| e.level),
        Some(3)
    );
    assert_eq!(
        strict_placement(&small, &BOUNDS, 10).map(|e| e.level),
        Some(10)
    );
    // 2 m boxes in the first octant: inside one level-2 cell (16 × 8 × 12) but across a
    // level-3 plane on x (x = -22).
    let mid_size = Aabb::new(
        Vec3::new(-23.0, -13.0, -21.0),
        Vec3::new(-21.0, -11.0, -19.0),
    );
    assert_eq!(
        strict_placement(&mid_size, &BOUNDS, 7).map(|e| e.level),
        Some(2)
    );
    // Leaving the bounds: overflow; touching a face: too close to call.
    let out = Aabb::new(Vec3::new(33.0, 0.5, 0.5), Vec3::new(35.0, 1.5, 1.5));
    assert_eq!(
        strict_placement(&out, &BOUNDS, 7),
        Some(Expected {
            level: 0,
            overflow: true
        })
    );
    let touching = Aabb::new(Vec3::new(33.0, 0.5, 0.5), Vec3::new(34.0, 1.5, 1.5));
    assert_eq!(strict_placement(&touching, &BOUNDS, 7), None);
    // Loose, shortest side 32 m: radius 1 (diameter 2) fits cells of 2 m at level 4.
    assert_eq!(
        loose_placement(Vec3::new(1.3, 0.7, 0.2), 0.9, &BOUNDS, 7).map(|e| e.level),
        Some(4)
    );
    assert_eq!(
        loose_placement(Vec3::new(1.3, 0.7, 0.2), 1.0, &BOUNDS, 7),
        None
    );
    assert_eq!(
        loose_placement(Vec3::new(1.3, 0.7, 0.2), 0.9, &BOUNDS, 3).map(|e| e.level),
        Some(3)
    );
    // Too big for the root, or centred outside: overflow.
    assert_eq!(
        loose_placement(Vec3::ZERO, 17.0, &BOUNDS, 7),
        Some(Expected {
            level: 0,
            overflow: true
        })
    );
    assert_eq!(
        loose_placement(Vec3::new(40.0, 0.0, 0.0), 0.1, &BOUNDS, 7),
        Some(Expected {
            level: 0,
            overflow: true
        })
    );
}
