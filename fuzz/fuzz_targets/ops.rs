//! Random operation sequences on `BroadPhase` against a brute-force model. Floats come raw from
//! the fuzzer, so NaN, infinities, huge and subnormal values all appear: every refusal must be
//! an `Err` that leaves the broadphase unchanged, and after every step the pairs and events
//! must equal the brute-force set and its difference with the previous step.
#![no_main]

use arbitrary::Arbitrary;
use broadleaf::{
    Aabb, BodyKind, BroadPhase, Config, Pair, Placement, ProxyKey, Shape, Vec3, brute,
};
use libfuzzer_sys::fuzz_target;

#[derive(Arbitrary, Debug)]
enum Op {
    InsertSphere([f32; 3], f32),
    InsertBody([f32; 3], [f32; 3], bool),
    UpdateSphere(u8, [f32; 3], f32),
    UpdateBody(u8, [f32; 3], [f32; 3]),
    Remove(u8),
    /// Moves proxy `i` by a small lattice step, so that pairs form and break often.
    Nudge(u8, i8, i8, i8),
    Step,
}

#[derive(Arbitrary, Debug)]
struct Input {
    depth: u8,
    /// The octree placement: strict (false) or loose (true).
    loose: bool,
    /// Bits 0–1: the margin (0, 0.25, 0.5, 0.75); bits 2–3: the pair cache's skin (0, 0,
    /// 0.1, 0.5).
    margin: u8,
    ops: Vec<Op>,
}

fn v(a: [f32; 3]) -> Vec3 {
    Vec3::from_array(a)
}

fn valid_sphere(c: Vec3, r: f32) -> bool {
    c.is_finite() && r.is_finite() && r >= 0.0
}

fn valid_box(b: &Aabb) -> bool {
    b.is_finite() && b.min.cmple(b.max).all()
}

fuzz_target!(|input: Input| {
    let margin = f32::from(input.margin % 4) * 0.25;
    let skin = [0.0, 0.0, 0.1, 0.5][usize::from(input.margin >> 2) % 4];
    let mut bp = BroadPhase::new(Config {
        bounds: Aabb::new(Vec3::splat(-16.0), Vec3::splat(16.0)),
        octree_depth: u32::from(input.depth % 7),
        margin,
        skin,
        octree_placement: if input.loose {
            Placement::Loose
        } else {
            Placement::Strict
        },
        ..Config::default()
    });
    let mut model: Vec<(ProxyKey, Shape)> = Vec::new();
    let mut dead: Vec<ProxyKey> = Vec::new();
    let mut prev: Vec<Pair> = Vec::new();
    let pick = |model: &[(ProxyKey, Shape)], dead: &[ProxyKey], i: u8| -> Option<ProxyKey> {
        let i = usize::from(i);
        if i % 8 == 7 && !dead.is_empty() {
            return Some(dead[i % dead.len()]);
        }
        (!model.is_empty()).then(|| model[i % model.len()].0)
    };
    for op in input.ops.iter().take(256) {
        match *op {
            Op::InsertSphere(c, r) => {
                let (c, r) = (v(c), r);
                match bp.insert_sphere(c, r) {
                    Ok(k) => model.push((k, Shape::Sphere { center: c, radius: r })),
                    Err(_) => assert!(!valid_sphere(c, r)),
                }
            }
            Op::InsertBody(lo, hi, is_static) => {
                let aabb = Aabb::new(v(lo), v(hi));
                let kind = if is_static { BodyKind::Static } else { BodyKind::Dynamic };
                match bp.insert_body(aabb, kind) {
                    Ok(k) => model.push((k, Shape::Body { aabb, kind })),
                    Err(_) => assert!(!valid_box(&aabb)),
                }
            }
            Op::UpdateSphere(i, c, r) => {
                let Some(key) = pick(&model, &dead, i) else { continue };
                let slot = model.iter().position(|m| m.0 == key);
                let res = bp.update_sphere(key, v(c), r);
                match (slot, res) {
                    (Some(s), Ok(())) => model[s].1 = Shape::Sphere { center: v(c), radius: r },
                    (Some(s), Err(_)) => assert!(
                        !valid_sphere(v(c), r) || !matches!(model[s].1, Shape::Sphere { .. })
                    ),
                    (None, res) => assert!(res.is_err()),
                }
            }
            Op::UpdateBody(i, lo, hi) => {
                let Some(key) = pick(&model, &dead, i) else { continue };
                let slot = model.iter().position(|m| m.0 == key);
                let aabb = Aabb::new(v(lo), v(hi));
                let res = bp.update_body(key, aabb);
                match (slot, res) {
                    (Some(s), Ok(())) => {
                        let Shape::Body { kind, .. } = model[s].1 else { panic!("updated a sphere as a body") };
                        model[s].1 = Shape::Body { aabb, kind };
                    }
                    (Some(s), Err(_)) => assert!(
                        !valid_box(&aabb) || matches!(model[s].1, Shape::Sphere { .. })
                    ),
                    (None, res) => assert!(res.is_err()),
                }
            }
            Op::Remove(i) => {
                let Some(key) = pick(&model, &dead, i) else { continue };
                match model.iter().position(|m| m.0 == key) {
                    Some(s) => {
                        bp.remove(key).expect("live key refused");
                        model.swap_remove(s);
                        dead.push(key);
                    }
                    None => assert!(bp.remove(key).is_err()),
                }
            }
            Op::Nudge(i, x, y, z) => {
                if model.is_empty() {
                    continue;
                }
                let s = usize::from(i) % model.len();
                let d = Vec3::new(f32::from(x % 4), f32::from(y % 4), f32::from(z % 4)) * 0.25;
                let (key, shape) = &mut model[s];
                match shape {
                    Shape::Sphere { center, radius } => {
                        if bp.update_sphere(*key, *center + d, *radius).is_ok() {
                            *center += d;
                        }
                    }
                    Shape::Body { aabb, .. } => {
                        let moved = Aabb::new(aabb.min + d, aabb.max + d);
                        if bp.update_body(*key, moved).is_ok() {
                            *aabb = moved;
                        }
                    }
                }
            }
            Op::Step => prev = check(&mut bp, &model, &prev, margin),
        }
        assert_eq!(bp.len(), model.len());
    }
    check(&mut bp, &model, &prev, margin);
    for (key, shape) in &model {
        assert_eq!(bp.shape(*key), Some(*shape));
    }
});

fn check(bp: &mut BroadPhase, model: &[(ProxyKey, Shape)], prev: &[Pair], margin: f32) -> Vec<Pair> {
    let proxies: Vec<brute::Proxy> = model
        .iter()
        .map(|(key, shape)| brute::Proxy {
            key: *key,
            aabb: shape.grown_aabb(margin),
            is_static: shape.is_static(),
        })
        .collect();
    let expected = brute::pairs(&proxies);
    let out = bp.step();
    assert_eq!(out.pairs, expected.as_slice());
    let mut added = Vec::new();
    let mut removed = Vec::new();
    broadleaf::pair::diff(prev, &expected, &mut added, &mut removed);
    assert_eq!(out.added, added.as_slice());
    assert_eq!(out.removed, removed.as_slice());
    expected
}
