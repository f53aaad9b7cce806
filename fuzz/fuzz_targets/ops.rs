//! Random operation sequences on `BroadPhase` against the target's own model: a map of the
//! shapes it inserted, its own growth by the margin, its own O(n²) loop and its own set
//! difference. Floats come raw from the fuzzer, so NaN, infinities, huge and subnormal values
//! all appear: every refusal must be an `Err` that leaves the broadphase unchanged, and after
//! every step the pairs and events must equal the model's set and its difference with the
//! model's previous set.
#![no_main]

use arbitrary::Arbitrary;
use broadleaf::{Aabb, BodyKind, BroadPhase, Config, Pair, Placement, ProxyKey, Shape, Vec3};
use libfuzzer_sys::fuzz_target;
use std::collections::{BTreeSet, HashMap};

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
    // The model: the shape of every live proxy as given, and the live keys in insertion order
    // (a deterministic order to pick from).
    let mut shapes: HashMap<ProxyKey, Shape> = HashMap::new();
    let mut live: Vec<ProxyKey> = Vec::new();
    let mut dead: Vec<ProxyKey> = Vec::new();
    let mut prev: Vec<KeyPair> = Vec::new();
    let pick = |live: &[ProxyKey], dead: &[ProxyKey], i: u8| -> Option<ProxyKey> {
        let i = usize::from(i);
        if i % 8 == 7 && !dead.is_empty() {
            return Some(dead[i % dead.len()]);
        }
        (!live.is_empty()).then(|| live[i % live.len()])
    };
    for op in input.ops.iter().take(256) {
        match *op {
            Op::InsertSphere(c, r) => {
                let (c, r) = (v(c), r);
                match bp.insert_sphere(c, r) {
                    Ok(k) => {
                        assert!(
                            shapes
                                .insert(
                                    k,
                                    Shape::Sphere {
                                        center: c,
                                        radius: r
                                    }
                                )
                                .is_none()
                        );
                        live.push(k);
                    }
                    Err(_) => assert!(!valid_sphere(c, r)),
                }
            }
            Op::InsertBody(lo, hi, is_static) => {
                let aabb = Aabb::new(v(lo), v(hi));
                let kind = if is_static {
                    BodyKind::Static
                } else {
                    BodyKind::Dynamic
                };
                match bp.insert_body(aabb, kind) {
                    Ok(k) => {
                        assert!(shapes.insert(k, Shape::Body { aabb, kind }).is_none());
                        live.push(k);
                    }
                    Err(_) => assert!(!valid_box(&aabb)),
                }
            }
            Op::UpdateSphere(i, c, r) => {
                let Some(key) = pick(&live, &dead, i) else {
                    continue;
                };
                let res = bp.update_sphere(key, v(c), r);
                match (shapes.get_mut(&key), res) {
                    (Some(shape), Ok(())) => {
                        assert!(
                            matches!(shape, Shape::Sphere { .. }),
                            "updated a body as a sphere"
                        );
                        *shape = Shape::Sphere {
                            center: v(c),
                            radius: r,
                        };
                    }
                    (Some(shape), Err(_)) => {
                        assert!(!valid_sphere(v(c), r) || !matches!(shape, Shape::Sphere { .. }))
                    }
                    (None, res) => assert!(res.is_err()),
                }
            }
            Op::UpdateBody(i, lo, hi) => {
                let Some(key) = pick(&live, &dead, i) else {
                    continue;
                };
                let aabb = Aabb::new(v(lo), v(hi));
                let res = bp.update_body(key, aabb);
                match (shapes.get_mut(&key), res) {
                    (Some(shape), Ok(())) => {
                        let Shape::Body { kind, .. } = *shape else {
                            panic!("updated a sphere as a body")
                        };
                        *shape = Shape::Body { aabb, kind };
                    }
                    (Some(shape), Err(_)) => {
                        assert!(!valid_box(&aabb) || matches!(shape, Shape::Sphere { .. }))
                    }
                    (None, res) => assert!(res.is_err()),
                }
            }
            Op::Remove(i) => {
                let Some(key) = pick(&live, &dead, i) else {
                    continue;
                };
                match shapes.remove(&key) {
                    Some(_) => {
                        bp.remove(key).expect("live key refused");
                        let s = live.iter().position(|&k| k == key).expect("a live key");
                        live.swap_remove(s);
                        dead.push(key);
                    }
                    None => assert!(bp.remove(key).is_err()),
                }
            }
            Op::Nudge(i, x, y, z) => {
                if live.is_empty() {
                    continue;
                }
                let key = live[usize::from(i) % live.len()];
                let d = Vec3::new(f32::from(x % 4), f32::from(y % 4), f32::from(z % 4)) * 0.25;
                let shape = shapes.get_mut(&key).expect("a live key");
                match shape {
                    Shape::Sphere { center, radius } => {
                        if bp.update_sphere(key, *center + d, *radius).is_ok() {
                            *center += d;
                        }
                    }
                    Shape::Body { aabb, .. } => {
                        let moved = Aabb::new(aabb.min + d, aabb.max + d);
                        if bp.update_body(key, moved).is_ok() {
                            *aabb = moved;
                        }
                    }
                }
            }
            Op::Step => prev = check(&mut bp, &shapes, &prev, margin),
        }
        assert_eq!(bp.len(), shapes.len());
    }
    check(&mut bp, &shapes, &prev, margin);
    for (key, shape) in &shapes {
        assert_eq!(bp.shape(*key), Some(*shape));
    }
});

/// A pair as the model lists it: `(smaller key, larger key)`.
type KeyPair = (ProxyKey, ProxyKey);

/// The box a proxy pairs with: a sphere's `center ± (radius + margin)`, a body's box with
/// `margin` added on every side. A face that overflows becomes `±∞`, which overlaps exactly
/// what the crate's `±f32::MAX` overlaps.
fn pair_box(shape: &Shape, margin: f32) -> (Vec3, Vec3) {
    match *shape {
        Shape::Sphere { center, radius } => {
            let r = radius + margin;
            (
                Vec3::new(center.x - r, center.y - r, center.z - r),
                Vec3::new(center.x + r, center.y + r, center.z + r),
            )
        }
        Shape::Body { aabb, .. } => (
            Vec3::new(
                aabb.min.x - margin,
                aabb.min.y - margin,
                aabb.min.z - margin,
            ),
            Vec3::new(
                aabb.max.x + margin,
                aabb.max.y + margin,
                aabb.max.z + margin,
            ),
        ),
    }
}

fn is_static(shape: &Shape) -> bool {
    matches!(
        shape,
        Shape::Body {
            kind: BodyKind::Static,
            ..
        }
    )
}

/// Every pair of overlapping closed pair boxes but static×static, by testing all of them;
/// sorted.
fn model_pairs(shapes: &HashMap<ProxyKey, Shape>, margin: f32) -> Vec<KeyPair> {
    let boxes: Vec<(ProxyKey, (Vec3, Vec3), bool)> = shapes
        .iter()
        .map(|(&k, s)| (k, pair_box(s, margin), is_static(s)))
        .collect();
    let mut out = Vec::new();
    for (i, (k, (p0, p1), s)) in boxes.iter().enumerate() {
        for (l, (q0, q1), t) in &boxes[i + 1..] {
            let overlap = p0.x <= q1.x
                && q0.x <= p1.x
                && p0.y <= q1.y
                && q0.y <= p1.y
                && p0.z <= q1.z
                && q0.z <= p1.z;
            if !(*s && *t) && overlap {
                out.push(if k < l { (*k, *l) } else { (*l, *k) });
            }
        }
    }
    out.sort_unstable();
    out
}

fn as_key_pairs(pairs: &[Pair]) -> Vec<KeyPair> {
    pairs.iter().map(|p| (p.a, p.b)).collect()
}

/// Steps `bp` and checks its pairs against the model's and its events against the model's own
/// set difference with `prev`; returns the model's pairs (the next step's `prev`).
fn check(
    bp: &mut BroadPhase,
    shapes: &HashMap<ProxyKey, Shape>,
    prev: &[KeyPair],
    margin: f32,
) -> Vec<KeyPair> {
    let expected = model_pairs(shapes, margin);
    let (now, before): (BTreeSet<KeyPair>, BTreeSet<KeyPair>) = (
        expected.iter().copied().collect(),
        prev.iter().copied().collect(),
    );
    let added: Vec<KeyPair> = now.difference(&before).copied().collect();
    let removed: Vec<KeyPair> = before.difference(&now).copied().collect();
    bp.step();
    assert_eq!(as_key_pairs(bp.pairs()), expected);
    assert_eq!(as_key_pairs(bp.added()), added);
    assert_eq!(as_key_pairs(bp.removed()), removed);
    bp.validate();
    expected
}
