//! Feature `parallel`: update batches large enough to be checked in parts over rayon's pool
//! (`update_spheres`, `update_centers`, `update_bodies` of 20 000 entries and more) give what
//! they give on one thread. Twins of a world of 22 000 spheres and 20 000 bodies take the
//! same batches, one in a pool of one thread and one in a pool of three (and of eight); a
//! batch has no bad entry, one at a random index, or several, the first anywhere from the
//! first entry to the last. A refused batch names the test's own first bad entry, with the
//! error that entry's single update gets, in both twins, and changes nothing (`len()`, every
//! shape); an accepted one leaves both twins with every entry's shape (a key given twice:
//! its last), and the next step's pairs equal in both and equal to the O(n²) model.
#![cfg(feature = "parallel")]

mod common;

use broadleaf::{Aabb, BatchError, BroadPhase, Config, ProxyKey, Vec3};
use common::{Model, ModelShape, Rng};

const SPHERES: usize = 22_000;
const BODIES: usize = 20_000;
const HALF: f32 = 60.0;

/// Which batch call.
#[derive(Clone, Copy, Debug)]
enum Call {
    Spheres,
    Centers,
    Bodies,
}

struct Twins {
    one: BroadPhase,
    many: BroadPhase,
    model: Model,
    spheres: Vec<ProxyKey>,
    bodies: Vec<ProxyKey>,
}

fn pool(threads: usize) -> rayon::ThreadPool {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .expect("a pool")
}

impl Twins {
    fn new(seed: u64) -> Self {
        let config = Config::default();
        let (mut one, mut many) = (BroadPhase::new(config), BroadPhase::new(config));
        let mut model = Model::new(config.margin);
        model.quadratic = false;
        let mut rng = Rng::new(seed);
        let (mut spheres, mut bodies) = (Vec::new(), Vec::new());
        for i in 0..SPHERES + BODIES {
            let c = rng.offset(HALF);
            let shape = if i % 2 == 0 && spheres.len() < SPHERES || bodies.len() == BODIES {
                ModelShape::Sphere {
                    center: c,
                    radius: rng.range(0.1, 0.6),
                }
            } else {
                ModelShape::body(c, Vec3::splat(rng.range(0.1, 0.6)), rng.chance(0.2))
            };
            let key = model.insert(&mut one, shape);
            assert_eq!(
                shape.insert_into(&mut many),
                Ok(key),
                "twins issue the same keys"
            );
            if shape.is_sphere() {
                spheres.push(key);
            } else {
                bodies.push(key);
            }
        }
        let mut twins = Twins {
            one,
            many,
            model,
            spheres,
            bodies,
        };
        twins.step("setup");
        twins
    }

    fn step(&mut self, context: &str) {
        let want = self.model.expect_step();
        pool(1).install(|| self.one.step());
        pool(3).install(|| self.many.step());
        for bp in [&self.one, &self.many] {
            self.model
                .assert_list(context, "pairs", bp.pairs(), &want.pairs);
            self.model
                .assert_list(context, "added", bp.added(), &want.added);
            self.model
                .assert_list(context, "removed", bp.removed(), &want.removed);
        }
    }

    /// Sends one batch of `n` moves through `call` to both twins, with bad entries at
    /// `bad` (increasing); checks both against the model.
    fn batch(&mut self, rng: &mut Rng, call: Call, n: usize, bad: &[usize], threads: usize) {
        let context = format!("{call:?}, {n} entries, bad at {bad:?}, {threads} threads");
        let keys = match call {
            Call::Spheres | Call::Centers => &self.spheres,
            Call::Bodies => &self.bodies,
        };
        let picked: Vec<ProxyKey> = (0..n).map(|_| keys[rng.below(keys.len())]).collect();
        // The shapes each entry sets, and the error the first bad one's single update gets.
        let mut shapes: Vec<ModelShape> = picked
            .iter()
            .map(|k| {
                let old = self.model.shapes[k];
                match call {
                    Call::Centers => old.teleported(old.center() + rng.offset(0.3)),
                    _ => old.moved(rng.offset(0.3)),
                }
            })
            .collect();
        let mut picked = picked;
        for (j, &i) in bad.iter().enumerate() {
            match (j + i) % 3 {
                0 => picked[i] = ProxyKey::default(),
                1 => {
                    picked[i] = if shapes[i].is_sphere() {
                        self.bodies[0]
                    } else {
                        self.spheres[0]
                    }
                }
                _ => shapes[i] = shapes[i].teleported(Vec3::new(f32::NAN, 0.0, 0.0)),
            }
        }
        let want = bad.first().map(|&i| {
            let mut scratch = self.one.clone();
            let error = shapes[i]
                .update_in(&mut scratch, picked[i])
                .expect_err("a bad entry is refused alone");
            BatchError { index: i, error }
        });
        let send = |bp: &mut BroadPhase| -> Result<(), BatchError> {
            match call {
                Call::Spheres => {
                    let batch: Vec<(ProxyKey, Vec3, f32)> = picked
                        .iter()
                        .zip(&shapes)
                        .map(|(&k, s)| match *s {
                            ModelShape::Sphere { center, radius } => (k, center, radius),
                            ModelShape::Body { aabb, .. } => (k, aabb.center(), 0.5),
                        })
                        .collect();
                    bp.update_spheres(&batch)
                }
                Call::Centers => {
                    let centers: Vec<Vec3> = shapes.iter().map(ModelShape::center).collect();
                    bp.update_centers(&picked, &centers)
                }
                Call::Bodies => {
                    let batch: Vec<(ProxyKey, Aabb)> = picked
                        .iter()
                        .zip(&shapes)
                        .map(|(&k, s)| (k, s.user_box()))
                        .collect();
                    bp.update_bodies(&batch)
                }
            }
        };
        let got_one = pool(1).install(|| send(&mut self.one));
        let got_many = pool(threads).install(|| send(&mut self.many));
        let same = |a: &Result<(), BatchError>, b: &Result<(), BatchError>| match (a, b) {
            (Ok(()), Ok(())) => true,
            (Err(a), Err(b)) => {
                a.index == b.index
                    && core::mem::discriminant(&a.error) == core::mem::discriminant(&b.error)
            }
            _ => false,
        };
        match &want {
            Some(w) => {
                let w = Err(*w);
                assert!(
                    same(&got_one, &w),
                    "{context}: one thread {got_one:?}, want {w:?}"
                );
                assert!(
                    same(&got_many, &w),
                    "{context}: pool {got_many:?}, want {w:?}"
                );
            }
            None => {
                assert_eq!(got_one, Ok(()), "{context}: one thread");
                assert_eq!(got_many, Ok(()), "{context}: pool");
                for (k, s) in picked.iter().zip(&shapes) {
                    let s = match (call, *s) {
                        (Call::Centers, ModelShape::Sphere { center, .. }) => ModelShape::Sphere {
                            center,
                            radius: match self.model.shapes[k] {
                                ModelShape::Sphere { radius, .. } => radius,
                                _ => unreachable!("a sphere's key"),
                            },
                        },
                        (_, s) => s,
                    };
                    self.model.shapes.insert(*k, s);
                }
            }
        }
        for bp in [&self.one, &self.many] {
            self.model.assert_same_proxies(bp, &context);
        }
        self.step(&context);
    }
}

#[test]
fn large_batches_are_refused_or_applied_as_on_one_thread() {
    let mut twins = Twins::new(11);
    let mut rng = Rng::new(12);
    let n = 20_000;
    for (round, call) in [Call::Spheres, Call::Centers, Call::Bodies]
        .into_iter()
        .cycle()
        .take(12)
        .enumerate()
    {
        let threads = if round % 4 == 3 { 8 } else { 3 };
        let bad: Vec<usize> = match round % 4 {
            0 => Vec::new(),
            1 => vec![rng.below(n)],
            2 => {
                let mut b: Vec<usize> = (0..3).map(|_| rng.below(n)).collect();
                b.sort_unstable();
                b.dedup();
                b
            }
            _ => [0, n - 1][rng.below(2)..].to_vec(),
        };
        twins.batch(&mut rng, call, n, &bad, threads);
    }
}
