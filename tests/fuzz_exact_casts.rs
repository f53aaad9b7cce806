//! Casts the whole-API fuzz target found answered wrongly (issue 43), replayed as the
//! operations their inputs decode to: a cast's answer is exactly the nearest hit of the public
//! shape functions (`geom::ray_sphere`, ...) over the shapes given, and those functions give
//! the exact geometric answer for these inputs, however close the ray passes and however small
//! the offsets: a point sphere of radius 0 is hit only by a ray through the point. The
//! expectations come from the tests' own `f64` reasoning about rays along one axis, never
//! from the functions under test.
#![cfg(feature = "serde")]

use broadleaf::geom::{ray_sphere, sphere_cast_sphere};
use broadleaf::{BroadPhase, Config, Error, Passes, Placement, QueryFilter, Vec3};

/// The hit of the segment `o + t·(0, 0, dz)`, `t ∈ [0, max_t]`, on the sphere `(c, r)`, by
/// the tests' own reasoning: the line is at squared distance `(o.x − c.x)² + (o.y − c.y)²`
/// from the centre (exact in `f64` for the inputs below: their differences and squares fit
/// its 53 bits); it meets the sphere iff that is at most `r²`, first at
/// `t = ((c.z − o.z) − sign(dz)·√(r² − dist²)) / dz`, or at 0 from inside.
fn hit_along_z(o: Vec3, dz: f32, c: Vec3, r: f32, max_t: f32) -> Option<f32> {
    let (dx, dy) = (
        f64::from(o.x) - f64::from(c.x),
        f64::from(o.y) - f64::from(c.y),
    );
    let dist2 = dx * dx + dy * dy;
    let r = f64::from(r);
    if dist2 > r * r {
        return None;
    }
    let half = (r * r - dist2).sqrt();
    let dz = f64::from(dz);
    let t = ((f64::from(c.z) - f64::from(o.z)) - dz.signum() * half) / dz;
    let inside = (f64::from(o.z) - f64::from(c.z)).abs() <= half;
    let t = if inside { 0.0 } else { t };
    (t >= 0.0 && t as f32 <= max_t).then_some(t as f32)
}

/// Issue 43's first input, about 90 seconds into a run from an empty corpus: a ray passing
/// `1.3e-9` beside a sphere of radius 0 was a hit at `t = 2.269` for `ray_sphere`, whose
/// discriminant `b² − a·c` cancelled in `f32` (`b ≈ −95.9`, `a·c ≈ 9192`, their true
/// difference `−1.65e-18`), while the broadphase's box test rightly missed it.
///
/// Config: no hint, strict placement, margin 0, skin 0, `Passes::Adaptive`.
#[test]
fn grazing_ray_beside_a_point_sphere_misses() {
    let mut bp = BroadPhase::new(Config {
        margin: 0.0,
        skin: 0.0,
        passes: Passes::Adaptive,
        octree_placement: Placement::Strict,
        ..Config::default()
    });
    let center = Vec3::new(0.0, 8.5e-44, -23.0);
    let point = bp.insert_sphere(center, 0.0).expect("a valid sphere");
    assert_eq!(
        bp.insert_sphere(Vec3::ZERO, -1.285_590_3e-9),
        Err(Error::NegativeRadius(-1.285_590_3e-9))
    );
    let (o, dz, max_t) = (Vec3::new(-1.285_590_3e-9, 2.47e-43, -8.25), -6.5, 15.25);
    let dir = Vec3::new(0.0, 0.0, dz);
    assert_eq!(hit_along_z(o, dz, center, 0.0, max_t), None);
    assert_eq!(ray_sphere(o, dir, center, 0.0, max_t), None);
    assert_eq!(bp.cast_ray_with(o, dir, max_t, &QueryFilter::new()), None);
    assert_eq!(bp.cast_ray(o, dir, max_t), None);
    // The same ray moved onto the point hits it, at the same `t` for both.
    let on = Vec3::new(center.x, center.y, o.z);
    let want = hit_along_z(on, dz, center, 0.0, max_t);
    assert_eq!(want, Some((14.75f64 / 6.5) as f32));
    assert_eq!(bp.cast_ray(on, dir, max_t), want.map(|t| (point, t)));
    bp.step();
    assert!(bp.pairs().is_empty());
    bp.validate();
}

/// Issue 43's second input, found once the discriminant had Lagrange's form in `f32`: a ray
/// missing a point by `5.9e-39` was a hit at `t = 0.687`, as `|m × d|²` squared `9.8e-38`
/// to 0 in `f32`; the box test missed it. A clean JSON snapshot is restored before the cast.
///
/// Config: no hint, loose placement, margin 0, skin 0, `Passes::Adaptive`.
#[test]
fn ray_a_subnormal_offset_beside_a_point_sphere_misses() {
    let config = Config {
        margin: 0.0,
        skin: 0.0,
        passes: Passes::Adaptive,
        octree_placement: Placement::Loose,
        ..Config::default()
    };
    let mut bp = BroadPhase::new(config);
    let center = Vec3::new(5.877_472e-39, 0.0, 11.5);
    let point = bp.insert_sphere(center, 0.0).expect("a valid sphere");
    let json = serde_json::to_vec(&bp).expect("a broadphase serialises");
    let bp: BroadPhase = serde_json::from_slice(&json).expect("its own snapshot restores");
    bp.validate();
    let (o, dz, max_t) = (Vec3::ZERO, 16.75, 11.5);
    let dir = Vec3::new(0.0, 0.0, dz);
    assert_eq!(hit_along_z(o, dz, center, 0.0, max_t), None);
    assert_eq!(ray_sphere(o, dir, center, 0.0, max_t), None);
    assert_eq!(bp.cast_ray_with(o, dir, max_t, &QueryFilter::new()), None);
    assert_eq!(bp.cast_ray(o, dir, max_t), None);
    // Started beside the point by that offset, the ray hits it.
    let on = Vec3::new(center.x, 0.0, 0.0);
    let want = hit_along_z(on, dz, center, 0.0, max_t);
    assert_eq!(want, Some((11.5f64 / 16.75) as f32));
    assert_eq!(bp.cast_ray(on, dir, max_t), want.map(|t| (point, t)));
}

/// The smallest `f32` radius whose sphere about `c` reaches the line through `o` along `z`,
/// and the largest that does not, from the squared distance in `f64` (exact here).
fn radii_around(o: Vec3, c: Vec3) -> (f32, f32) {
    let (dx, dy) = (
        f64::from(o.x) - f64::from(c.x),
        f64::from(o.y) - f64::from(c.y),
    );
    let dist2 = dx * dx + dy * dy;
    let reaches = |r: f32| f64::from(r) * f64::from(r) >= dist2;
    let mut r = dist2.sqrt() as f32;
    while !reaches(r) {
        r = f32::from_bits(r.to_bits() + 1);
    }
    while r > 0.0 && reaches(f32::from_bits(r.to_bits() - 1)) {
        r = f32::from_bits(r.to_bits() - 1);
    }
    (r, f32::from_bits(r.to_bits() - 1))
}

/// `ray_sphere` and `sphere_cast_sphere` (a ray is a cast of radius 0) on the issue's numbers
/// and their neighbours: beside the point, through it, and grazing spheres whose radius is
/// the offset (tangent: a hit) or just under it (a miss).
#[test]
fn shape_functions_on_the_issue_numbers() {
    let cases = [
        (
            Vec3::new(-1.285_590_3e-9, 2.47e-43, -8.25),
            -6.5,
            Vec3::new(0.0, 8.5e-44, -23.0),
            15.25,
        ),
        (Vec3::ZERO, 16.75, Vec3::new(5.877_472e-39, 0.0, 11.5), 11.5),
    ];
    for (o, dz, c, max_t) in cases {
        let dir = Vec3::new(0.0, 0.0, dz);
        let (offset, under) = radii_around(o, c);
        let on = Vec3::new(c.x, c.y, o.z);
        for (o, r) in [(o, 0.0), (o, offset), (o, under), (on, 0.0), (on, offset)] {
            let want = hit_along_z(o, dz, c, r, max_t);
            assert_eq!(ray_sphere(o, dir, c, r, max_t), want, "ray {o} {r}");
            assert_eq!(
                sphere_cast_sphere(o, 0.0, dir, max_t, c, r),
                want,
                "cast {o} {r}"
            );
            assert_eq!(
                sphere_cast_sphere(c, r, -dir, max_t, o, 0.0),
                want,
                "reversed cast {o} {r}"
            );
        }
        assert!(hit_along_z(o, dz, c, offset, max_t).is_some());
        assert!(hit_along_z(o, dz, c, under, max_t).is_none());
    }
}

/// Found by reading, not by the fuzzer: a sphere of radius `x` about `(x, 0, 0)` has its
/// surface through the origin, and for a huge `x` the `f64` difference `start − centre`
/// drops a start `0.25` beside it, so the shape functions answer as for a start on the
/// surface (exact for a sphere moved by a few `2⁻⁵²` of its radius, as documented), while the
/// sphere's `f32` box, `0.25` away, pruned it: the broadphase must answer as the functions
/// do, for a ray, a sphere cast and `nearest` alike, beside a small sphere `0.5` away.
#[test]
fn a_huge_sphere_grazed_by_a_small_query_answers_as_the_shape_functions() {
    use broadleaf::geom::point_sphere_distance;
    for x in [1e30f32, 3e20, 1e10, 7e7] {
        for passes in [Passes::Full, Passes::Incremental] {
            let mut bp = BroadPhase::new(Config {
                passes,
                ..Config::default()
            });
            let huge_center = Vec3::new(x, 0.0, 0.0);
            let small_center = Vec3::new(-1.0, 0.0, 0.0);
            let huge = bp.insert_sphere(huge_center, x).expect("a valid sphere");
            let small = bp
                .insert_sphere(small_center, 0.25)
                .expect("a valid sphere");
            for step in [false, true] {
                if step {
                    bp.step();
                    bp.validate();
                }
                for ox in [-0.25f32, -1e-3, -1e-6] {
                    let (o, dir, max_t) = (Vec3::new(ox, -1.0, 0.0), Vec3::Y, 2.0);
                    let first = |t_huge: Option<f32>, t_small: Option<f32>| match (t_huge, t_small)
                    {
                        (Some(a), Some(b)) if b < a => Some((small, b)),
                        (Some(a), _) => Some((huge, a)),
                        (None, b) => b.map(|b| (small, b)),
                    };
                    let want = first(
                        ray_sphere(o, dir, huge_center, x, max_t),
                        ray_sphere(o, dir, small_center, 0.25, max_t),
                    );
                    assert_eq!(bp.cast_ray(o, dir, max_t), want, "ray {x} {ox}");
                    let want = first(
                        sphere_cast_sphere(o, 0.0, dir, max_t, huge_center, x),
                        sphere_cast_sphere(o, 0.0, dir, max_t, small_center, 0.25),
                    );
                    assert_eq!(bp.cast_sphere(o, 0.0, dir, max_t), want, "cast {x} {ox}");
                    let mut want = [
                        (point_sphere_distance(o, huge_center, x), huge),
                        (point_sphere_distance(o, small_center, 0.25), small),
                    ];
                    want.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
                    let want = want.map(|(d, k)| (k, d));
                    assert_eq!(bp.nearest(o, 1), want[..1], "nearest {x} {ox}");
                }
            }
        }
    }
}
