//! Batches are checked whole: `update_spheres` / `update_centers` / `update_bodies` with good
//! entries and bad ones
//! (NaN or infinite coordinates or radius, a negative radius, an inverted box, a stale key, a
//! key of the other kind) at random positions. On `Err` the `BatchError` names the first bad
//! entry with the right error, and nothing changed: `len()`, every `aabb()`, and the next
//! step's lists equal those of a twin `BroadPhase` that got no batch and of the test's model.
//! On `Ok` the result equals applying the entries one by one (a key given twice: the last
//! wins): same lists and boxes as a twin that got the per-object calls, and as the model.
//! `update_centers` keeps each sphere's radius (its entries' radius defects do not apply to
//! it), and refuses slices of different lengths at the first index only one of them has.

mod common;

use broadleaf::{Aabb, BatchError, BroadPhase, Config, Error, ProxyKey, Vec3};
use common::{Model, ModelShape, Rng, uniform};
use proptest::prelude::*;

/// What is wrong with an entry, if anything.
#[derive(Clone, Copy, Debug)]
enum Defect {
    None,
    /// NaN in a coordinate (axis; for bodies `min` or `max`).
    Nan(usize, bool),
    /// ±∞ in a coordinate.
    Inf(usize, bool, bool),
    /// A sphere's radius NaN or +∞; for a body, `min > max` on an axis by this much instead.
    BadSize(usize, f32),
    /// A radius below zero (a body: inverted on axis 0).
    Negative(f32),
    Stale,
    WrongKind,
}

#[derive(Clone, Copy, Debug)]
struct Entry {
    /// Which proxy (of the batch's kind, or a stale or wrong-kind key); small, so picks repeat.
    pick: usize,
    /// The move: an offset, scaled by `scale`, and a new size.
    offset: Vec3,
    scale: f32,
    size: f32,
    defect: Defect,
}

fn entry() -> impl Strategy<Value = Entry> {
    let axis = 0usize..3;
    let defect = prop_oneof![
        12 => Just(Defect::None),
        1 => (axis.clone(), any::<bool>()).prop_map(|(a, m)| Defect::Nan(a, m)),
        1 => (axis.clone(), any::<bool>(), any::<bool>()).prop_map(|(a, m, n)| Defect::Inf(a, m, n)),
        1 => (axis, prop_oneof![Just(f32::NAN), Just(f32::INFINITY), uniform(1e-6, 3.0)])
            .prop_map(|(a, g)| Defect::BadSize(a, g)),
        1 => prop_oneof![Just(-f32::MIN_POSITIVE), uniform(-5.0, -1e-7)].prop_map(Defect::Negative),
        1 => Just(Defect::Stale),
        1 => Just(Defect::WrongKind),
    ];
    let offset = (uniform(-1.0, 1.0), uniform(-1.0, 1.0), uniform(-1.0, 1.0))
        .prop_map(|(x, y, z)| Vec3::new(x, y, z));
    let scale = prop_oneof![Just(1e-4f32), Just(0.05f32), Just(1.0f32), Just(700.0f32)];
    (0usize..10, offset, scale, uniform(0.0, 1.5), defect).prop_map(
        |(pick, offset, scale, size, defect)| Entry {
            pick,
            offset,
            scale,
            size,
            defect,
        },
    )
}

/// Which batch call a batch goes through.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Call {
    Spheres,
    Centers,
    Bodies,
}

/// The world both twins hold: spheres, dynamic and static bodies in a ±6 m box, some removed
/// (their keys are the stale ones).
struct World {
    a: BroadPhase,
    b: BroadPhase,
    model: Model,
    stale: Vec<ProxyKey>,
}

impl World {
    fn new(config: Config, seed: u64) -> Self {
        let (mut a, mut b) = (BroadPhase::new(config), BroadPhase::new(config));
        let mut model = Model::new(config.margin);
        let mut rng = Rng::new(seed);
        let mut keys = Vec::new();
        for _ in 0..70 {
            let c = rng.offset(6.0);
            let shape = match rng.below(8) {
                0 => ModelShape::body(c, Vec3::splat(rng.range(0.0, 1.5)), true),
                1 | 2 => ModelShape::body(c, Vec3::splat(rng.range(0.0, 1.5)), false),
                _ => ModelShape::Sphere {
                    center: c,
                    radius: rng.range(0.0, 1.2),
                },
            };
            let key = model.insert(&mut a, shape);
            assert_eq!(
                shape.insert_into(&mut b),
                Ok(key),
                "twins issue the same keys"
            );
            keys.push(key);
        }
        let mut stale = Vec::new();
        for key in keys.into_iter().step_by(7) {
            model.remove(&mut a, key);
            b.remove(key).unwrap();
            stale.push(key);
        }
        Self { a, b, model, stale }
    }

    /// Applies one batch through `call` to `a`; on `Ok` gives `b` the same entries one by one.
    fn batch(&mut self, call: Call, entries: &[Entry]) {
        let spheres = call != Call::Bodies;
        let of_kind = |model: &Model, sphere: bool| -> Vec<ProxyKey> {
            let keys = model.keys().into_iter();
            keys.filter(|k| model.shapes[k].is_sphere() == sphere)
                .collect()
        };
        let (mine, others) = (
            of_kind(&self.model, spheres),
            of_kind(&self.model, !spheres),
        );
        if mine.is_empty() || others.is_empty() {
            return;
        }
        let mut batch: Vec<(ProxyKey, ModelShape)> = Vec::new();
        let mut first_bad: Option<(usize, Error)> = None;
        for (index, e) in entries.iter().enumerate() {
            let key = mine[e.pick % mine.len()];
            let s = self.model.shapes[&key];
            let (size, e) = match (call, s, e.defect) {
                // A centre update keeps the radius, so a radius defect has nothing to spoil.
                (Call::Centers, ModelShape::Sphere { radius, .. }, d) => {
                    let keeps = matches!(d, Defect::BadSize(..) | Defect::Negative(_));
                    let mut e = *e;
                    if keeps {
                        e.defect = Defect::None;
                    }
                    (radius, e)
                }
                _ => (e.size, *e),
            };
            let good = s.placed(s.center() + e.offset * e.scale, size);
            let (key, shape, error) = spoil(good, key, &e, &self.stale, &others);
            if let (None, Some(error)) = (first_bad, error) {
                first_bad = Some((index, error));
            }
            batch.push((key, shape));
        }
        let got = if call == Call::Centers {
            let keys: Vec<ProxyKey> = batch.iter().map(|&(k, _)| k).collect();
            let centers: Vec<Vec3> = batch.iter().map(|&(_, s)| s.center()).collect();
            self.a.update_centers(&keys, &centers)
        } else if spheres {
            let b: Vec<_> = batch
                .iter()
                .map(|&(k, s)| match s {
                    ModelShape::Sphere { center, radius } => (k, center, radius),
                    ModelShape::Body { .. } => unreachable!("a sphere batch"),
                })
                .collect();
            self.a.update_spheres(&b)
        } else {
            let b: Vec<_> = batch.iter().map(|&(k, s)| (k, s.user_box())).collect();
            self.a.update_bodies(&b)
        };
        match first_bad {
            Some((index, error)) => {
                let got = got.expect_err("a batch with a bad entry is refused");
                assert_eq!(got.index, index, "{batch:?}");
                assert_same_error(got, error);
            }
            None => {
                assert_eq!(got, Ok(()), "a good batch is accepted");
                for (key, shape) in batch {
                    self.model.shapes.insert(key, shape);
                    shape.update_in(&mut self.b, key).unwrap();
                }
            }
        }
        self.model.assert_same_proxies(&self.a, "a after the batch");
        self.model.assert_same_proxies(&self.b, "b after the batch");
    }

    /// The live spheres' keys, in key order.
    fn sphere_keys(&self) -> Vec<ProxyKey> {
        let keys = self.model.keys().into_iter();
        keys.filter(|k| self.model.shapes[k].is_sphere()).collect()
    }

    /// Steps both twins: each equals the model (so they equal each other).
    fn step(&mut self, context: &str) {
        let want = self.model.check_step(&mut self.a, context);
        self.b.step();
        self.model
            .assert_list(context, "b pairs", self.b.pairs(), &want.pairs);
        self.model
            .assert_list(context, "b added", self.b.added(), &want.added);
        self.model
            .assert_list(context, "b removed", self.b.removed(), &want.removed);
        self.b.validate();
    }
}

/// The entry `e` turns the good `(key, shape)` into: its key and shape, and the error the
/// batch must report for it (`None` for a good entry).
fn spoil(
    good: ModelShape,
    key: ProxyKey,
    e: &Entry,
    stale: &[ProxyKey],
    others: &[ProxyKey],
) -> (ProxyKey, ModelShape, Option<Error>) {
    let non_finite = Error::NonFinite {
        what: "",
        value: Vec3::ZERO,
    };
    let set = |v: &mut Vec3, axis: usize, x: f32| v[axis] = x;
    match (good, e.defect) {
        (_, Defect::None) => (key, good, None),
        (_, Defect::Stale) => (stale[e.pick % stale.len()], good, Some(Error::UnknownProxy)),
        (_, Defect::WrongKind) => (others[e.pick % others.len()], good, Some(Error::WrongKind)),
        (ModelShape::Sphere { mut center, radius }, Defect::Nan(axis, _)) => {
            set(&mut center, axis, f32::NAN);
            (key, ModelShape::Sphere { center, radius }, Some(non_finite))
        }
        (ModelShape::Sphere { mut center, radius }, Defect::Inf(axis, _, neg)) => {
            set(
                &mut center,
                axis,
                if neg {
                    f32::NEG_INFINITY
                } else {
                    f32::INFINITY
                },
            );
            (key, ModelShape::Sphere { center, radius }, Some(non_finite))
        }
        (ModelShape::Sphere { center, .. }, Defect::BadSize(_, g)) => {
            let radius = if g.is_finite() { f32::NAN } else { g };
            (key, ModelShape::Sphere { center, radius }, Some(non_finite))
        }
        (ModelShape::Sphere { center, .. }, Defect::Negative(radius)) => (
            key,
            ModelShape::Sphere { center, radius },
            Some(Error::NegativeRadius(radius)),
        ),
        (
            ModelShape::Body {
                mut aabb,
                is_static,
            },
            Defect::Nan(axis, max),
        ) => {
            set(
                if max { &mut aabb.max } else { &mut aabb.min },
                axis,
                f32::NAN,
            );
            (key, ModelShape::Body { aabb, is_static }, Some(non_finite))
        }
        (
            ModelShape::Body {
                mut aabb,
                is_static,
            },
            Defect::Inf(axis, max, neg),
        ) => {
            let x = if neg {
                f32::NEG_INFINITY
            } else {
                f32::INFINITY
            };
            set(if max { &mut aabb.max } else { &mut aabb.min }, axis, x);
            (key, ModelShape::Body { aabb, is_static }, Some(non_finite))
        }
        (
            ModelShape::Body {
                mut aabb,
                is_static,
            },
            Defect::BadSize(..) | Defect::Negative(_),
        ) => {
            let (axis, gap) = match e.defect {
                Defect::BadSize(axis, g) if g.is_finite() => (axis, g),
                Defect::BadSize(axis, _) => (axis, 1.0),
                _ => (0, 0.5),
            };
            // Above `max` even where `gap` is below half an ulp of it.
            let top = aabb.max[axis];
            set(&mut aabb.min, axis, (top + gap).max(top.next_up()));
            let error = Error::InvertedAabb {
                min: aabb.min,
                max: aabb.max,
            };
            (key, ModelShape::Body { aabb, is_static }, Some(error))
        }
    }
}

/// Same variant; values compared where they cannot be NaN.
fn assert_same_error(got: BatchError, want: Error) {
    match (got.error, want) {
        (Error::NonFinite { .. }, Error::NonFinite { .. }) => {}
        (g, w) => assert_eq!(g, w, "entry {}", got.index),
    }
}

fn run(config: Config, seed: u64, rounds: &[(Vec<Entry>, Vec<Entry>)]) {
    let mut world = World::new(config, seed);
    world.step("setup");
    for (n, (spheres, bodies)) in rounds.iter().enumerate() {
        let call = if n % 2 == 0 {
            Call::Spheres
        } else {
            Call::Centers
        };
        world.batch(call, spheres);
        world.batch(Call::Bodies, bodies);
        world.step(&format!("round {n}"));
    }
}

/// Per round a sphere batch and a body batch; half the batches have no bad entry.
fn rounds() -> impl Strategy<Value = Vec<(Vec<Entry>, Vec<Entry>)>> {
    let batch = || {
        (any::<bool>(), prop::collection::vec(entry(), 0..12)).prop_map(|(clean, mut b)| {
            if clean {
                b.iter_mut().for_each(|e| e.defect = Defect::None);
            }
            b
        })
    };
    prop::collection::vec((batch(), batch()), 1..8)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]

    #[test]
    fn batches_apply_whole_or_not_at_all(
        config in prop_oneof![
            Just(Config::default()),
            Just(Config { margin: 0.2, ..Config::default() }),
            Just(Config {
                bounds: Some(Aabb::new(Vec3::splat(-8.0), Vec3::splat(8.0))),
                skin: 0.1,
                ..Config::default()
            }),
        ],
        seed in any::<u64>(),
        rounds in rounds(),
    ) {
        run(config, seed, &rounds);
    }
}

/// A good prefix followed by one bad entry: none of the prefix is applied, though every entry
/// of it would have made new pairs.
#[test]
fn bad_last_entry_leaves_the_good_prefix_unapplied() {
    let mut world = World::new(Config::default(), 7);
    world.step("setup");
    let spheres = world.sphere_keys();
    let mut batch: Vec<_> = spheres.iter().map(|&k| (k, Vec3::ZERO, 1.0)).collect();
    batch.push((spheres[0], Vec3::new(0.0, f32::NAN, 0.0), 1.0));
    let err = world.a.update_spheres(&batch).unwrap_err();
    assert_eq!(err.index, spheres.len());
    assert!(matches!(err.error, Error::NonFinite { .. }), "{err:?}");
    world
        .model
        .assert_same_proxies(&world.a, "after the refused batch");
    world.step("after the refused batch");
}

/// `update_centers` with slices of different lengths is refused at the first index only one
/// of them has, naming both lengths; nothing is applied.
#[test]
fn centers_of_another_length_are_refused_whole() {
    let mut world = World::new(Config::default(), 11);
    world.step("setup");
    let spheres = world.sphere_keys();
    let centers = vec![Vec3::ZERO; spheres.len() + 1];
    for (keys, centers) in [
        (&spheres[..], &centers[..]),
        (&spheres[..], &centers[..spheres.len() - 1]),
        (&spheres[..0], &centers[..1]),
    ] {
        let err = world.a.update_centers(keys, centers).unwrap_err();
        assert_eq!(err.index, keys.len().min(centers.len()));
        assert_eq!(
            err.error,
            Error::LengthMismatch {
                keys: keys.len(),
                values: centers.len(),
            }
        );
        world
            .model
            .assert_same_proxies(&world.a, "after the refused batch");
    }
    assert_eq!(world.a.update_centers(&[], &[]), Ok(()));
    world.step("after the refused batches");
}

/// A key given twice in one batch ends where its last entry puts it, in both orders.
#[test]
fn a_key_given_twice_ends_at_its_last_entry() {
    let touching = Vec3::new(1.0, 0.0, 0.0);
    let far = Vec3::new(100.0, 0.0, 0.0);
    for (first, last) in [(far, touching), (touching, far)] {
        let mut bp = BroadPhase::new(Config::default());
        let mut model = Model::new(0.0);
        let wall = Aabb::new(Vec3::new(-1.0, -1.0, -1.0), Vec3::new(0.5, 1.0, 1.0));
        model.insert(
            &mut bp,
            ModelShape::Body {
                aabb: wall,
                is_static: true,
            },
        );
        let s = ModelShape::Sphere {
            center: Vec3::splat(50.0),
            radius: 0.5,
        };
        let key = model.insert(&mut bp, s);
        model.check_step(&mut bp, "setup");
        let batch = [
            (key, first, 0.5),
            (key, Vec3::splat(7.0), 2.0),
            (key, last, 0.5),
        ];
        assert_eq!(bp.update_spheres(&batch), Ok(()));
        model.shapes.insert(
            key,
            ModelShape::Sphere {
                center: last,
                radius: 0.5,
            },
        );
        let want = model.check_step(&mut bp, "after the batch");
        assert_eq!(want.pairs.len(), usize::from(last == touching));
    }
}
