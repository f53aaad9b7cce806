//! Cases the fuzz target's logic found, replayed against the same model (a map of the shapes
//! inserted, its own growth by the margin, its own O(n²) loop and set difference): after every
//! step the pairs and events equal the model's, whatever the magnitudes (boxes reaching
//! `3e38`, fat boxes that overflow to infinity), and nothing panics.

use broadleaf::{Aabb, BodyKind, BroadPhase, Config, Pair, Placement, ProxyKey, Shape, Vec3};

use std::collections::{BTreeSet, HashMap};

#[derive(Debug, Clone)]
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

#[derive(Debug, Clone)]
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

fn run(input: Input) {
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
}

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
    let out = bp.step();
    let got = as_key_pairs(out.pairs);
    if got != expected {
        for p in expected.iter().filter(|p| !got.contains(p)) {
            eprintln!(
                "MISSING {p:?} {:?} {:?} margin {margin}",
                shapes[&p.0], shapes[&p.1]
            );
        }
        for p in got.iter().filter(|p| !expected.contains(p)) {
            eprintln!(
                "EXTRA {p:?} {:?} {:?} margin {margin}",
                shapes[&p.0], shapes[&p.1]
            );
        }
    }
    assert_eq!(got, expected);
    assert_eq!(as_key_pairs(out.added), added);
    assert_eq!(as_key_pairs(out.removed), removed);
    bp.validate();
    expected
}

/// A sphere of radius `3e38` gets a box (and a fat box) that overflows to infinity; an infinite
/// query box must not meet the grid's removed entries (their box is the empty box, `+∞..−∞`,
/// which an infinite box would otherwise "overlap").
#[test]
fn an_infinite_box_meets_no_removed_entry() {
    run(Input {
        depth: 5,
        loose: false,
        margin: 1,
        ops: vec![
            Op::InsertBody([2.25, -1.0, 0.75], [5.25, 6.25, 2.0], true),
            Op::UpdateBody(82, [3.0, 4.0, -6.25], [6.25, 3e38, -1.25]),
            Op::InsertBody([-5.75, 3.25, 2.0], [-1.0, 9.0, 9.25], false),
            Op::InsertSphere([-0.75, 4.25, 1.25], 1.5),
            Op::InsertBody([1.75, -0.75, -3.25], [4.5, 1.5, 3e38], true),
            Op::InsertBody([3.25, -6.75, -1.5], [9.75, -4.0, 1.5], true),
            Op::InsertBody([-5.0, -2.25, 2.25], [0.5, 3.75, 7.0], false),
            Op::InsertBody([-7.5, 4.0, 3e38], [-0.25, 5.75, 3e38], false),
            Op::InsertBody([6.0, 1.0, 4.75], [6.0, 8.0, 8.5], true),
            Op::InsertBody([6.75, 2.0, 5.5], [9.5, 5.75, 8.25], false),
            Op::InsertSphere([-3.0, -6.25, -3.5], 3.75),
            Op::InsertSphere([4.5, 4.75, -2.75], 3.5),
            Op::InsertSphere([-3.25, -2.0, 1.0], 1.25),
            Op::Remove(47),
            Op::InsertSphere([5.5, -4.75, 3.0], 4.5),
            Op::InsertBody([5.25, -0.75, -0.75], [5.25, 0.0, 1.0], true),
            Op::InsertBody([-4.25, -1.75, -6.5], [2.75, 3.0, -1.0], true),
            Op::InsertSphere([8.0, 7.25, 3.5], 5.5),
            Op::InsertSphere([-1.0, -4.25, 6.0], 5.0),
            Op::InsertBody([-1.0, 4.5, 8.0], [5.75, 12.25, 9.0], false),
            Op::InsertBody([-3.25, -4.25, 0.5], [-1.0, -1.5, 3.75], false),
            Op::UpdateSphere(101, [-4.75, 0.5, 3e38], 5.25),
            Op::Step,
            Op::InsertSphere([-4.0, -6.25, 7.0], 7.75),
            Op::InsertBody([-1.75, 7.5, -4.5], [1.25, 10.25, -2.75], false),
            Op::Step,
            Op::Remove(74),
            Op::InsertSphere([-1.5, -0.75, -1.0], 3e38),
            Op::Step,
        ],
    });
}

/// Two bodies touching exactly at `y = 3e38` (one reaching up to it, one flat there) pair in the
/// incremental pass as in the full pass.
#[test]
fn boxes_touching_at_3e38_pair_incrementally() {
    run(Input {
        depth: 4,
        loose: false,
        margin: 15,
        ops: vec![
            Op::InsertBody([7.5, 1.5, 5.25], [13.5, 3e38, 6.5], false),
            Op::InsertSphere([-5.5, 6.0, -1.0], 7.0),
            Op::InsertBody([8.0, -6.0, -5.5], [3e38, -1.5, -1.75], false),
            Op::InsertBody([-4.0, 3e38, -1.75], [-1.0, 3e38, 2.0], true),
            Op::InsertBody([-1.25, -3.75, -2.75], [5.5, 1.75, 2.25], false),
            Op::Remove(19),
            Op::InsertSphere([2.25, -6.0, -0.75], 4.75),
            Op::InsertSphere([-0.25, -5.5, -3.5], 2.75),
            Op::InsertSphere([-5.0, -3.25, -0.75], 5.5),
            Op::InsertBody([6.5, -4.5, 6.75], [6.75, 2.75, 11.0], false),
            Op::Remove(45),
            Op::InsertSphere([-1.25, -5.75, 5.75], 1.25),
            Op::InsertBody([0.5, -0.75, -2.5], [7.5, 3e38, 2.0], false),
            Op::Remove(173),
            Op::InsertSphere([-6.25, -2.0, -7.5], 5.5),
            Op::InsertSphere([-5.5, 5.25, 4.25], 7.5),
            Op::Remove(109),
            Op::InsertBody([3.5, -1.25, 5.0], [10.25, 5.5, 5.5], false),
            Op::InsertSphere([5.0, 1.25, -6.5], 1.75),
            Op::InsertSphere([-2.25, 1.0, 3.75], 4.25),
            Op::InsertSphere([-0.75, 4.25, -1.0], 5.75),
            Op::InsertBody([6.0, -6.75, 5.0], [8.5, -5.25, 11.5], true),
            Op::InsertSphere([3e38, 4.5, -6.0], 6.5),
            Op::Remove(88),
            Op::Remove(6),
            Op::Step,
            Op::UpdateSphere(60, [3.5, -0.75, 6.25], 2.0),
            Op::Step,
            Op::Nudge(133, -1, 3, -3),
        ],
    });
}
