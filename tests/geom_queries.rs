//! `geom`'s distance and sphere-cast functions against the tests' own geometry
//! (`reference`: clamping and a search of the exact gap function in `f64`), on random shapes
//! and on the cases with a known answer: grazing contact, edges and corners, zero radius, zero
//! direction, a start inside, huge coordinates, and arguments that must find nothing.

mod common;
mod reference;

use broadleaf::geom::{
    inverse_dir, point_aabb_distance, point_sphere_distance, ray_sphere, sphere_cast_aabb,
    sphere_cast_sphere,
};
use broadleaf::{Aabb, Vec3};
use common::Rng;
use reference::{Cast, CastExpect, Target, box_distance, p, sphere_distance};

fn random_box(rng: &mut Rng, scale: f32) -> Aabb {
    let c = rng.offset(scale);
    let half = match rng.below(6) {
        0 => Vec3::ZERO,
        1 => Vec3::new(rng.range(0.0, scale), 0.0, rng.range(0.0, scale)),
        _ => rng.vec3_in(Vec3::ZERO, Vec3::splat(scale * 0.3)),
    };
    Aabb::new(c - half, c + half)
}

fn random_cast(rng: &mut Rng, scale: f32) -> Cast {
    Cast {
        o: rng.offset(scale * 1.5),
        r: if rng.chance(0.2) {
            0.0
        } else {
            rng.range(0.0, scale * 0.3)
        },
        d: match rng.below(6) {
            0 => Vec3::ZERO,
            1 => Vec3::Z * rng.range(-1.0, 1.0),
            _ => rng.offset(1.0),
        },
        max_t: if rng.chance(0.1) {
            0.0
        } else {
            rng.range(0.0, scale * 4.0)
        },
    }
}

/// The crate's cast against one target, as the reference checker wants it.
fn crate_cast(c: &Cast, target: &Target) -> Option<(usize, f32)> {
    match *target {
        Target::Sphere(center, radius) => {
            sphere_cast_sphere(c.o, c.r, c.d, c.max_t, center, radius)
        }
        Target::Box(ref b) => sphere_cast_aabb(c.o, c.r, c.d, c.max_t, b),
    }
    .map(|t| (0, t))
}

#[test]
fn distances_match_the_reference() {
    let mut rng = Rng::new(1);
    for scale in [1.0f32, 100.0, 1e30] {
        for i in 0..2000 {
            let q = rng.offset(scale * 1.5);
            let b = random_box(&mut rng, scale);
            let got = f64::from(point_aabb_distance(q, &b));
            let want = box_distance(p(q), &b);
            assert!(
                (got - want).abs() <= want * 1e-6,
                "box {i}: {got} vs {want}"
            );
            if b.contains_point(q) {
                assert_eq!(got, 0.0);
            }
            let (c, r) = (rng.offset(scale), rng.range(0.0, scale * 0.5));
            let got = f64::from(point_sphere_distance(q, c, r));
            let want = sphere_distance(p(q), c, r);
            assert!(
                (got - want).abs() <= 1e-6 * (want + f64::from(scale)),
                "sphere {i}: {got} vs {want}"
            );
        }
    }
}

#[test]
fn distances_on_faces_inside_and_at_the_extremes() {
    let b = Aabb::new(Vec3::ZERO, Vec3::ONE);
    assert_eq!(point_aabb_distance(Vec3::new(1.0, 0.5, 0.0), &b), 0.0);
    assert_eq!(point_aabb_distance(Vec3::new(3.0, 0.5, 0.5), &b), 2.0);
    assert_eq!(point_aabb_distance(Vec3::new(4.0, 5.0, 0.5), &b), 5.0);
    assert_eq!(
        point_sphere_distance(Vec3::new(3.0, 4.0, 0.0), Vec3::ZERO, 5.0),
        0.0
    );
    assert_eq!(
        point_sphere_distance(Vec3::new(6.0, 8.0, 0.0), Vec3::ZERO, 5.0),
        5.0
    );
    assert_eq!(point_sphere_distance(Vec3::ZERO, Vec3::ZERO, 0.0), 0.0);
    // Far apart but finite: no intermediate overflow.
    let far = Aabb::new(Vec3::splat(1e38), Vec3::splat(2e38));
    let d = point_aabb_distance(Vec3::new(-1e38, 1e38, 1e38), &far);
    assert_eq!(d, 2e38);
    let d = point_sphere_distance(Vec3::splat(-1e38), Vec3::splat(1e38), 1e38);
    assert!(
        (f64::from(d) - (2e38 * 3f64.sqrt() - 1e38)).abs() < 1e32,
        "{d}"
    );
    // An infinite face (a box that overflowed from finite input) is fine.
    let open = Aabb::new(Vec3::splat(f32::NEG_INFINITY), Vec3::ZERO);
    assert_eq!(point_aabb_distance(Vec3::new(-5.0, -1e30, 3.0), &open), 3.0);
    // Bad input: +∞, never NaN; the empty box is infinitely far, an inverted one not at 0.
    let nan = f32::NAN;
    assert_eq!(
        point_aabb_distance(Vec3::new(nan, 0.0, 0.0), &b),
        f32::INFINITY
    );
    assert_eq!(
        point_aabb_distance(Vec3::splat(f32::INFINITY), &b),
        f32::INFINITY
    );
    assert_eq!(
        point_aabb_distance(Vec3::ZERO, &Aabb::new(Vec3::splat(nan), Vec3::ONE)),
        f32::INFINITY
    );
    assert_eq!(point_aabb_distance(Vec3::ZERO, &Aabb::EMPTY), f32::INFINITY);
    assert!(point_aabb_distance(Vec3::splat(0.5), &Aabb::new(Vec3::ONE, Vec3::ZERO)) > 0.0);
    for (q, c, r) in [
        (Vec3::new(nan, 0.0, 0.0), Vec3::ZERO, 1.0),
        (Vec3::ZERO, Vec3::splat(f32::INFINITY), 1.0),
        (Vec3::ZERO, Vec3::ZERO, f32::INFINITY),
        (Vec3::ZERO, Vec3::ZERO, nan),
        (Vec3::ZERO, Vec3::X * 5.0, -1.0),
    ] {
        assert_eq!(point_sphere_distance(q, c, r), f32::INFINITY, "{q} {c} {r}");
    }
}

#[test]
fn casts_match_the_reference() {
    let mut rng = Rng::new(2);
    let mut hits = [0usize; 2];
    for scale in [1.0f32, 50.0, 1e30] {
        let eps = 1e-5 * f64::from(scale);
        for i in 0..3000 {
            let mut cast = random_cast(&mut rng, scale);
            let (target, aim) = if i % 2 == 0 {
                let c = rng.offset(scale);
                (Target::Sphere(c, rng.range(0.0, scale * 0.5)), c)
            } else {
                let b = random_box(&mut rng, scale);
                (Target::Box(b), b.center())
            };
            // Most casts head for the target (give or take), or random ones would rarely hit.
            if rng.chance(0.7) {
                let to = aim + rng.offset(scale * 0.4) - cast.o;
                let speed = rng.range(0.1, 2.0);
                cast.d = to * speed;
                cast.max_t = rng.range(0.0, 2.0 / speed);
            }
            let targets = [target];
            let got = crate_cast(&cast, &target);
            let speed = f64::from(cast.d.length()).max(1e-30);
            // A gap of `eps` is crossed in `eps / speed`; grazing contact takes longer to
            // close, which the checker's near/deep bracketing allows for.
            let t_tol = 1e-9 * f64::from(cast.max_t) + eps / speed;
            let expect = CastExpect::new(&cast, &targets, eps);
            expect.check(
                &cast,
                &targets,
                got,
                eps,
                t_tol,
                &format!("{scale} cast {i} {cast:?} {target:?}"),
            );
            hits[i % 2] += usize::from(got.is_some());
        }
    }
    assert!(
        hits.iter().all(|&h| h > 500),
        "too few hits to mean anything: {hits:?}"
    );
}

#[test]
fn grazing_edges_and_corners_have_their_exact_times() {
    let unit = Aabb::new(Vec3::splat(-1.0), Vec3::ONE);
    // Tangent pass: centres 2 apart at closest approach, radii 1 + 1.
    let o = Vec3::new(-10.0, 2.0, 0.0);
    assert_eq!(
        sphere_cast_sphere(o, 1.0, Vec3::X, 20.0, Vec3::ZERO, 1.0),
        Some(10.0)
    );
    assert_eq!(
        sphere_cast_sphere(o, 0.999, Vec3::X, 20.0, Vec3::ZERO, 1.0),
        None
    );
    // Past the box's top face at height `radius`: it first touches the edge at x = −1,
    // where the entry into the grown box (x = −2) is in the edge's region.
    assert_eq!(sphere_cast_aabb(o, 1.0, Vec3::X, 20.0, &unit), Some(9.0));
    assert_eq!(sphere_cast_aabb(o, 0.999, Vec3::X, 20.0, &unit), None);
    // Higher above the top face than the radius: a miss...
    let skew = Vec3::new(-10.0, 1.0 + 1.5, 0.0);
    assert_eq!(sphere_cast_aabb(skew, 1.0, Vec3::X, 20.0, &unit), None);
    // ...and a diagonal approach to the corner (1, 1, 1) touches it at |c − corner| = 1.
    let t = sphere_cast_aabb(Vec3::splat(5.0), 1.0, Vec3::splat(-1.0), 10.0, &unit).unwrap();
    assert!(
        (f64::from(t) - (4.0 - 1.0 / 3f64.sqrt())).abs() < 1e-6,
        "{t}"
    );
    // The same corner through the grown box's corner region but along an edge direction:
    // moving along −x at y = z = 1 + 0.6, the edge capsule along x at (y, z) = (1, 1) is at
    // distance 0.6·√2 ≈ 0.85 < 1: touched when the end sphere at x = 1 is reached.
    let along = Vec3::new(5.0, 1.6, 1.6);
    let t = sphere_cast_aabb(along, 1.0, -Vec3::X, 10.0, &unit).unwrap();
    let want = 4.0 - (1.0 - 2.0 * 0.36f64).sqrt();
    assert!((f64::from(t) - want).abs() < 1e-6, "{t} vs {want}");
    // A face hit, a slower direction (t in units of dir) and a max_t just short of it.
    assert_eq!(
        sphere_cast_aabb(Vec3::new(0.0, 0.0, 5.0), 0.5, -Vec3::Z, 10.0, &unit),
        Some(3.5)
    );
    assert_eq!(
        sphere_cast_aabb(Vec3::new(0.0, 0.0, 5.0), 0.5, -Vec3::Z * 0.5, 10.0, &unit),
        Some(7.0)
    );
    assert_eq!(
        sphere_cast_aabb(Vec3::new(0.0, 0.0, 5.0), 0.5, -Vec3::Z, 3.4, &unit),
        None
    );
    assert_eq!(
        sphere_cast_sphere(Vec3::X * 5.0, 1.0, -Vec3::X * 2.0, 10.0, Vec3::ZERO, 1.0),
        Some(1.5)
    );
}

/// Panics unless a ray's `t` and a zero-radius cast's `t` agree, or the ray grazes the shape:
/// it comes within `1e-4` of it (`grown`) but does not enter it shrunk by `1e-4` (`shrunk`,
/// `None` when nothing is left of it), by the reference.
#[allow(
    clippy::too_many_arguments,
    reason = "one comparison and its grazing test"
)]
fn agree(
    i: usize,
    ray: Option<f32>,
    cast: Option<f32>,
    o: Vec3,
    d: Vec3,
    max_t: f32,
    grown: Target,
    shrunk: Option<Target>,
) {
    match (ray, cast) {
        (Some(a), Some(c)) => assert!((a - c).abs() <= 1e-4 * (1.0 + a), "{i}: {a} {c}"),
        (None, None) => {}
        _ => {
            let path = Cast {
                o,
                r: 0.0,
                d,
                max_t,
            };
            let near = path.first_within(&grown, 0.0).is_some();
            let deep = shrunk.is_some_and(|s| path.first_within(&s, 0.0).is_some());
            assert!(near && !deep, "{i}: ray {ray:?}, zero-radius cast {cast:?}");
        }
    }
}

#[test]
fn zero_radius_is_a_ray_zero_direction_is_a_test_and_a_start_inside_is_zero() {
    let mut rng = Rng::new(3);
    for i in 0..2000 {
        let (o, d, max_t) = (rng.offset(20.0), rng.offset(1.0), rng.range(0.0, 60.0));
        let b = random_box(&mut rng, 10.0);
        let ray = b.ray_entry(o, inverse_dir(d), max_t);
        let cast = sphere_cast_aabb(o, 0.0, d, max_t, &b);
        let shrunk = Aabb::new(b.min + 1e-4, b.max - 1e-4);
        let shrunk = shrunk
            .min
            .cmple(shrunk.max)
            .all()
            .then_some(Target::Box(shrunk));
        agree(
            i,
            ray,
            cast,
            o,
            d,
            max_t,
            Target::Box(b.grown(1e-4)),
            shrunk,
        );
        let (c, r) = (rng.offset(10.0), rng.range(0.0, 5.0));
        let ray = ray_sphere(o, d, c, r, max_t);
        let cast = sphere_cast_sphere(o, 0.0, d, max_t, c, r);
        let shrunk = (r > 1e-4).then_some(Target::Sphere(c, r - 1e-4));
        agree(
            i,
            ray,
            cast,
            o,
            d,
            max_t,
            Target::Sphere(c, r + 1e-4),
            shrunk,
        );
    }
    let unit = Aabb::new(Vec3::splat(-1.0), Vec3::ONE);
    // Zero direction: touching (exactly, on a corner sphere) is 0, apart is None.
    let corner_touch = Vec3::splat(1.0) + Vec3::splat(1.0 / 3f32.sqrt());
    let t = sphere_cast_aabb(corner_touch, 1.0001, Vec3::ZERO, 5.0, &unit);
    assert_eq!(t, Some(0.0));
    assert_eq!(
        sphere_cast_aabb(Vec3::splat(1.7), 1.0, Vec3::ZERO, 5.0, &unit),
        None
    );
    assert_eq!(
        sphere_cast_aabb(Vec3::new(3.0, 0.0, 0.0), 2.0, Vec3::ZERO, 5.0, &unit),
        Some(0.0)
    );
    assert_eq!(
        sphere_cast_sphere(Vec3::X * 3.0, 1.0, Vec3::ZERO, 5.0, Vec3::ZERO, 2.0),
        Some(0.0)
    );
    assert_eq!(
        sphere_cast_sphere(Vec3::X * 3.0, 0.5, Vec3::ZERO, 5.0, Vec3::ZERO, 2.0),
        None
    );
    // Inside or overlapping at the start, moving away or not: 0, also with max_t 0.
    assert_eq!(
        sphere_cast_aabb(Vec3::ZERO, 0.1, Vec3::X, 0.0, &unit),
        Some(0.0)
    );
    assert_eq!(
        sphere_cast_aabb(Vec3::X * 1.5, 0.6, Vec3::X, 3.0, &unit),
        Some(0.0)
    );
    assert_eq!(
        sphere_cast_sphere(Vec3::X, 0.5, Vec3::X, 0.0, Vec3::ZERO, 1.0),
        Some(0.0)
    );
    // Apart with max_t 0: None.
    assert_eq!(
        sphere_cast_aabb(Vec3::X * 5.0, 1.0, -Vec3::X, 0.0, &unit),
        None
    );
}

#[test]
fn huge_coordinates_keep_their_answers() {
    let s = 1e30f32;
    let unit = Aabb::new(Vec3::splat(-s), Vec3::splat(s));
    let o = Vec3::new(-10.0 * s, 2.0 * s, 0.0);
    let t = sphere_cast_aabb(o, s, Vec3::X * s, 20.0, &unit).unwrap();
    assert!((t - 9.0).abs() < 1e-5, "{t}");
    let t = sphere_cast_sphere(o, s, Vec3::X * s, 20.0, Vec3::ZERO, s).unwrap();
    assert!((t - 10.0).abs() < 1e-5, "{t}");
    // Extremes of f32: centres ±3e38 apart, a direction of 3e38: nothing overflows to NaN.
    let m = 3e38f32;
    let t = sphere_cast_sphere(Vec3::splat(-m), m, Vec3::splat(m), 10.0, Vec3::splat(m), m);
    let t = t.expect("they meet");
    let want = 2.0 - 2.0 / 3f64.sqrt();
    assert!((f64::from(t) - want).abs() < 1e-6, "{t} vs {want}");
    let far = Aabb::new(Vec3::splat(m), Vec3::splat(f32::MAX));
    let t = sphere_cast_aabb(Vec3::splat(-m), m, Vec3::splat(m), 10.0, &far).unwrap();
    assert!(
        (f64::from(t) - (2.0 - 1.0 / 3f64.sqrt())).abs() < 1e-6,
        "{t}"
    );
    assert_eq!(
        sphere_cast_aabb(Vec3::splat(-m), m, -Vec3::splat(m), 10.0, &far),
        None
    );
}

#[test]
fn bad_arguments_find_nothing_and_nothing_is_nan() {
    let unit = Aabb::new(Vec3::splat(-1.0), Vec3::ONE);
    let (nan, inf) = (f32::NAN, f32::INFINITY);
    let o = Vec3::X * 5.0;
    for (o, r, d, max_t) in [
        (Vec3::new(nan, 0.0, 0.0), 1.0, -Vec3::X, 10.0),
        (Vec3::new(inf, 0.0, 0.0), 1.0, -Vec3::X, 10.0),
        (o, nan, -Vec3::X, 10.0),
        (o, inf, -Vec3::X, 10.0),
        (o, -1.0, -Vec3::X, 10.0),
        (o, 1.0, Vec3::new(-1.0, nan, 0.0), 10.0),
        (o, 1.0, Vec3::new(-inf, 0.0, 0.0), 10.0),
        (o, 1.0, -Vec3::X, nan),
        (o, 1.0, -Vec3::X, inf),
        (o, 1.0, -Vec3::X, -1.0),
    ] {
        assert_eq!(
            sphere_cast_aabb(o, r, d, max_t, &unit),
            None,
            "{o} {r} {d} {max_t}"
        );
        assert_eq!(sphere_cast_sphere(o, r, d, max_t, Vec3::ZERO, 1.0), None);
    }
    let d = -Vec3::X;
    assert_eq!(
        sphere_cast_aabb(o, 1.0, d, 10.0, &Aabb::new(Vec3::ONE, Vec3::ZERO)),
        None
    );
    assert_eq!(
        sphere_cast_aabb(o, 1.0, d, 10.0, &Aabb::new(Vec3::ZERO, Vec3::splat(inf))),
        None
    );
    assert_eq!(sphere_cast_aabb(o, 1.0, d, 10.0, &Aabb::EMPTY), None);
    assert_eq!(
        sphere_cast_sphere(o, 1.0, d, 10.0, Vec3::splat(nan), 1.0),
        None
    );
    assert_eq!(sphere_cast_sphere(o, 1.0, d, 10.0, Vec3::ZERO, -1.0), None);
    assert_eq!(sphere_cast_sphere(o, 1.0, d, 10.0, Vec3::ZERO, inf), None);
    // Random extreme but valid values: an answer is in [0, max_t], never NaN.
    let mut rng = Rng::new(4);
    let pick = |rng: &mut Rng| {
        let v = [0.0, -0.0, 1e-45, 1e-38, 1.0, 3e38, f32::MAX, 0.5];
        let x = v[rng.below(v.len())];
        if rng.chance(0.5) { -x } else { x }
    };
    for _ in 0..20_000 {
        let v = |rng: &mut Rng| Vec3::new(pick(rng), pick(rng), pick(rng));
        let (o, d, c) = (v(&mut rng), v(&mut rng), v(&mut rng));
        let (r, s, max_t) = (
            pick(&mut rng).abs(),
            pick(&mut rng).abs(),
            pick(&mut rng).abs(),
        );
        let (a, b) = (v(&mut rng), v(&mut rng));
        let bx = Aabb::new(a.min(b), a.max(b));
        for t in [
            sphere_cast_sphere(o, r, d, max_t, c, s),
            sphere_cast_aabb(o, r, d, max_t, &bx),
        ]
        .into_iter()
        .flatten()
        {
            assert!((0.0..=max_t).contains(&t), "{t} outside [0, {max_t}]");
        }
        assert!(!point_aabb_distance(o, &bx).is_nan());
        assert!(!point_sphere_distance(o, c, r).is_nan());
    }
}
