//! Serde snapshots of `BroadPhase` (feature `serde`), in a text format (JSON) and a compact
//! binary one (postcard).
//!
//! - A restored broadphase continues bit-identically: random operation sequences (inserts of
//!   spheres and of dynamic and static bodies, updates, removes, group changes, refused stale
//!   keys, steps) under every `Passes`, margins 0 and 0.1 and both placements are snapshot at
//!   random points, restored from both formats, and the next 50 operations applied to the
//!   original and to both copies must give the same keys, errors and lists; the copies pass
//!   `validate()` after every step, and the original's lists equal the test's own brute force
//!   (the model's O(n²) loop, filtered by the groups rule) after every step.
//! - A snapshot is input: every truncation, every single-digit edit of the JSON and every bit
//!   flip (and random byte values) of the binary gives an error or a broadphase that passes
//!   `validate()` and then pairs its own shapes exactly as brute force does; no panic.
//! - Each rule of the key state is refused when broken, with a message naming it.

mod common;

use broadleaf::{
    Aabb, BodyKind, BroadPhase, CollisionGroups, Config, Error, Pair, Passes, Placement, ProxyKey,
    Shape, Vec3,
};
use common::{KeyPair, Model, ModelShape, Rng};
use std::collections::{BTreeSet, HashMap};
use std::fmt::Display;
use std::panic::{AssertUnwindSafe, catch_unwind};

/// One operation, drawn from the original's state and applied to every copy.
#[derive(Clone, Copy, Debug)]
enum Op {
    Insert(ModelShape),
    Update(ProxyKey, ModelShape),
    Remove(ProxyKey),
    SetGroups(ProxyKey, CollisionGroups),
    /// An update with a removed key: refused.
    Stale(ProxyKey),
    Step,
}

/// What an operation returned.
#[derive(Clone, Debug, PartialEq)]
enum Outcome {
    Key(Result<ProxyKey, Error>),
    Done(Result<(), Error>),
    Lists {
        pairs: Vec<Pair>,
        added: Vec<Pair>,
        removed: Vec<Pair>,
    },
}

fn apply(op: Op, bp: &mut BroadPhase) -> Outcome {
    match op {
        Op::Insert(shape) => Outcome::Key(shape.insert_into(bp)),
        Op::Update(key, shape) => Outcome::Done(shape.update_in(bp, key)),
        Op::Remove(key) => Outcome::Done(bp.remove(key)),
        Op::SetGroups(key, groups) => Outcome::Done(bp.set_groups(key, groups)),
        Op::Stale(key) => Outcome::Done(bp.update_sphere(key, Vec3::ZERO, 1.0)),
        Op::Step => {
            bp.step();
            Outcome::Lists {
                pairs: bp.pairs().to_vec(),
                added: bp.added().to_vec(),
                removed: bp.removed().to_vec(),
            }
        }
    }
}

/// The test's own record of the original: shapes and groups as given, removed keys, and the
/// previous step's pairs.
struct Record {
    margin: f32,
    shapes: HashMap<ProxyKey, (ModelShape, CollisionGroups)>,
    removed: Vec<ProxyKey>,
    prev: Vec<KeyPair>,
}

impl Record {
    fn keys(&self) -> Vec<ProxyKey> {
        let mut keys: Vec<ProxyKey> = self.shapes.keys().copied().collect();
        keys.sort_unstable();
        keys
    }

    /// A point near the ±8 m bounds (on a half-metre lattice half the time), or far outside.
    fn point(rng: &mut Rng) -> Vec3 {
        if rng.chance(0.5) {
            let mut lattice = || (rng.below(33) as f32 - 16.0) * 0.5;
            Vec3::new(lattice(), lattice(), lattice())
        } else if rng.chance(0.9) {
            rng.offset(10.0)
        } else {
            rng.offset(200.0)
        }
    }

    fn shape(rng: &mut Rng) -> ModelShape {
        let center = Self::point(rng);
        let size = if rng.chance(0.3) {
            rng.below(5) as f32 * 0.5
        } else {
            rng.range(0.0, 2.0)
        };
        match rng.below(3) {
            0 => ModelShape::Sphere {
                center,
                radius: size,
            },
            1 => ModelShape::body(center, Vec3::splat(size), false),
            _ => ModelShape::body(center, rng.vec3_in(Vec3::ZERO, Vec3::splat(3.0)), true),
        }
    }

    fn groups(rng: &mut Rng) -> CollisionGroups {
        if rng.chance(0.2) {
            return CollisionGroups::ALL;
        }
        let filters = [0b01, 0b10, 0b11, u32::MAX];
        CollisionGroups {
            memberships: 1 + rng.below(3) as u32,
            filter: filters[rng.below(filters.len())],
        }
    }

    fn next_op(&self, rng: &mut Rng) -> Op {
        let keys = self.keys();
        let r = rng.below(100);
        if keys.is_empty() || (r < 22 && keys.len() < 60) {
            return if rng.chance(0.2) && !keys.is_empty() {
                Op::Step
            } else {
                Op::Insert(Self::shape(rng))
            };
        }
        let key = keys[rng.below(keys.len())];
        let shape = self.shapes[&key].0;
        match r {
            0..48 => Op::Update(
                key,
                match rng.below(3) {
                    0 => shape.moved(rng.offset(0.3)),
                    1 => shape.teleported(Self::point(rng)),
                    _ => shape.placed(shape.center(), rng.range(0.0, 2.0)),
                },
            ),
            48..58 => Op::Remove(key),
            58..66 => Op::SetGroups(key, Self::groups(rng)),
            66..69 if !self.removed.is_empty() => {
                Op::Stale(self.removed[rng.below(self.removed.len())])
            }
            _ => Op::Step,
        }
    }

    /// Records what the original did, and checks a step's lists against brute force.
    fn record(&mut self, op: Op, outcome: &Outcome, context: &str) {
        match (op, outcome) {
            (Op::Insert(shape), Outcome::Key(Ok(key))) => {
                let old = self.shapes.insert(*key, (shape, CollisionGroups::ALL));
                assert!(
                    old.is_none(),
                    "{context}: insert issued the live key {key:?}"
                );
            }
            (Op::Update(key, shape), Outcome::Done(Ok(()))) => {
                self.shapes.get_mut(&key).expect("a live key").0 = shape;
            }
            (Op::Remove(key), Outcome::Done(Ok(()))) => {
                self.shapes.remove(&key);
                self.removed.push(key);
            }
            (Op::SetGroups(key, groups), Outcome::Done(Ok(()))) => {
                self.shapes.get_mut(&key).expect("a live key").1 = groups;
            }
            (Op::Stale(_), Outcome::Done(Err(Error::UnknownProxy))) => {}
            (
                Op::Step,
                Outcome::Lists {
                    pairs,
                    added,
                    removed,
                },
            ) => {
                let shapes = self.shapes.iter().map(|(&k, &(s, g))| (k, s, g));
                let (model, want) = brute(self.margin, shapes);
                let (now, before): (BTreeSet<KeyPair>, BTreeSet<KeyPair>) = (
                    want.iter().copied().collect(),
                    self.prev.iter().copied().collect(),
                );
                let want_added: Vec<KeyPair> = now.difference(&before).copied().collect();
                let want_removed: Vec<KeyPair> = before.difference(&now).copied().collect();
                model.assert_list(context, "pairs", pairs, &want);
                model.assert_list(context, "added", added, &want_added);
                model.assert_list(context, "removed", removed, &want_removed);
                self.prev = want;
            }
            _ => panic!("{context}: {op:?} gave {outcome:?}"),
        }
    }
}

/// The model's O(n²) pairs of `shapes` with `margin`, filtered by the groups rule, and the
/// model (for its messages).
fn brute(
    margin: f32,
    shapes: impl Iterator<Item = (ProxyKey, ModelShape, CollisionGroups)>,
) -> (Model, Vec<KeyPair>) {
    let mut model = Model::new(margin);
    let mut groups = HashMap::new();
    for (k, s, g) in shapes {
        model.shapes.insert(k, s);
        groups.insert(k, g);
    }
    let allows = |a: CollisionGroups, b: CollisionGroups| {
        a.memberships & b.filter != 0 && b.memberships & a.filter != 0
    };
    let pairs = model
        .pairs_quadratic()
        .into_iter()
        .filter(|(a, b)| allows(groups[a], groups[b]))
        .collect();
    (model, pairs)
}

fn model_shape(shape: Shape) -> ModelShape {
    match shape {
        Shape::Sphere { center, radius } => ModelShape::Sphere { center, radius },
        Shape::Body { aabb, kind } => ModelShape::Body {
            aabb,
            is_static: kind == BodyKind::Static,
        },
    }
}

/// Every proxy of `bp` with its shape and groups, in slot order.
fn proxies(bp: &BroadPhase) -> Vec<(ProxyKey, Shape, Option<CollisionGroups>)> {
    bp.iter().map(|(k, s)| (k, s, bp.groups(k))).collect()
}

/// Snapshots `bp` in both formats and restores both; each copy holds the same proxies, passes
/// `validate()`, and saves to the same snapshot.
fn restore_both(bp: &BroadPhase, context: &str) -> Vec<(&'static str, BroadPhase)> {
    let json = serde_json::to_string(bp).expect("a broadphase serialises");
    let bin = postcard::to_allocvec(bp).expect("a broadphase serialises");
    let from_json: BroadPhase = serde_json::from_str(&json)
        .unwrap_or_else(|e| panic!("{context}: its own JSON snapshot is refused: {e}\n{json}"));
    let from_bin: BroadPhase = postcard::from_bytes(&bin)
        .unwrap_or_else(|e| panic!("{context}: its own binary snapshot is refused: {e}"));
    for (name, copy) in [("json", &from_json), ("postcard", &from_bin)] {
        copy.validate();
        assert_eq!(proxies(copy), proxies(bp), "{context}: {name}: proxies");
        assert_eq!(copy.config(), bp.config(), "{context}: {name}: config");
        assert_eq!(
            serde_json::to_string(copy).expect("serialises"),
            json,
            "{context}: {name}: the copy's snapshot"
        );
        assert_eq!(
            postcard::to_allocvec(copy).expect("serialises"),
            bin,
            "{context}: {name}: the copy's binary snapshot"
        );
    }
    vec![("json", from_json), ("postcard", from_bin)]
}

/// Operations after each snapshot applied to the original and its copies.
const FOLLOW: usize = 50;

fn run(seed: u64, passes: Passes, margin: f32, placement: Placement) {
    let config = Config {
        bounds: Some(Aabb::new(Vec3::splat(-8.0), Vec3::splat(8.0))),
        octree_placement: placement,
        margin,
        passes,
        ..Config::default()
    };
    let context = format!("seed {seed}, {passes:?}, margin {margin}, {placement:?}");
    let mut rng = Rng::new(seed);
    let mut bp = BroadPhase::new(config);
    let mut record = Record {
        margin,
        shapes: HashMap::new(),
        removed: Vec::new(),
        prev: Vec::new(),
    };
    let mut copies = Vec::new();
    let mut left = 0;
    let (mut snapshots, mut steps) = (0, 0);
    for i in 0..600 {
        if left == 0 && (i == 0 || rng.chance(0.04)) {
            copies = restore_both(&bp, &format!("{context}: snapshot before op {i}"));
            left = FOLLOW;
            snapshots += 1;
        }
        let op = record.next_op(&mut rng);
        let context = format!("{context}: op {i} {op:?}");
        let want = apply(op, &mut bp);
        record.record(op, &want, &context);
        if matches!(op, Op::Step) {
            bp.validate();
            steps += 1;
        }
        for (name, copy) in &mut copies {
            let got = apply(op, copy);
            assert_eq!(
                got, want,
                "{context}: the copy restored from {name} differs"
            );
            if matches!(op, Op::Step) {
                copy.validate();
            }
        }
        if left > 0 {
            left -= 1;
            if left == 0 {
                copies.clear();
            }
        }
    }
    assert!(
        snapshots >= 3 && steps >= 50,
        "{context}: {snapshots} snapshots, {steps} steps"
    );
}

#[test]
fn restored_broadphase_continues_bit_identically() {
    let mut seed = 1;
    for passes in [Passes::Adaptive, Passes::Full, Passes::Incremental] {
        for margin in [0.0, 0.1] {
            for placement in [Placement::Strict, Placement::Loose] {
                for _ in 0..3 {
                    run(seed, passes, margin, placement);
                    seed += 1;
                }
            }
        }
    }
}

/// A small broadphase with every kind of state: spheres, dynamic and static bodies
/// (overlapping), groups, a free slot, a quarantined slot in the last step's pairs, and a
/// pending update.
fn small() -> BroadPhase {
    let mut bp = BroadPhase::new(Config {
        bounds: Some(Aabb::new(Vec3::splat(-4.0), Vec3::splat(4.0))),
        margin: 0.1,
        ..Config::default()
    });
    let s = |x: f32, r: f32| (Vec3::new(x, 0.5, -0.25), r);
    let mut keys = Vec::new();
    for (c, r) in [s(0.0, 1.0), s(1.5, 0.75), s(-1.25, 0.5)] {
        keys.push(bp.insert_sphere(c, r).expect("valid"));
    }
    let body = |lo: f32, hi: f32| Aabb::new(Vec3::new(lo, -1.0, -1.0), Vec3::new(hi, 1.0, 1.0));
    keys.push(
        bp.insert_body(body(-0.5, 0.5), BodyKind::Dynamic)
            .expect("valid"),
    );
    keys.push(
        bp.insert_body(body(2.0, 3.0), BodyKind::Dynamic)
            .expect("valid"),
    );
    keys.push(
        bp.insert_body(body(-3.0, 3.0), BodyKind::Static)
            .expect("valid"),
    );
    keys.push(
        bp.insert_body(body(-4.0, -2.0), BodyKind::Static)
            .expect("valid"),
    );
    let groups = CollisionGroups {
        memberships: 2,
        filter: 1,
    };
    bp.set_groups(keys[1], groups).expect("live");
    bp.step();
    bp.remove(keys[2]).expect("live");
    bp.step();
    bp.remove(keys[4]).expect("live");
    bp.update_sphere(keys[0], Vec3::new(0.25, 0.5, 0.0), 1.0)
        .expect("valid");
    bp
}

/// Deserialises with `de`; on `Ok` the broadphase must pass `validate()`, step exactly like
/// brute force over its own shapes, and keep doing so through a few more operations. A panic
/// anywhere fails the test with `input` in the message. True if the input was accepted.
fn survives<E: Display>(
    what: &str,
    input: &dyn Fn() -> String,
    de: impl FnOnce() -> Result<BroadPhase, E>,
) -> bool {
    let outcome = catch_unwind(AssertUnwindSafe(|| match de() {
        Err(e) => {
            assert!(!e.to_string().is_empty(), "an error without a message");
            false
        }
        Ok(mut bp) => {
            exercise(&mut bp);
            true
        }
    }));
    match outcome {
        Ok(accepted) => accepted,
        Err(panic) => {
            let msg = panic
                .downcast_ref::<String>()
                .cloned()
                .or_else(|| panic.downcast_ref::<&str>().map(|s| s.to_string()))
                .unwrap_or_default();
            panic!("{what}: panicked ({msg}) on the input\n{}", input());
        }
    }
}

/// The pairs brute force finds among `bp`'s own proxies.
fn own_brute(bp: &BroadPhase) -> (Model, Vec<KeyPair>) {
    let shapes = bp.iter().map(|(k, s)| {
        let groups = bp.groups(k).expect("iter gives live keys");
        (k, model_shape(s), groups)
    });
    brute(bp.config().margin, shapes)
}

fn exercise(bp: &mut BroadPhase) {
    bp.validate();
    let (model, want) = own_brute(bp);
    bp.step();
    model.assert_list("first step", "pairs", bp.pairs(), &want);
    for p in bp.added() {
        assert!(bp.pairs().contains(p), "added {p:?} is not a pair");
    }
    for p in bp.removed() {
        assert!(!bp.pairs().contains(p), "removed {p:?} is a pair");
    }
    bp.validate();
    let before: BTreeSet<KeyPair> = want.into_iter().collect();
    let live: Vec<(ProxyKey, Shape)> = bp.iter().collect();
    let fresh = bp
        .insert_sphere(Vec3::new(0.5, 0.5, 0.0), 1.0)
        .expect("valid");
    assert!(
        live.iter().all(|&(k, _)| k != fresh),
        "insert issued a live key"
    );
    if let Some(&(key, shape)) = live.first() {
        match shape {
            Shape::Sphere { .. } => bp.update_sphere(key, Vec3::new(-0.5, 0.0, 0.0), 0.75),
            Shape::Body { .. } => bp.update_body(key, Aabb::new(Vec3::ZERO, Vec3::ONE)),
        }
        .expect("a live key takes a valid update");
    }
    if let Some(&(key, _)) = live.last() {
        bp.remove(key).expect("a live key is removed");
    }
    let (model, want) = own_brute(bp);
    let now: BTreeSet<KeyPair> = want.iter().copied().collect();
    let added: Vec<KeyPair> = now.difference(&before).copied().collect();
    let removed: Vec<KeyPair> = before.difference(&now).copied().collect();
    bp.step();
    model.assert_list("second step", "pairs", bp.pairs(), &want);
    model.assert_list("second step", "added", bp.added(), &added);
    model.assert_list("second step", "removed", bp.removed(), &removed);
    bp.validate();
}

#[test]
fn every_truncation_is_refused() {
    let bp = small();
    let json = serde_json::to_string(&bp).expect("serialises");
    let bin = postcard::to_allocvec(&bp).expect("serialises");
    // Both formats end with the pair list, whose length comes first: no proper prefix of a
    // snapshot is a complete one.
    for len in 0..json.len() {
        let cut = &json[..len];
        let ok = survives("truncated JSON", &|| cut.to_string(), || {
            serde_json::from_str::<BroadPhase>(cut)
        });
        assert!(!ok, "the JSON truncated to {len} bytes was accepted: {cut}");
    }
    for len in 0..bin.len() {
        let cut = &bin[..len];
        let ok = survives("truncated binary", &|| format!("{cut:02x?}"), || {
            postcard::from_bytes::<BroadPhase>(cut)
        });
        assert!(
            !ok,
            "the binary truncated to {len} bytes was accepted: {cut:02x?}"
        );
    }
    assert!(survives("whole JSON", &|| json.clone(), || {
        serde_json::from_str::<BroadPhase>(&json)
    }));
    assert!(survives("whole binary", &|| format!("{bin:02x?}"), || {
        postcard::from_bytes::<BroadPhase>(&bin)
    }));
}

#[test]
fn every_digit_edit_of_the_json_is_an_error_or_consistent() {
    let json = serde_json::to_string(&small()).expect("serialises");
    let (mut accepted, mut refused) = (0, 0);
    for (i, c) in json.char_indices() {
        if !c.is_ascii_digit() {
            continue;
        }
        for d in b'0'..=b'9' {
            if d == c as u8 {
                continue;
            }
            let mut edited = json.clone().into_bytes();
            edited[i] = d;
            let edited = String::from_utf8(edited).expect("ASCII digits");
            if survives(
                &format!("digit {} at {i} set to {}", c, d as char),
                &|| edited.clone(),
                || serde_json::from_str::<BroadPhase>(&edited),
            ) {
                accepted += 1;
            } else {
                refused += 1;
            }
        }
    }
    println!("single-digit edits: {accepted} accepted, {refused} refused");
    assert!(
        accepted > 0 && refused > 0,
        "{accepted} accepted, {refused} refused"
    );
}

#[test]
fn every_bit_flip_of_the_binary_is_an_error_or_consistent() {
    let bin = postcard::to_allocvec(&small()).expect("serialises");
    let mut rng = Rng::new(7);
    let (mut accepted, mut refused) = (0, 0);
    for i in 0..bin.len() {
        let flips = (0..8).map(|b| bin[i] ^ (1 << b));
        let randoms: Vec<u8> = (0..8).map(|_| rng.next_u64() as u8).collect();
        for byte in flips.chain(randoms) {
            if byte == bin[i] {
                continue;
            }
            let mut edited = bin.clone();
            edited[i] = byte;
            if survives(
                &format!("byte {i} set to {byte:#04x}"),
                &|| format!("{edited:02x?}"),
                || postcard::from_bytes::<BroadPhase>(&edited),
            ) {
                accepted += 1;
            } else {
                refused += 1;
            }
        }
    }
    println!("byte edits: {accepted} accepted, {refused} refused");
    assert!(
        accepted > 0 && refused > 0,
        "{accepted} accepted, {refused} refused"
    );
}

/// The JSON snapshot of [`small`] as a value, to break one rule at a time.
fn small_value() -> serde_json::Value {
    serde_json::to_value(small()).expect("serialises")
}

fn refused_with(value: &serde_json::Value, phrase: &str) {
    match serde_json::from_value::<BroadPhase>(value.clone()) {
        Ok(_) => panic!("accepted, expected an error about {phrase:?}: {value}"),
        Err(e) => assert!(
            e.to_string().contains(phrase),
            "error {e:?} does not mention {phrase:?}: {value}"
        ),
    }
}

#[test]
fn each_broken_rule_is_refused_with_its_reason() {
    use serde_json::json;
    let v = small_value();
    // The state `small` leaves: slot 2 free, slot 4 quarantined and in a pair.
    assert_eq!(v["free"], json!([2]), "{v}");
    assert_eq!(v["quarantine"], json!([4]), "{v}");
    assert_eq!(v["slots"][2], json!({ "Free": 2 }), "{v}");
    assert!(
        v["pairs"]
            .as_array()
            .expect("a list")
            .contains(&json!([1, 4])),
        "{v}"
    );

    let edit = |f: &dyn Fn(&mut serde_json::Value)| {
        let mut e = v.clone();
        f(&mut e);
        e
    };
    refused_with(&edit(&|e| e["format"] = json!(2)), "format 2");
    refused_with(
        &edit(&|e| e["config"]["bounds"] = json!({ "min": [1, 1, 1], "max": [0, 0, 0] })),
        "config",
    );
    refused_with(&edit(&|e| e["config"]["margin"] = json!(-1.0)), "config");
    refused_with(&edit(&|e| e["slots"][2] = json!({ "Free": 3 })), "is odd");
    refused_with(
        &edit(&|e| e["slots"][0]["Sphere"]["version"] = json!(2)),
        "is live but its version",
    );
    refused_with(
        &edit(&|e| e["slots"][0]["Sphere"]["version"] = json!(u32::MAX)),
        "is live but its version",
    );
    refused_with(
        &edit(&|e| e["slots"][0]["Sphere"]["radius"] = json!(-1.0)),
        "slot 0: radius is negative",
    );
    refused_with(
        &edit(&|e| e["slots"][3]["Dynamic"]["min"] = json!([5.0, 0.0, 0.0])),
        "slot 3: aabb is inverted",
    );
    refused_with(
        &edit(&|e| e["free"] = json!([])),
        "in neither the free list",
    );
    refused_with(&edit(&|e| e["free"] = json!([2, 2])), "listed twice");
    refused_with(&edit(&|e| e["free"] = json!([2, 4])), "listed twice");
    refused_with(
        &edit(&|e| e["free"] = json!([2, 0])),
        "in the free list but live",
    );
    refused_with(
        &edit(&|e| e["free"] = json!([2, 99])),
        "but there are 7 slots",
    );
    refused_with(
        &edit(&|e| e["slots"][2] = json!({ "Free": u32::MAX - 1 })),
        "version 4294967294 is spent",
    );
    refused_with(
        &edit(&|e| e["slots"][4] = json!({ "Free": 0 })),
        "never been live",
    );
    refused_with(&edit(&|e| e["pairs"] = json!([[3, 3]])), "increasing order");
    refused_with(&edit(&|e| e["pairs"] = json!([[0, 7]])), "increasing order");
    refused_with(&edit(&|e| e["pairs"] = json!([[0, 3], [0, 3]])), "strictly");
    refused_with(&edit(&|e| e["pairs"] = json!([[0, 2]])), "neither live nor");
    refused_with(
        &edit(&|e| e["pairs"] = json!([[5, 6]])),
        "two static bodies",
    );
    refused_with(&edit(&|e| e["unknown"] = json!(1)), "unknown field");

    // A slot whose versions are spent is retired: in neither list, and never reused.
    let retired = edit(&|e| {
        e["slots"][2] = json!({ "Free": u32::MAX - 1 });
        e["free"] = json!([]);
    });
    let mut bp: BroadPhase = serde_json::from_value(retired).expect("a retired slot is fine");
    bp.validate();
    for _ in 0..3 {
        bp.step();
        let key = bp.insert_sphere(Vec3::ZERO, 1.0).expect("valid");
        assert!(
            serde_json::to_value(&bp).expect("serialises")["slots"][2]
                == json!({ "Free": u32::MAX - 1 }),
            "the retired slot was reused by {key:?}"
        );
    }
    bp.validate();
}

/// An empty broadphase, one never stepped, and one whose proxies were all removed restore and
/// continue like the original.
#[test]
fn edge_states_restore() {
    let empty = BroadPhase::new(Config::default());
    let mut fresh = BroadPhase::new(Config::default());
    fresh.insert_sphere(Vec3::ZERO, 1.0).expect("valid");
    fresh.insert_sphere(Vec3::ONE, 1.0).expect("valid");
    let mut gone = fresh.clone();
    gone.step();
    let keys: Vec<ProxyKey> = gone.iter().map(|(k, _)| k).collect();
    for k in keys {
        gone.remove(k).expect("live");
    }
    for (name, original) in [("empty", empty), ("fresh", fresh), ("all removed", gone)] {
        for (format, mut copy) in restore_both(&original, name) {
            let mut original = original.clone();
            for i in 0..3 {
                let want = apply(Op::Step, &mut original);
                assert_eq!(
                    apply(Op::Step, &mut copy),
                    want,
                    "{name}: {format}: step {i}"
                );
                copy.validate();
                let at = Vec3::splat(i as f32);
                let key = original.insert_sphere(at, 0.5);
                assert_eq!(
                    copy.insert_sphere(at, 0.5),
                    key,
                    "{name}: {format}: insert {i}"
                );
            }
        }
    }
}
