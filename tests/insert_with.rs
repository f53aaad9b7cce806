//! `insert_sphere_with` and `insert_body_with` insert a proxy with its collision groups in one
//! call, and `contains` says whether a key is live. Random worlds (spheres, dynamic and static
//! bodies inserted with random groups, moved, teleported and removed) run on two broadphases:
//! one inserts through the one-call forms, the other through the plain forms followed by
//! `set_groups`. After every step the first one's `pairs`, `added` and `removed` equal the
//! test's own brute force with the groups rule and its own set difference, its `stats()` (the
//! proxies updated and escaped, the pass, the pairs) equal the second one's, so the one call
//! marks a new proxy once like the two, and `validate()` holds. `contains` agrees with the
//! model for every live key, every removed key and the null key. Bad input (a NaN, infinite
//! centre or radius, a negative radius, a box with a NaN or infinite corner or inverted) is
//! refused with the plain form's error, and nothing changes: no key, the same `len`, and the
//! next step's lists still equal the model's. Under `Passes` Adaptive, Full and Incremental,
//! with margins 0 and 0.1.

mod common;

use broadleaf::{
    Aabb, BodyKind, BroadPhase, CollisionGroups, Config, Error, Passes, ProxyKey, StepStats, Vec3,
};
use common::{KeyPair, Model, ModelShape, Rng};
use std::collections::{BTreeSet, HashMap};

/// Half the side of the cube the worlds live in, in metres: small enough for many overlaps.
const REGION: f32 = 8.0;
/// Proxies inserted before the first step; the population then drifts between `LOW` and
/// `HIGH`.
const INITIAL: usize = 120;
const LOW: usize = 80;
const HIGH: usize = 160;
/// Steps per Config.
const STEPS: usize = 150;

/// A mask over a few bits: mostly a subset of bits 0–3 (so pairs are often filtered),
/// sometimes all bits.
fn random_mask(rng: &mut Rng) -> u32 {
    if rng.chance(0.15) {
        u32::MAX
    } else {
        rng.below(16) as u32
    }
}

fn random_groups(rng: &mut Rng) -> CollisionGroups {
    if rng.chance(0.2) {
        return CollisionGroups::ALL;
    }
    CollisionGroups {
        memberships: random_mask(rng),
        filter: random_mask(rng),
    }
}

fn random_shape(rng: &mut Rng) -> ModelShape {
    let c = rng.offset(REGION);
    match rng.below(10) {
        0..=5 => ModelShape::Sphere {
            center: c,
            radius: rng.range(0.2, 1.5),
        },
        6..=8 => ModelShape::body(c, rng.vec3_in(Vec3::splat(0.1), Vec3::splat(1.5)), false),
        _ => ModelShape::body(c, rng.vec3_in(Vec3::splat(0.1), Vec3::splat(2.0)), true),
    }
}

fn body_kind(is_static: bool) -> BodyKind {
    if is_static {
        BodyKind::Static
    } else {
        BodyKind::Dynamic
    }
}

/// Inserts `shape` with `groups` through the one-call forms.
fn insert_with(
    bp: &mut BroadPhase,
    shape: &ModelShape,
    groups: CollisionGroups,
) -> Result<ProxyKey, Error> {
    match *shape {
        ModelShape::Sphere { center, radius } => bp.insert_sphere_with(center, radius, groups),
        ModelShape::Body { aabb, is_static } => {
            bp.insert_body_with(aabb, body_kind(is_static), groups)
        }
    }
}

/// The parts of the stats both forms must agree on.
fn comparable(s: StepStats) -> String {
    format!(
        "pass {:?}, updated {}, escaped {}, candidates {}/{}, pairs {}",
        s.pass, s.updated, s.escaped, s.candidates_tested, s.candidates, s.pairs
    )
}

/// The broadphase under test (one-call inserts), its twin (insert then `set_groups`), the
/// model of their shapes and groups, and the test's own previous pair set.
struct World {
    bp: BroadPhase,
    twin: BroadPhase,
    model: Model,
    rng: Rng,
    groups: HashMap<ProxyKey, CollisionGroups>,
    prev: Vec<KeyPair>,
    removed: Vec<ProxyKey>,
}

impl World {
    fn new(config: Config, seed: u64) -> Self {
        Self {
            bp: BroadPhase::new(config),
            twin: BroadPhase::new(config),
            model: Model::new(config.margin),
            rng: Rng::new(seed),
            groups: HashMap::new(),
            prev: Vec::new(),
            removed: Vec::new(),
        }
    }

    /// Inserts a random shape with random groups in both; the keys agree (same slots) and the
    /// groups read back.
    fn insert(&mut self, context: &str) {
        let shape = random_shape(&mut self.rng);
        let groups = random_groups(&mut self.rng);
        let key = insert_with(&mut self.bp, &shape, groups).expect("a good shape is inserted");
        let twin = shape.insert_into(&mut self.twin).expect("the twin inserts");
        self.twin.set_groups(twin, groups).expect("a live key");
        assert_eq!(key, twin, "{context}: the two forms gave different keys");
        assert!(
            self.bp.contains(key),
            "{context}: new {key:?} not contained"
        );
        assert_eq!(self.bp.groups(key), Some(groups), "{context}: groups");
        assert_eq!(self.bp.shape(key), self.twin.shape(key), "{context}: shape");
        self.model.shapes.insert(key, shape);
        self.groups.insert(key, groups);
    }

    fn pick(&mut self) -> Option<ProxyKey> {
        let keys = self.model.keys();
        (!keys.is_empty()).then(|| keys[self.rng.below(keys.len())])
    }

    /// One random operation: insert, move, teleport or remove, in both.
    fn operate(&mut self, context: &str) {
        let n = self.model.shapes.len();
        let op = match n {
            _ if n < LOW => 0,
            _ if n > HIGH => 6,
            _ => self.rng.below(8),
        };
        if op <= 1 {
            return self.insert(context);
        }
        let Some(key) = self.pick() else {
            return;
        };
        let shape = self.model.shapes[&key];
        let to = match op {
            2..=4 => shape.moved(self.rng.offset(0.5)),
            5 => shape.teleported(self.rng.offset(REGION)),
            _ => {
                self.bp.remove(key).expect("a live key is removed");
                self.twin.remove(key).expect("the twin removes");
                self.model.shapes.remove(&key);
                self.groups.remove(&key);
                self.removed.push(key);
                return;
            }
        };
        to.update_in(&mut self.bp, key).expect("a live key moves");
        to.update_in(&mut self.twin, key).expect("the twin moves");
        self.model.shapes.insert(key, to);
    }

    /// A bad sphere or box, through the one-call form, is refused with the error the plain
    /// form gives it, and changes nothing the test can see now (the next step checks the rest).
    fn try_bad(&mut self, context: &str) {
        let good = Vec3::new(1.0, 2.0, 3.0);
        let groups = random_groups(&mut self.rng);
        let len = self.bp.len();
        let got = match self.rng.below(8) {
            0 => self
                .bp
                .insert_sphere_with(Vec3::new(f32::NAN, 0.0, 0.0), 1.0, groups),
            1 => self
                .bp
                .insert_sphere_with(Vec3::new(0.0, f32::INFINITY, 0.0), 1.0, groups),
            2 => self.bp.insert_sphere_with(good, f32::NAN, groups),
            3 => self.bp.insert_sphere_with(good, f32::INFINITY, groups),
            4 => self.bp.insert_sphere_with(good, -0.5, groups),
            5 => {
                let aabb = Aabb::new(Vec3::new(0.0, 0.0, f32::NAN), Vec3::ONE);
                self.bp.insert_body_with(aabb, BodyKind::Dynamic, groups)
            }
            6 => {
                let aabb = Aabb::new(Vec3::ZERO, Vec3::new(f32::NEG_INFINITY, 1.0, 1.0));
                self.bp.insert_body_with(aabb, BodyKind::Static, groups)
            }
            _ => {
                let aabb = Aabb::new(Vec3::ONE, Vec3::new(2.0, 0.5, 2.0));
                self.bp.insert_body_with(aabb, BodyKind::Dynamic, groups)
            }
        };
        let err = got.expect_err("bad input is refused");
        let expected = matches!(
            err,
            Error::NonFinite { .. } | Error::NegativeRadius(_) | Error::InvertedAabb { .. }
        );
        assert!(expected, "{context}: bad input refused with {err:?}");
        assert_eq!(
            self.bp.len(),
            len,
            "{context}: a refused insert changed len"
        );
    }

    /// Plain-form errors for the same bad input, so the one-call form is known to give the
    /// same: checked once per world on a fresh broadphase.
    fn same_errors_as_plain(config: Config) {
        let g = CollisionGroups {
            memberships: 1,
            filter: 2,
        };
        let spheres = [
            (Vec3::new(f32::NAN, 0.0, 0.0), 1.0),
            (Vec3::ZERO, f32::INFINITY),
            (Vec3::ZERO, -1.0),
        ];
        let boxes = [
            Aabb::new(Vec3::new(0.0, f32::NAN, 0.0), Vec3::ONE),
            Aabb::new(Vec3::ONE, Vec3::ZERO),
        ];
        let (mut a, mut b) = (BroadPhase::new(config), BroadPhase::new(config));
        for (c, r) in spheres {
            let (x, y) = (a.insert_sphere_with(c, r, g), b.insert_sphere(c, r));
            assert!(x.is_err(), "sphere {c} {r} accepted");
            // Compared as text: the errors carry the NaN they refused, which equals nothing.
            assert_eq!(
                format!("{x:?}"),
                format!("{y:?}"),
                "sphere {c} {r}: the forms disagree"
            );
        }
        for aabb in boxes {
            let x = a.insert_body_with(aabb, BodyKind::Static, g);
            let y = b.insert_body(aabb, BodyKind::Static);
            assert!(x.is_err(), "box {aabb:?} accepted");
            assert_eq!(
                format!("{x:?}"),
                format!("{y:?}"),
                "box {aabb:?}: the forms disagree"
            );
        }
        assert!(a.is_empty(), "a refused insert left a proxy");
    }

    /// `contains` for every live key, every removed key and the null key.
    fn check_contains(&self, context: &str) {
        for key in self.model.keys() {
            assert!(
                self.bp.contains(key),
                "{context}: live {key:?} not contained"
            );
        }
        for key in &self.removed {
            assert!(
                !self.bp.contains(*key),
                "{context}: removed {key:?} contained"
            );
        }
        assert!(
            !self.bp.contains(ProxyKey::default()),
            "{context}: null key"
        );
    }

    /// The model's pairs with the groups rule, sorted.
    fn expected_pairs(&self) -> Vec<KeyPair> {
        self.model
            .pairs_sweep()
            .into_iter()
            .filter(|(a, b)| self.groups[a].allows(self.groups[b]))
            .collect()
    }

    /// Steps both and checks the lists against the test's own, the stats against the twin's,
    /// `contains`, and `validate()`.
    fn step(&mut self, context: &str) {
        let want = self.expected_pairs();
        let (now, before): (BTreeSet<KeyPair>, BTreeSet<KeyPair>) = (
            want.iter().copied().collect(),
            self.prev.iter().copied().collect(),
        );
        let added: Vec<KeyPair> = now.difference(&before).copied().collect();
        let removed: Vec<KeyPair> = before.difference(&now).copied().collect();
        self.bp.step();
        self.twin.step();
        let m = &self.model;
        m.assert_list(context, "pairs", self.bp.pairs(), &want);
        m.assert_list(context, "added", self.bp.added(), &added);
        m.assert_list(context, "removed", self.bp.removed(), &removed);
        assert_eq!(
            comparable(self.bp.stats()),
            comparable(self.twin.stats()),
            "{context}: the one-call inserts' stats differ from insert + set_groups"
        );
        self.bp.validate();
        self.check_contains(context);
        self.prev = want;
    }
}

fn run(config: Config, seed: u64) {
    let name = format!("{config:?}");
    World::same_errors_as_plain(config);
    let mut w = World::new(config, seed);
    for _ in 0..INITIAL {
        w.insert(&name);
    }
    w.step(&format!("{name}, first step"));
    for s in 0..STEPS {
        let context = format!("{name}, step {s}");
        for _ in 0..1 + w.rng.below(10) {
            w.operate(&context);
        }
        if w.rng.chance(0.3) {
            w.try_bad(&context);
        }
        w.step(&context);
    }
    assert!(
        !w.removed.is_empty(),
        "{name}: no proxy was removed, so contains was never checked on a stale key"
    );
}

#[test]
fn one_call_inserts_match_the_model_and_insert_then_set_groups() {
    for (i, passes) in [Passes::Adaptive, Passes::Full, Passes::Incremental]
        .into_iter()
        .enumerate()
    {
        for (j, margin) in [0.0, 0.1].into_iter().enumerate() {
            let config = Config {
                margin,
                passes,
                ..Config::default()
            };
            run(config, 0x1257_0000 + (i * 2 + j) as u64);
        }
    }
}
