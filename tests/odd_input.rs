//! Odd but valid input is kept and paired exactly: spheres a million metres outside the
//! bounds, a sphere larger than the world, zero radii, ten thousand spheres at one point,
//! boxes that exactly touch, a static body covering everything. Each case keeps its own model
//! of what it inserted and moved (`common::Model`: the shapes as given, its own margin growth,
//! its own O(n²) loop and set difference) and compares every step's sorted pairs and events
//! with it (or, for the crowd, with the complete set it must be), with the octree in both
//! placements.

mod common;

use broadleaf::fixtures::scene::Rng;
use broadleaf::{Aabb, BodyKind, BroadPhase, Config, Pair, Passes, Placement, ProxyKey, Vec3};
use common::{Model, ModelShape};

/// Both placements under the full pass, and both under the incremental pass (forced, with
/// fat boxes of a fixed skin, 0.3 m).
const BOTH: [(Placement, Passes); 4] = [
    (Placement::Strict, Passes::Full),
    (Placement::Loose, Passes::Full),
    (Placement::Strict, Passes::Incremental),
    (Placement::Loose, Passes::Incremental),
];

/// The fixed skin of the incremental cases.
fn skin_of(passes: Passes) -> f32 {
    if passes == Passes::Incremental {
        0.3
    } else {
        0.0
    }
}

/// `hint`: give the octree ±10 m as its region hint, or none.
fn config(hint: bool, (placement, passes): (Placement, Passes)) -> Config {
    Config {
        bounds: hint.then(|| Aabb::new(Vec3::splat(-10.0), Vec3::splat(10.0))),
        octree_placement: placement,
        skin: skin_of(passes),
        passes,
        ..Config::default()
    }
}

/// A broadphase and the test's model of what it was given: every insert and update goes to
/// both, and [`Odd::check`] steps the broadphase against the model.
struct Odd {
    bp: BroadPhase,
    model: Model,
}

impl Odd {
    /// The model grows boxes by the margin this test asked for.
    fn new(config: Config) -> Self {
        Self {
            model: Model::new(config.margin),
            bp: BroadPhase::new(config),
        }
    }

    fn insert_sphere(&mut self, center: Vec3, radius: f32) -> ProxyKey {
        self.model
            .insert(&mut self.bp, ModelShape::Sphere { center, radius })
    }

    fn insert_body(&mut self, aabb: Aabb, kind: BodyKind) -> ProxyKey {
        let is_static = kind == BodyKind::Static;
        self.model
            .insert(&mut self.bp, ModelShape::Body { aabb, is_static })
    }

    fn update_sphere(&mut self, key: ProxyKey, center: Vec3, radius: f32) {
        self.model
            .update(&mut self.bp, key, ModelShape::Sphere { center, radius });
    }

    fn update_body(&mut self, key: ProxyKey, aabb: Aabb) {
        let is_static = self.model.shapes[&key].is_static();
        self.model
            .update(&mut self.bp, key, ModelShape::Body { aabb, is_static });
    }

    /// Steps; the pairs, added and removed lists must equal the model's, the proxies the
    /// model's, and `validate()` must hold. Returns the broadphase's pairs.
    fn check(&mut self) -> Vec<Pair> {
        let want = self.model.expect_step();
        self.bp.step();
        let pairs = self.bp.pairs().to_vec();
        self.model
            .assert_list("odd input", "pairs", self.bp.pairs(), &want.pairs);
        self.model
            .assert_list("odd input", "added", self.bp.added(), &want.added);
        self.model
            .assert_list("odd input", "removed", self.bp.removed(), &want.removed);
        self.bp.validate();
        self.model.assert_same_proxies(&self.bp, "odd input");
        pairs
    }
}

#[test]
fn far_away_spheres_are_kept_and_paired() {
    for p in BOTH {
        for seed in [0, 3, 6] {
            let mut bp = Odd::new(config(seed != 3, p));
            let mut rng = Rng::new(seed);
            for _ in 0..200 {
                let c = rng.vec3_in(Vec3::splat(-12.0), Vec3::splat(12.0));
                bp.insert_sphere(c, rng.range(0.0, 1.0));
            }
            // A cluster a million metres away, and spheres straddling the bounds' faces.
            let far = Vec3::new(1.0e6, -1.0e6, 3.0e5);
            let a = bp.insert_sphere(far, 1.0);
            let b = bp.insert_sphere(far + Vec3::X * 2.0, 1.0);
            bp.insert_sphere(Vec3::new(10.0, 0.0, 0.0), 0.5);
            bp.insert_sphere(Vec3::new(-10.2, 9.9, 0.0), 0.5);
            let pairs = bp.check();
            assert!(
                pairs.contains(&Pair::new(a, b)),
                "touching far spheres pair"
            );
            // Moving between far away and inside keeps them paired correctly.
            bp.update_sphere(a, Vec3::ZERO, 1.0);
            bp.update_sphere(b, Vec3::new(0.0, 2.0, 0.0), 1.0);
            assert!(bp.check().contains(&Pair::new(a, b)));
            bp.update_sphere(b, -far, 1.0);
            assert!(!bp.check().contains(&Pair::new(a, b)));
        }
    }
}

#[test]
fn a_sphere_larger_than_the_world_pairs_with_everything() {
    for p in BOTH {
        let mut bp = Odd::new(config(true, p));
        let mut rng = Rng::new(9);
        let small: Vec<ProxyKey> = (0..300)
            .map(|_| {
                let c = rng.vec3_in(Vec3::splat(-10.0), Vec3::splat(10.0));
                bp.insert_sphere(c, 0.2)
            })
            .collect();
        let huge = bp.insert_sphere(Vec3::ZERO, 1.0e4);
        let pairs = bp.check();
        for &k in &small {
            assert!(pairs.contains(&Pair::new(k, huge)));
        }
    }
}

#[test]
fn zero_radius_spheres_pair_only_when_they_touch() {
    for p in BOTH {
        let mut bp = Odd::new(config(false, p));
        let p = Vec3::new(1.25, -3.5, 0.75);
        let a = bp.insert_sphere(p, 0.0);
        let b = bp.insert_sphere(p, 0.0);
        let c = bp.insert_sphere(p + Vec3::X, 0.0);
        let d = bp.insert_sphere(p + Vec3::X * 0.5, 0.5);
        let pairs = bp.check();
        assert!(pairs.contains(&Pair::new(a, b)));
        assert!(!pairs.contains(&Pair::new(a, c)));
        assert!(pairs.contains(&Pair::new(c, d)) && pairs.contains(&Pair::new(a, d)));
    }
}

#[test]
fn ten_thousand_spheres_at_one_point_report_every_pair() {
    for p in BOTH {
        const N: usize = 10_000;
        let mut bp = BroadPhase::new(config(true, p));
        let p = Vec3::new(3.3, 3.3, 3.3);
        let keys: Vec<ProxyKey> = (0..N).map(|_| bp.insert_sphere(p, 0.1).unwrap()).collect();
        bp.step();
        // A strictly increasing list of N(N−1)/2 pairs of these N keys is the complete set.
        assert_eq!(bp.pairs().len(), N * (N - 1) / 2);
        assert_eq!(bp.added().len(), bp.pairs().len());
        assert!(bp.pairs().windows(2).all(|w| w[0] < w[1]));
        let mut sorted = keys.clone();
        sorted.sort_unstable();
        assert!(
            bp.pairs()
                .iter()
                .all(|p| sorted.binary_search(&p.a).is_ok() && sorted.binary_search(&p.b).is_ok())
        );
    }
}

#[test]
fn exactly_touching_boxes_and_spheres_pair() {
    for p in BOTH {
        let mut bp = Odd::new(config(false, p));
        // A lattice of unit boxes that touch their neighbours on faces, edges and corners.
        for x in -3..3 {
            for y in -3..3 {
                for z in -1..1 {
                    let min = Vec3::new(x as f32, y as f32, z as f32);
                    let kind = if (x + y + z) % 3 == 0 {
                        BodyKind::Static
                    } else {
                        BodyKind::Dynamic
                    };
                    bp.insert_body(Aabb::new(min, min + Vec3::ONE), kind);
                }
            }
        }
        // Spheres whose boxes touch the lattice's faces from outside, and one another.
        for i in -3..3 {
            bp.insert_sphere(Vec3::new(i as f32 + 0.5, 3.5, 0.0), 0.5);
            bp.insert_sphere(Vec3::new(3.25, i as f32 + 0.5, 0.0), 0.25);
        }
        let pairs = bp.check();
        // A 6×6×2 lattice has ((3·6−2)²(3·2−2) − 72)/2 = 476 adjacent pairs (face, edge or
        // corner); static×static ones drop out and the spheres add theirs.
        assert!(pairs.len() > 400, "{}", pairs.len());
    }
}

#[test]
fn a_static_body_covering_everything_pairs_with_every_moving_proxy() {
    for p in BOTH {
        let mut bp = Odd::new(config(true, p));
        let mut rng = Rng::new(4);
        for i in 0..400 {
            let c = rng.vec3_in(Vec3::splat(-30.0), Vec3::splat(30.0));
            if i % 4 == 0 {
                let aabb = Aabb::from_center_half_extents(c, Vec3::splat(rng.range(0.0, 3.0)));
                let kind = if i % 8 == 0 {
                    BodyKind::Static
                } else {
                    BodyKind::Dynamic
                };
                bp.insert_body(aabb, kind);
            } else {
                bp.insert_sphere(c, rng.range(0.0, 2.0));
            }
        }
        let world = Aabb::new(Vec3::splat(-1.0e5), Vec3::splat(1.0e5));
        let all = bp.insert_body(world, BodyKind::Static);
        let pairs = bp.check();
        let with_all = pairs.iter().filter(|p| p.a == all || p.b == all).count();
        assert_eq!(with_all, 400 - 50, "every proxy but the 50 static ones");
    }
}

/// Regression (found by `fuzz/ops`): bodies near `f32::MAX` are finite, but their doubled
/// centroids `min + max` overflow to infinity, so the SAH binning puts every one in one bucket.
/// The build must still split (or make a leaf), and the pairs must still equal the model's.
#[test]
fn bodies_near_f32_max_whose_centroids_overflow_still_pair_exactly() {
    for p in BOTH {
        let big = 3.396_151_4e38_f32;
        for kind in [BodyKind::Dynamic, BodyKind::Static] {
            let mut bp = Odd::new(config(false, p));
            bp.insert_sphere(Vec3::ZERO, 1.0);
            for i in 0..40 {
                let lo = Vec3::new(big - i as f32 * 1.0e36, -1.7e38, big);
                bp.insert_body(Aabb::new(lo.min(Vec3::splat(big)), Vec3::splat(big)), kind);
                bp.insert_body(
                    Aabb::new(Vec3::splat(-f32::MAX), Vec3::new(1.0, -1.0e38, f32::MAX)),
                    BodyKind::Dynamic,
                );
            }
            bp.check();
            bp.check();
        }
    }
}

/// Regression (found by `fuzz/ops`): a sphere whose centre and radius are both near `f32::MAX`
/// is finite input, but its box runs from about 0 to +∞. It lives in the octree's root (it
/// leaves the bounds) and must pair with every box it overlaps — static bodies included, which
/// find spheres through `Octree::query_aabb`.
#[test]
fn a_sphere_whose_box_overflows_to_infinity_pairs_with_the_bodies_it_overlaps() {
    for p in BOTH {
        let big = 3.396_151_4e38_f32;
        let tiny = 1.092_050_6e-5_f32;
        let mut bp = Odd::new(Config {
            bounds: Some(Aabb::new(Vec3::splat(-16.0), Vec3::splat(16.0))),
            octree_placement: p.0,
            margin: 0.75,
            skin: skin_of(p.1),
            passes: p.1,
            ..Config::default()
        });
        bp.insert_sphere(Vec3::new(0.0, 0.046_875, 4.5737e-41), tiny);
        bp.insert_body(
            Aabb::new(Vec3::splat(tiny), Vec3::splat(tiny)),
            BodyKind::Static,
        );
        bp.insert_body(
            Aabb::new(
                Vec3::new(-4.973_355_7e17, 2.367_701_2e14, 2.367_701_2e14),
                Vec3::splat(2.367_701_2e14),
            ),
            BodyKind::Static,
        );
        bp.insert_body(
            Aabb::new(Vec3::splat(tiny), Vec3::new(tiny, 1.318_548_2e-5, tiny)),
            BodyKind::Static,
        );
        bp.check();
        bp.insert_sphere(Vec3::splat(big), big);
        bp.check();
        bp.insert_sphere(Vec3::splat(big), big);
        bp.check();
    }
}

/// A skin or a margin so large that the grown boxes of finite boxes overflow to infinity:
/// every insert and move is still accepted, nothing is lost, and the pairs equal the model's
/// at every step.
#[test]
fn a_skin_or_margin_that_overflows_the_grown_boxes_is_still_exact() {
    for (placement, skin, margin) in [
        (Placement::Strict, 3.0e38, 0.0),
        (Placement::Loose, 3.0e38, 0.0),
        (Placement::Loose, 0.0, 3.0e38),
        (Placement::Strict, 0.1, 3.0e38),
    ] {
        let mut bp = Odd::new(Config {
            bounds: Some(Aabb::new(Vec3::splat(-10.0), Vec3::splat(10.0))),
            octree_placement: placement,
            skin,
            margin,
            ..Config::default()
        });
        assert_eq!(bp.bp.config().margin, margin);
        let big = 3.0e38_f32;
        let body = Aabb::new(Vec3::splat(big * 0.5), Vec3::splat(big));
        let b = bp.insert_body(body, BodyKind::Dynamic);
        let s = bp.insert_sphere(Vec3::splat(big * 0.9), big * 0.05);
        let w = bp.insert_body(body, BodyKind::Static);
        bp.insert_sphere(Vec3::ZERO, 1.0);
        bp.check();
        for step in 1..6 {
            let d = Vec3::splat(-1.0e37 * step as f32);
            bp.update_body(b, Aabb::new(body.min + d, body.max + d));
            bp.update_body(w, Aabb::new(body.min + d * 2.0, body.max));
            bp.update_sphere(s, Vec3::splat(big * 0.9) + d, big * 0.05);
            bp.check();
        }
        assert_eq!(bp.bp.len(), 4);
    }
}
