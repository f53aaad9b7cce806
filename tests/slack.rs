//! The incremental pass skips the candidates whose status cannot have changed (a proxy that
//! moved less than half the least slack of its candidates re-tests nothing), and the lists
//! stay exact: a settled-pile-like world (spheres on a lattice whose neighbours touch exactly,
//! overlap by under a millimetre or miss by as little, nudged by 0.01–1 mm each step, some
//! snapping back to the lattice so exact touches come and go, some random-walking away from
//! where their candidates were last tested), with radii that grow and shrink, bodies nudged
//! and a static floor, removes and inserts, and collision groups changed in between. Under
//! each of the three `Passes`, after every step `pairs` equals the test's own brute force over
//! its own copy of the shapes and groups, `added` / `removed` equal its set difference, and
//! `validate()` holds (which checks the slack invariants whenever candidates are kept).

mod common;

use broadleaf::brute;
use broadleaf::{Aabb, BodyKind, BroadPhase, CollisionGroups, Config, Pair, Passes, ProxyKey};
use broadleaf::{Pass, Vec3};
use common::Rng;
use std::collections::{BTreeSet, HashMap};

/// Lattice cells per side of the pile's square base, and its layers.
const SIDE: i32 = 12;
const LAYERS: i32 = 6;

#[derive(Clone, Copy, Debug)]
enum Shape {
    Sphere { center: Vec3, radius: f32 },
    Body { aabb: Aabb, kind: BodyKind },
}

impl Shape {
    fn aabb(&self) -> Aabb {
        match *self {
            Shape::Sphere { center, radius } => Aabb::from_center_radius(center, radius),
            Shape::Body { aabb, .. } => aabb,
        }
    }
}

/// One proxy of the test's own copy of the world.
#[derive(Clone, Copy, Debug)]
struct Proxy {
    shape: Shape,
    groups: CollisionGroups,
    /// The lattice point a sphere rests around.
    home: Vec3,
    /// True for a sphere that random-walks instead of jittering around its home.
    walker: bool,
}

struct World {
    bp: BroadPhase,
    rng: Rng,
    proxies: HashMap<ProxyKey, Proxy>,
    prev: BTreeSet<Pair>,
    /// The chance that a sphere is left alone in a step.
    still: f32,
}

/// A radius that makes lattice neighbours touch exactly (0.5), overlap by 0.8 mm, or miss by
/// 0.8 mm.
fn lattice_radius(rng: &mut Rng) -> f32 {
    [0.5, 0.5, 0.5004, 0.4996][rng.below(4)]
}

fn some_groups(rng: &mut Rng) -> CollisionGroups {
    match rng.below(4) {
        0 => CollisionGroups {
            memberships: 1,
            filter: 2,
        },
        1 => CollisionGroups {
            memberships: 2,
            filter: u32::MAX,
        },
        2 => CollisionGroups {
            memberships: 4,
            filter: 4,
        },
        _ => CollisionGroups::ALL,
    }
}

impl World {
    fn new(passes: Passes, seed: u64) -> Self {
        let mut w = World {
            bp: BroadPhase::new(Config {
                passes,
                ..Config::default()
            }),
            rng: Rng::new(seed),
            proxies: HashMap::new(),
            prev: BTreeSet::new(),
            still: 0.1,
        };
        for x in 0..SIDE {
            for z in 0..SIDE {
                for y in 0..LAYERS {
                    let home = Vec3::new(x as f32, y as f32 + 0.5, z as f32);
                    w.insert_sphere(home);
                }
            }
        }
        // The floor, touching the bottom layer exactly, and a few boxes resting on top.
        let floor = Aabb::new(
            Vec3::new(-1.0, -1.0, -1.0),
            Vec3::new(SIDE as f32, 0.0, SIDE as f32),
        );
        w.insert_body(floor, BodyKind::Static);
        for i in 0..8 {
            let c = Vec3::new(1.5 * i as f32, LAYERS as f32 + 0.5, 5.0);
            let aabb = Aabb::new(c - Vec3::splat(0.5), c + Vec3::splat(0.5));
            w.insert_body(aabb, BodyKind::Dynamic);
        }
        w
    }

    fn insert_sphere(&mut self, home: Vec3) {
        let radius = lattice_radius(&mut self.rng);
        let key = self.bp.insert_sphere(home, radius).expect("a valid sphere");
        let walker = self.rng.chance(0.15);
        let shape = Shape::Sphere {
            center: home,
            radius,
        };
        let groups = CollisionGroups::ALL;
        self.proxies.insert(
            key,
            Proxy {
                shape,
                groups,
                home,
                walker,
            },
        );
    }

    fn insert_body(&mut self, aabb: Aabb, kind: BodyKind) {
        let key = self.bp.insert_body(aabb, kind).expect("a valid body");
        let shape = Shape::Body { aabb, kind };
        let (groups, home, walker) = (CollisionGroups::ALL, aabb.center(), false);
        self.proxies.insert(
            key,
            Proxy {
                shape,
                groups,
                home,
                walker,
            },
        );
    }

    fn keys(&self) -> Vec<ProxyKey> {
        let mut keys: Vec<ProxyKey> = self.proxies.keys().copied().collect();
        keys.sort_unstable();
        keys
    }

    /// One step of settled-pile motion: most spheres nudged, some snapped home, walkers
    /// walking, a few radii changed, bodies nudged.
    fn jitter(&mut self) {
        let mut batch = Vec::new();
        for key in self.keys() {
            let rng = &mut self.rng;
            let p = self.proxies.get_mut(&key).expect("a live key");
            match p.shape {
                Shape::Sphere { center, radius } => {
                    let center = if rng.chance(self.still) {
                        continue;
                    } else if p.walker {
                        center + rng.offset(0.002)
                    } else if rng.chance(0.3) {
                        p.home
                    } else {
                        let len = rng.range(1e-5, 1e-3);
                        p.home + rng.offset(len)
                    };
                    let radius = match rng.below(40) {
                        0 => radius * 1.001,
                        1 => radius * 0.999,
                        2 => lattice_radius(rng),
                        _ => radius,
                    };
                    p.shape = Shape::Sphere { center, radius };
                    if rng.chance(0.5) {
                        batch.push((key, center, radius));
                    } else {
                        self.bp
                            .update_sphere(key, center, radius)
                            .expect("a valid sphere");
                    }
                }
                Shape::Body {
                    kind: BodyKind::Dynamic,
                    aabb,
                } => {
                    let d = rng.offset(1e-3);
                    let aabb = Aabb::new(aabb.min + d, aabb.max + d);
                    p.shape = Shape::Body {
                        aabb,
                        kind: BodyKind::Dynamic,
                    };
                    self.bp.update_body(key, aabb).expect("a valid box");
                }
                Shape::Body { .. } => {}
            }
        }
        assert_eq!(self.bp.update_spheres(&batch), Ok(()));
    }

    /// Removes, inserts (at free lattice points or where a sphere was), group changes.
    fn churn(&mut self) {
        let keys = self.keys();
        for _ in 0..self.rng.below(4) {
            let key = keys[self.rng.below(keys.len())];
            if let Some(p) = self.proxies.remove(&key) {
                self.bp.remove(key).expect("a live key");
                if matches!(p.shape, Shape::Sphere { .. }) && self.rng.chance(0.7) {
                    self.insert_sphere(p.home);
                }
            }
        }
        if self.rng.chance(0.3) {
            let key = keys[self.rng.below(keys.len())];
            if let Some(p) = self.proxies.get_mut(&key) {
                p.groups = some_groups(&mut self.rng);
                self.bp.set_groups(key, p.groups).expect("a live key");
            }
        }
    }

    /// Steps and checks the three lists against brute force over the test's own shapes, and
    /// `validate()`.
    fn check_step(&mut self, context: &str) -> (Pass, usize) {
        let proxies: Vec<brute::Proxy> = self
            .proxies
            .iter()
            .map(|(&key, p)| brute::Proxy {
                key,
                aabb: p.shape.aabb(),
                is_static: matches!(
                    p.shape,
                    Shape::Body {
                        kind: BodyKind::Static,
                        ..
                    }
                ),
            })
            .collect();
        let want: BTreeSet<Pair> = brute::sweep_pairs(&proxies)
            .into_iter()
            .filter(|q| self.proxies[&q.a].groups.allows(self.proxies[&q.b].groups))
            .collect();
        self.bp.step();
        let got: Vec<Pair> = self.bp.pairs().to_vec();
        assert!(
            got.windows(2).all(|w| w[0] < w[1]),
            "{context}: pairs not sorted"
        );
        let got_set: BTreeSet<Pair> = got.iter().copied().collect();
        if got_set != want {
            let missing: Vec<_> = want.difference(&got_set).take(3).collect();
            let extra: Vec<_> = got_set.difference(&want).take(3).collect();
            panic!("{context}: missing {missing:?}, extra {extra:?}");
        }
        let added: Vec<Pair> = want.difference(&self.prev).copied().collect();
        let removed: Vec<Pair> = self.prev.difference(&want).copied().collect();
        assert_eq!(self.bp.added(), &added[..], "{context}: added");
        assert_eq!(self.bp.removed(), &removed[..], "{context}: removed");
        self.prev = want;
        self.bp.validate();
        (self.bp.stats().pass, added.len() + removed.len())
    }
}

fn settled_pile(passes: Passes, seed: u64, steps: usize, still: f32) {
    let mut w = World::new(passes, seed);
    w.still = still;
    w.check_step("first step");
    let (mut incremental, mut changes, mut skipped) = (0, 0, 0);
    for step in 0..steps {
        w.jitter();
        if step % 3 == 0 {
            w.churn();
        }
        let (pass, events) = w.check_step(&format!("{passes:?} seed {seed} step {step}"));
        let s = w.bp.stats();
        changes += events;
        if pass == Pass::Incremental {
            incremental += 1;
            skipped += s.candidates.saturating_sub(s.candidates_tested);
        }
    }
    // Not vacuous: pairs start and stop overlapping, and the forced incremental pass skips
    // candidates.
    assert!(changes > steps / 2, "{changes} events in {steps} steps");
    if passes == Passes::Incremental {
        assert_eq!(incremental, steps);
        assert!(skipped > 0, "nothing skipped");
    }
}

#[test]
fn settled_pile_incremental_equals_brute_force_every_step() {
    settled_pile(Passes::Incremental, 1, 120, 0.1);
    settled_pile(Passes::Incremental, 2, 60, 0.1);
    // Few movers: the loud proxies' candidates are looked up, not scanned for.
    settled_pile(Passes::Incremental, 5, 120, 0.995);
}

#[test]
fn settled_pile_adaptive_equals_brute_force_every_step() {
    settled_pile(Passes::Adaptive, 3, 120, 0.1);
    settled_pile(Passes::Adaptive, 6, 60, 0.99);
}

#[test]
fn settled_pile_full_equals_brute_force_every_step() {
    settled_pile(Passes::Full, 4, 40, 0.1);
}

/// Steps with many movers scan the candidates for the loud proxies' and leave the reverse
/// index; steps with few look them up through it, building it again first. Blocks of each,
/// alternating, stay exact, and `validate` checks the index after every step that kept it.
#[test]
fn alternating_many_and_few_movers_stay_exact() {
    let mut w = World::new(Passes::Incremental, 7);
    w.check_step("first step");
    for step in 0..120 {
        w.still = if (step / 5) % 2 == 0 { 0.1 } else { 0.995 };
        w.jitter();
        w.check_step(&format!("alternating step {step}"));
    }
}
