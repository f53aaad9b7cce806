//! Collision groups filter pairs by bevy_rapier's rule and nothing else: a pair is reported iff
//! the two (margin-grown) boxes overlap, they are not both static, and
//! `a.memberships & b.filter != 0 && b.memberships & a.filter != 0`. Random worlds (spheres,
//! dynamic and static bodies inserted, moved, teleported and removed) have their groups set
//! and changed at random, with masks over a few bits so that some overlapping pairs are
//! filtered, some steps changing nothing but groups; after every step `pairs` equals the
//! test's own brute force with the groups rule, and `added` / `removed` its own set difference
//! with the previous step, so a group change shows in the next step's lists. `groups(key)`
//! reads back what was set (the default, all / all, for a new proxy); a stale or null key is
//! refused with `UnknownProxy` and changes nothing. Under `Passes` Adaptive, Full and
//! Incremental, with margins 0 and 0.1.

mod common;

use broadleaf::{BroadPhase, CollisionGroups, Config, Error, Passes, ProxyKey, Vec3};
use common::{KeyPair, Model, ModelShape, Rng};
use std::collections::{BTreeSet, HashMap};

/// Half the side of the cube the worlds live in, in metres: small enough for many overlaps.
const REGION: f32 = 8.0;
/// Proxies inserted before the first step; the population then drifts between `LOW` and
/// `HIGH`.
const INITIAL: usize = 150;
const LOW: usize = 100;
const HIGH: usize = 200;
/// Steps per Config.
const STEPS: usize = 250;

/// Groups as the test keeps them: `(memberships, filter)`, so the test relies on no derive of
/// `CollisionGroups`.
type Masks = (u32, u32);

/// The default groups: member of all, filtering none out.
const ALL: Masks = (u32::MAX, u32::MAX);

fn groups(m: Masks) -> CollisionGroups {
    CollisionGroups {
        memberships: m.0,
        filter: m.1,
    }
}

fn masks(g: CollisionGroups) -> Masks {
    (g.memberships, g.filter)
}

/// A mask over a few bits: mostly any of the 16 subsets of bits 0–3 (so pairs are often
/// filtered), sometimes all bits, none, or bit 31 with two low bits (the high bits count too).
fn random_mask(rng: &mut Rng) -> u32 {
    match rng.below(20) {
        0..=1 => u32::MAX,
        2 => 0,
        3..=4 => 1 << 31 | rng.below(4) as u32,
        _ => rng.below(16) as u32,
    }
}

fn random_masks(rng: &mut Rng) -> Masks {
    (random_mask(rng), random_mask(rng))
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

/// One broadphase, the model of its shapes, the groups the test set, and its own previous
/// pair set.
struct World {
    bp: BroadPhase,
    model: Model,
    rng: Rng,
    /// Groups of the live proxies whose groups were set; the others have `ALL`.
    groups: HashMap<ProxyKey, Masks>,
    prev: Vec<KeyPair>,
    removed: Vec<ProxyKey>,
}

impl World {
    fn new(config: Config, seed: u64) -> Self {
        Self {
            bp: BroadPhase::new(config),
            model: Model::new(config.margin),
            rng: Rng::new(seed),
            groups: HashMap::new(),
            prev: Vec::new(),
            removed: Vec::new(),
        }
    }

    fn groups_of(&self, key: ProxyKey) -> Masks {
        self.groups.get(&key).copied().unwrap_or(ALL)
    }

    /// Inserts a random shape: its groups read back as the default.
    fn insert(&mut self, context: &str) -> ProxyKey {
        let shape = random_shape(&mut self.rng);
        let key = self.model.insert(&mut self.bp, shape);
        let got = self.bp.groups(key).map(masks);
        assert_eq!(got, Some(ALL), "{context}: new {key:?} has groups {got:?}");
        key
    }

    /// Sets `key`'s groups in both; the broadphase must accept and read them back.
    fn set(&mut self, key: ProxyKey, m: Masks, context: &str) {
        self.bp
            .set_groups(key, groups(m))
            .expect("a live key's groups are set");
        self.groups.insert(key, m);
        let got = self.bp.groups(key).map(masks);
        assert_eq!(
            got,
            Some(m),
            "{context}: {key:?}'s groups read back as {got:?}"
        );
    }

    fn pick(&mut self) -> Option<ProxyKey> {
        let keys = self.model.keys();
        (!keys.is_empty()).then(|| keys[self.rng.below(keys.len())])
    }

    /// One random operation: insert (sometimes with groups), move, teleport, remove or set
    /// groups.
    fn operate(&mut self, context: &str) {
        let n = self.model.shapes.len();
        let op = if n < LOW {
            0
        } else if n > HIGH {
            6
        } else {
            self.rng.below(10)
        };
        if op <= 1 {
            let key = self.insert(context);
            if self.rng.chance(0.5) {
                let m = random_masks(&mut self.rng);
                self.set(key, m, context);
            }
            return;
        }
        let Some(key) = self.pick() else {
            return;
        };
        let shape = self.model.shapes[&key];
        match op {
            2..=4 => {
                let d = self.rng.offset(0.5);
                self.model.update(&mut self.bp, key, shape.moved(d));
            }
            5 => {
                let to = self.rng.offset(REGION);
                self.model.update(&mut self.bp, key, shape.teleported(to));
            }
            6 => {
                self.model.remove(&mut self.bp, key);
                self.groups.remove(&key);
                self.removed.push(key);
            }
            _ => self.set_random_groups(key, context),
        }
    }

    /// New random groups for `key`, now and then the default again.
    fn set_random_groups(&mut self, key: ProxyKey, context: &str) {
        let m = if self.rng.chance(0.15) {
            ALL
        } else {
            random_masks(&mut self.rng)
        };
        self.set(key, m, context);
    }

    /// A stale (removed) or null key is refused with `UnknownProxy` and changes nothing: the
    /// live proxies' groups and the next step's lists are checked as usual.
    fn try_stale(&mut self, context: &str) {
        let stale = if self.removed.is_empty() || self.rng.chance(0.2) {
            ProxyKey::default()
        } else {
            self.removed[self.rng.below(self.removed.len())]
        };
        let m = random_masks(&mut self.rng);
        assert!(
            matches!(
                self.bp.set_groups(stale, groups(m)),
                Err(Error::UnknownProxy)
            ),
            "{context}: set_groups on the stale {stale:?} is not refused with UnknownProxy"
        );
        assert!(
            self.bp.groups(stale).is_none(),
            "{context}: the stale {stale:?} has groups"
        );
        assert_eq!(self.bp.len(), self.model.shapes.len(), "{context}: len");
    }

    /// The model's pairs with the groups rule, sorted.
    fn expected_pairs(&self) -> Vec<KeyPair> {
        self.model
            .pairs_quadratic()
            .into_iter()
            .filter(|&(a, b)| {
                let (ga, gb) = (self.groups_of(a), self.groups_of(b));
                ga.0 & gb.1 != 0 && gb.0 & ga.1 != 0
            })
            .collect()
    }

    /// Steps and checks the three lists against the test's own, every live key's groups, and
    /// `validate()`; returns the number of pairs the groups filtered out.
    fn step(&mut self, context: &str) -> usize {
        let all = self.model.pairs_quadratic().len();
        let want = self.expected_pairs();
        let (now, before): (BTreeSet<KeyPair>, BTreeSet<KeyPair>) = (
            want.iter().copied().collect(),
            self.prev.iter().copied().collect(),
        );
        let added: Vec<KeyPair> = now.difference(&before).copied().collect();
        let removed: Vec<KeyPair> = before.difference(&now).copied().collect();
        self.bp.step();
        self.model
            .assert_list(context, "pairs", self.bp.pairs(), &want);
        self.model
            .assert_list(context, "added", self.bp.added(), &added);
        self.model
            .assert_list(context, "removed", self.bp.removed(), &removed);
        self.bp.validate();
        for key in self.model.keys() {
            let got = self.bp.groups(key).map(masks);
            let set = self.groups_of(key);
            assert_eq!(got, Some(set), "{context}: {key:?}'s groups");
        }
        for &key in &self.removed {
            assert!(
                self.bp.groups(key).is_none(),
                "{context}: removed {key:?} has groups"
            );
        }
        let filtered = all - want.len();
        self.prev = want;
        filtered
    }
}

/// Random worlds under `config`: inserts, moves, teleports, removes and group changes, some
/// steps with group changes only, a stale key tried now and then; every step checked.
fn run(config: Config, seed: u64) {
    let name = format!("{config:?}");
    let mut w = World::new(config, seed);
    for _ in 0..INITIAL {
        let key = w.insert(&name);
        if w.rng.chance(0.6) {
            let m = random_masks(&mut w.rng);
            w.set(key, m, &name);
        }
    }
    let mut filtered = w.step(&format!("{name}, first step"));
    let mut changed_only_groups = 0;
    for s in 0..STEPS {
        let context = format!("{name}, step {s}");
        if w.rng.chance(0.2) {
            // Nothing moves: only groups change, and the lists must follow them.
            for _ in 0..1 + w.rng.below(6) {
                if let Some(key) = w.pick() {
                    w.set_random_groups(key, &context);
                }
            }
            changed_only_groups += 1;
        } else {
            for _ in 0..1 + w.rng.below(12) {
                w.operate(&context);
            }
        }
        if w.rng.chance(0.2) {
            w.try_stale(&context);
        }
        filtered += w.step(&context);
    }
    assert!(filtered > 0, "{name}: the groups never filtered a pair");
    assert!(
        changed_only_groups > 0,
        "{name}: no step changed only groups"
    );
}

fn configs() -> Vec<Config> {
    let mut out = Vec::new();
    for passes in [Passes::Adaptive, Passes::Full, Passes::Incremental] {
        for margin in [0.0, 0.1] {
            out.push(Config {
                margin,
                passes,
                ..Config::default()
            });
        }
    }
    out
}

#[test]
fn pairs_follow_the_groups_rule_every_step_under_adaptive_passes() {
    for (i, config) in configs().into_iter().enumerate() {
        if config.passes == Passes::Adaptive {
            run(config, 0x6709_0000 + i as u64);
        }
    }
}

#[test]
fn pairs_follow_the_groups_rule_every_step_under_full_passes() {
    for (i, config) in configs().into_iter().enumerate() {
        if config.passes == Passes::Full {
            run(config, 0x6709_0000 + i as u64);
        }
    }
}

#[test]
fn pairs_follow_the_groups_rule_every_step_under_incremental_passes() {
    for (i, config) in configs().into_iter().enumerate() {
        if config.passes == Passes::Incremental {
            run(config, 0x6709_0000 + i as u64);
        }
    }
}

/// The default is all / all; a group change alone (nothing moved) shows in the very next
/// step's lists, both ways; a change that keeps a pair allowed changes nothing; a refused one
/// changes nothing.
#[test]
fn a_group_change_alone_shows_in_the_next_step() {
    let d = CollisionGroups::default();
    assert_eq!((d.memberships, d.filter), ALL, "CollisionGroups::default()");
    for passes in [Passes::Adaptive, Passes::Full, Passes::Incremental] {
        for margin in [0.0, 0.1] {
            let context = format!("{passes:?}, margin {margin}");
            let mut model = Model::new(margin);
            let mut bp = BroadPhase::new(Config {
                margin,
                passes,
                ..Config::default()
            });
            let a = model.insert(&mut bp, ModelShape::body(Vec3::ZERO, Vec3::ONE, false));
            let b = model.insert(
                &mut bp,
                ModelShape::Sphere {
                    center: Vec3::new(1.5, 0.0, 0.0),
                    radius: 1.0,
                },
            );
            let s = model.insert(&mut bp, ModelShape::body(Vec3::ZERO, Vec3::ONE, true));
            let t = model.insert(&mut bp, ModelShape::body(Vec3::Y, Vec3::ONE, true));
            let ab = if a < b { (a, b) } else { (b, a) };
            let all = model.pairs_quadratic();
            assert!(all.contains(&ab) && all.len() == 5, "{context}: the scene");
            let lists = |bp: &mut BroadPhase| {
                bp.step();
                let pick = |l: &[broadleaf::Pair]| l.iter().map(|p| (p.a, p.b)).collect();
                let got: (Vec<KeyPair>, Vec<KeyPair>, Vec<KeyPair>) =
                    (pick(bp.pairs()), pick(bp.added()), pick(bp.removed()));
                got
            };
            let (pairs, added, _) = lists(&mut bp);
            assert_eq!((pairs.len(), added.len()), (5, 5), "{context}: first step");
            // `a` is in group 1 and filters group 2 in; `b` (default) is in every group.
            bp.set_groups(a, groups((1, 2))).unwrap();
            assert_eq!(lists(&mut bp), (all.clone(), vec![], vec![]), "{context}");
            // `b` only in group 4: `a` no longer accepts it; only `ab` goes.
            bp.set_groups(b, groups((4, u32::MAX))).unwrap();
            let without: Vec<KeyPair> = all.iter().copied().filter(|&p| p != ab).collect();
            assert_eq!(
                lists(&mut bp),
                (without.clone(), vec![], vec![ab]),
                "{context}: filtered"
            );
            assert_eq!(
                lists(&mut bp),
                (without.clone(), vec![], vec![]),
                "{context}: nothing changed"
            );
            // A refused change changes nothing.
            bp.remove(t).unwrap();
            let without_t: Vec<KeyPair> = without
                .iter()
                .copied()
                .filter(|&(x, y)| x != t && y != t)
                .collect();
            let gone: Vec<KeyPair> = without
                .iter()
                .copied()
                .filter(|&(x, y)| x == t || y == t)
                .collect();
            assert!(matches!(
                bp.set_groups(t, groups(ALL)),
                Err(Error::UnknownProxy)
            ));
            assert_eq!(
                lists(&mut bp),
                (without_t.clone(), vec![], gone),
                "{context}"
            );
            // `a` accepts group 4 again: `ab` is back.
            bp.set_groups(a, groups((1, 6))).unwrap();
            let mut back = without_t.clone();
            back.push(ab);
            back.sort_unstable();
            assert_eq!(lists(&mut bp), (back, vec![ab], vec![]), "{context}: back");
            assert_eq!(bp.groups(a).map(masks), Some((1, 6)), "{context}");
            assert_eq!(bp.groups(b).map(masks), Some((4, u32::MAX)), "{context}");
            assert_eq!(bp.groups(s).map(masks), Some(ALL), "{context}");
            assert!(bp.groups(t).is_none(), "{context}: removed");
        }
    }
}
