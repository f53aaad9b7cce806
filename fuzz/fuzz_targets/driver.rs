//! The fuzz driver: random operation sequences over the whole `BroadPhase` API, checked
//! against the driver's own model — a map of the shapes and groups it gave, its own growth by
//! the margin, its own O(n²) pair loop with bevy_rapier's groups rule, its own set difference
//! for the events, and its own loops over the model for every query. Nothing it expects is
//! read from the state under test.
//!
//! Shared by the libFuzzer target (`fuzz/fuzz_targets/ops.rs`, nightly, `cargo fuzz run ops`)
//! and the stable test `tests/fuzz_ops.rs` (random bytes through `arbitrary::Unstructured`):
//! both `#[path]`-import this file and call [`run`].
//!
//! What it drives and checks:
//! - `insert_sphere_with` / `insert_body_with` with groups beside the plain inserts, and
//!   `contains` (live keys, removed keys, the null key) after every step;
//! - every `Config` corner it can reach: a region hint (valid or not: `try_new` must refuse
//!   exactly the bad ones), both placements, margins 0–0.75, skins, all three `Passes` (after
//!   a step, `stats().pass` must be one the forced choice allows);
//! - inserts, updates, removes, small lattice moves, `set_groups` (stale keys refused), and
//!   the batches `update_spheres` / `update_bodies` / `update_centers` (also with slices of
//!   different lengths) with bad entries mixed in: a batch with a
//!   bad entry must be refused whole, `BatchError.index` naming the first bad entry by the
//!   driver's own rule and its error the kind that rule gives, nothing applied;
//! - after every step: `pairs` equals the model's sorted O(n²) set (static × static and
//!   pairs the groups forbid left out), `added` / `removed` equal the model's difference with
//!   its previous set, `validate()` holds;
//! - every query, plain and filtered (groups, an excluded key, a predicate that rejects a
//!   subset of the model's proxies and checks it is shown the model's shape), against the
//!   model: `query_aabb(_with)` (margin-grown boxes), `query_sphere(_with)` with a visitor
//!   that may stop early (then exactly `n + 1` distinct matches were visited and `Break` was
//!   returned), and the casts and `nearest(_into)`. The casts and distances are compared
//!   exactly with the nearest accepted hit over the model's shapes through `geom`'s public
//!   shape functions (`ray_sphere`, `Aabb::ray_entry`, `sphere_cast_sphere`,
//!   `sphere_cast_aabb`, `point_sphere_distance`, `point_aabb_distance`) — the same `f32`
//!   (or `f64`, rounded once) computation the broadphase promises its answers equal, so the
//!   comparison needs no tolerance — ties to the smaller key, as `tests/bp_queries.rs` does;
//! - serde snapshots (JSON and postcard): a clean one must restore, pass `validate()`, and
//!   carry on as the original would (the driver continues with the restored copy against the
//!   same model); a damaged one (a byte changed, or cut short) must give `Err` or a
//!   broadphase whose `validate()` holds and that pairs its own shapes as the O(n²) loop
//!   does — never a panic.
//!
//! Floats come from the input either as small lattice values (so that shapes meet, touch
//! exactly and pair often) or raw (NaN, infinities, huge and subnormal values): every refusal
//! must be the `Err` the driver's own rule predicts, with the broadphase unchanged.

use arbitrary::{Arbitrary, Unstructured};
use broadleaf::geom::{
    inverse_dir, point_aabb_distance, point_sphere_distance, ray_sphere, sphere_cast_aabb,
    sphere_cast_sphere,
};
use broadleaf::{
    Aabb, BatchError, BodyKind, BroadPhase, CollisionGroups, Config, Error, Pair, Pass, Passes,
    Placement, ProxyKey, QueryFilter, Shape, Vec3,
};
use core::ops::ControlFlow;
use std::collections::{BTreeSet, HashMap};

/// A float: a small lattice value (a quarter of an `i8`, so `±32`) or any `f32` bit pattern.
#[derive(Arbitrary, Clone, Copy, Debug)]
pub enum F {
    Small(i8),
    Raw(f32),
}

impl F {
    fn get(self) -> f32 {
        match self {
            F::Small(i) => f32::from(i) * 0.25,
            F::Raw(x) => x,
        }
    }
}

fn v(a: [F; 3]) -> Vec3 {
    Vec3::new(a[0].get(), a[1].get(), a[2].get())
}

/// A query filter as the input describes it; proxies are named by pick index (see
/// [`Model::pick`]), the predicate by the proxies' insertion serials.
#[derive(Arbitrary, Clone, Copy, Debug)]
pub struct Filter {
    /// Groups as two 4-bit masks.
    groups: Option<(u8, u8)>,
    exclude: Option<u8>,
    /// Reject the proxies whose serial is `residue` modulo `2 + modulus % 4`.
    predicate: Option<(u8, u8)>,
}

#[derive(Arbitrary, Debug)]
pub enum Op {
    /// An insert, with groups as two 4-bit masks through `insert_sphere_with` if given.
    InsertSphere([F; 3], F, Option<(u8, u8)>),
    InsertBody([F; 3], [F; 3], bool, Option<(u8, u8)>),
    UpdateSphere(u8, [F; 3], F),
    UpdateBody(u8, [F; 3], [F; 3]),
    Remove(u8),
    /// Moves proxy `i` by a small lattice step, so that pairs form and break often.
    Nudge(u8, i8, i8, i8),
    /// Sets proxy `i`'s groups to two 4-bit masks (`0xff`: every group).
    SetGroups(u8, u8, u8),
    /// The first `n % (MAX_BATCH + 1)` entries as one batch (an array, not a `Vec`, whose
    /// decoded length would eat the rest of the input).
    UpdateSpheres(u8, [(u8, [F; 3], F); MAX_BATCH]),
    UpdateBodies(u8, [(u8, [F; 3], [F; 3]); MAX_BATCH]),
    /// `update_centers` with the first `n % (MAX_BATCH + 1)` keys and, one time in four, a
    /// different number of centres (`m / 4 % (MAX_BATCH + 1)`, for `m % 4 == 0`).
    UpdateCenters(u8, u8, [(u8, [F; 3]); MAX_BATCH]),
    /// `insert_spheres` with the first `n % (MAX_BATCH + 1)` entries.
    InsertSpheres(u8, [([F; 3], F); MAX_BATCH]),
    /// A box query, with a visitor that stops after this many matches if given.
    QueryAabb([F; 3], [F; 3], Filter, Option<u8>),
    QuerySphere([F; 3], F, Filter, Option<u8>),
    CastRay([F; 3], [F; 3], F, Filter),
    CastSphere([F; 3], F, [F; 3], F, Filter),
    Nearest([F; 3], u8, Filter),
    /// A snapshot in JSON (true) or postcard, optionally damaged: a byte xored at a position,
    /// or the bytes cut at a position.
    Snapshot {
        json: bool,
        xor: Option<(u16, u8)>,
        cut: Option<u16>,
    },
    Step,
}

#[derive(Debug)]
pub struct Input {
    /// The region hint, valid or not.
    hint: Option<([F; 3], [F; 3])>,
    /// The octree placement: strict (false) or loose (true).
    loose: bool,
    /// Bits 0–1: the margin (0, 0.25, 0.5, 0.75); bits 2–3: the skin (0, 0, 0.1, 0.5);
    /// bits 4–5: the passes (adaptive, full, incremental, adaptive).
    knobs: u8,
    ops: Vec<Op>,
}

impl Input {
    /// Decodes any bytes: the settings, then operations until the bytes run out (or
    /// [`MAX_OPS`]). Not `Vec::arbitrary`, whose continuation bits stop a random byte string
    /// after two operations on average.
    pub fn decode(bytes: &[u8]) -> Input {
        let mut u = Unstructured::new(bytes);
        let hint = u.arbitrary().unwrap_or(None);
        let loose = u.arbitrary().unwrap_or(false);
        let knobs = u.arbitrary().unwrap_or(0);
        let mut ops = Vec::new();
        while !u.is_empty() && ops.len() < MAX_OPS {
            match Op::arbitrary(&mut u) {
                Ok(op) => ops.push(op),
                Err(_) => break,
            }
        }
        Input {
            hint,
            loose,
            knobs,
            ops,
        }
    }
}

/// Operations per input; longer inputs are cut.
const MAX_OPS: usize = 256;
/// Entries per batch at most.
const MAX_BATCH: usize = 6;

/// A pair as the model lists it: `(smaller key, larger key)`.
type KeyPair = (ProxyKey, ProxyKey);

/// The driver's model of the broadphase: what it was given, nothing read back.
struct Model {
    shapes: HashMap<ProxyKey, Shape>,
    groups: HashMap<ProxyKey, CollisionGroups>,
    /// Insertion serial of every live key (what the predicate filters on).
    serial: HashMap<ProxyKey, u32>,
    next_serial: u32,
    /// Live keys in insertion order (a deterministic order to pick from) and removed keys.
    live: Vec<ProxyKey>,
    dead: Vec<ProxyKey>,
    /// The model's pairs at the last step.
    prev: Vec<KeyPair>,
    margin: f32,
}

impl Model {
    /// Proxy `i` of the live ones, or (one time in eight, if any) a removed key.
    fn pick(&self, i: u8) -> Option<ProxyKey> {
        let i = usize::from(i);
        if i % 8 == 7 && !self.dead.is_empty() {
            return Some(self.dead[i % self.dead.len()]);
        }
        (!self.live.is_empty()).then(|| self.live[i % self.live.len()])
    }

    fn add(&mut self, key: ProxyKey, shape: Shape, groups: CollisionGroups) {
        assert!(
            self.shapes.insert(key, shape).is_none(),
            "a key issued twice"
        );
        self.groups.insert(key, groups);
        self.serial.insert(key, self.next_serial);
        self.next_serial += 1;
        self.live.push(key);
    }

    fn remove(&mut self, key: ProxyKey) {
        self.shapes.remove(&key);
        self.groups.remove(&key);
        self.serial.remove(&key);
        let s = self
            .live
            .iter()
            .position(|&k| k == key)
            .expect("a live key");
        self.live.remove(s);
        self.dead.push(key);
    }

    /// The error the contract gives for a sphere update of `key`, or `None` if it applies.
    fn sphere_refusal(&self, key: ProxyKey, c: Vec3, r: f32) -> Option<Error> {
        if !c.is_finite() {
            return Some(Error::NonFinite {
                what: "center",
                value: c,
            });
        }
        if !r.is_finite() {
            return Some(Error::NonFinite {
                what: "radius",
                value: Vec3::new(r, 0.0, 0.0),
            });
        }
        if r < 0.0 {
            return Some(Error::NegativeRadius(r));
        }
        match self.shapes.get(&key) {
            None => Some(Error::UnknownProxy),
            Some(Shape::Body { .. }) => Some(Error::WrongKind),
            Some(Shape::Sphere { .. }) => None,
        }
    }

    /// The error the contract gives for a body update of `key`, or `None` if it applies.
    fn body_refusal(&self, key: ProxyKey, b: &Aabb) -> Option<Error> {
        if let Some(e) = box_refusal(b) {
            return Some(e);
        }
        match self.shapes.get(&key) {
            None => Some(Error::UnknownProxy),
            Some(Shape::Sphere { .. }) => Some(Error::WrongKind),
            Some(Shape::Body { .. }) => None,
        }
    }

    /// The filter the input describes, over the model's keys and serials.
    fn filter<'a>(
        &self,
        f: &Filter,
        predicate: &'a dyn Fn(ProxyKey, &Shape) -> bool,
    ) -> QueryFilter<'a> {
        let mut q = QueryFilter::new();
        if let Some((m, f)) = f.groups {
            q = q.groups(groups_of(m, f));
        }
        if let Some(k) = f.exclude.and_then(|i| self.pick(i)) {
            q = q.exclude(k);
        }
        if f.predicate.is_some() {
            q = q.predicate(predicate);
        }
        q
    }

    /// True if the model's filter rule passes `key`.
    fn passes(&self, f: &Filter, key: ProxyKey) -> bool {
        let excluded = f.exclude.and_then(|i| self.pick(i)) == Some(key);
        let groups = f
            .groups
            .is_none_or(|(m, fl)| allows(groups_of(m, fl), self.groups[&key]));
        let predicate = f
            .predicate
            .is_none_or(|(m, r)| self.predicate_accepts(m, r, key));
        !excluded && groups && predicate
    }

    fn predicate_accepts(&self, modulus: u8, residue: u8, key: ProxyKey) -> bool {
        let m = 2 + u32::from(modulus % 4);
        self.serial[&key] % m != u32::from(residue) % m
    }

    /// The live keys in key order (so that ties break as the contract says).
    fn sorted_keys(&self) -> Vec<ProxyKey> {
        let mut keys: Vec<ProxyKey> = self.shapes.keys().copied().collect();
        keys.sort_unstable();
        keys
    }
}

fn groups_of(m: u8, f: u8) -> CollisionGroups {
    let mask = |x: u8| {
        if x == 0xff {
            u32::MAX
        } else {
            u32::from(x & 15)
        }
    };
    CollisionGroups {
        memberships: mask(m),
        filter: mask(f),
    }
}

/// bevy_rapier's rule, written out here.
fn allows(a: CollisionGroups, b: CollisionGroups) -> bool {
    a.memberships & b.filter != 0 && b.memberships & a.filter != 0
}

fn box_refusal(b: &Aabb) -> Option<Error> {
    if !b.min.is_finite() {
        return Some(Error::NonFinite {
            what: "aabb.min",
            value: b.min,
        });
    }
    if !b.max.is_finite() {
        return Some(Error::NonFinite {
            what: "aabb.max",
            value: b.max,
        });
    }
    (!b.min.cmple(b.max).all()).then_some(Error::InvertedAabb {
        min: b.min,
        max: b.max,
    })
}

/// Same variant (the fields are the contract's too, but NaN values compare unequal).
fn same_kind(a: &Error, b: &Error) -> bool {
    core::mem::discriminant(a) == core::mem::discriminant(b)
}

fn sphere_ok(c: Vec3, r: f32) -> bool {
    c.is_finite() && r.is_finite() && r >= 0.0
}

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

fn overlap((p0, p1): (Vec3, Vec3), (q0, q1): (Vec3, Vec3)) -> bool {
    p0.x <= q1.x && q0.x <= p1.x && p0.y <= q1.y && q0.y <= p1.y && p0.z <= q1.z && q0.z <= p1.z
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

/// Every pair of overlapping closed pair boxes whose groups allow it, but static × static,
/// by testing all of them; sorted.
fn brute_pairs(shapes: &[(ProxyKey, Shape, CollisionGroups)], margin: f32) -> Vec<KeyPair> {
    let mut out = Vec::new();
    for (i, (k, s, g)) in shapes.iter().enumerate() {
        for (l, t, h) in &shapes[i + 1..] {
            if !(is_static(s) && is_static(t))
                && allows(*g, *h)
                && overlap(pair_box(s, margin), pair_box(t, margin))
            {
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

/// Runs one input: builds the broadphase, applies every operation with its check, and a final
/// step.
pub fn run(input: &Input) {
    let margin = f32::from(input.knobs % 4) * 0.25;
    let skin = [0.0, 0.0, 0.1, 0.5][usize::from(input.knobs >> 2) % 4];
    let passes = [
        Passes::Adaptive,
        Passes::Full,
        Passes::Incremental,
        Passes::Adaptive,
    ][usize::from(input.knobs >> 4) % 4];
    let hint = input.hint.map(|(lo, hi)| Aabb::new(v(lo), v(hi)));
    let hint_ok = hint.is_none_or(|h| h.is_finite() && h.min.cmplt(h.max).all());
    let config = Config {
        bounds: hint,
        margin,
        skin,
        passes,
        octree_placement: if input.loose {
            Placement::Loose
        } else {
            Placement::Strict
        },
        ..Config::default()
    };
    match BroadPhase::try_new(config) {
        Ok(_) => assert!(hint_ok, "a bad region hint accepted"),
        Err(e) => assert!(
            !hint_ok && matches!(e, Error::InvalidBounds { .. }),
            "refused {e:?}"
        ),
    }
    let mut bp = BroadPhase::new(config);
    assert_eq!(bp.config().bounds.is_some(), hint.is_some() && hint_ok);
    let mut m = Model {
        shapes: HashMap::new(),
        groups: HashMap::new(),
        serial: HashMap::new(),
        next_serial: 0,
        live: Vec::new(),
        dead: Vec::new(),
        prev: Vec::new(),
        margin,
    };
    let trace = std::env::var_os("FUZZ_TRACE").is_some();
    for op in &input.ops {
        if trace {
            eprintln!("{op:?}");
        }
        apply(&mut bp, &mut m, op, passes);
        assert_eq!(bp.len(), m.shapes.len());
    }
    step_and_check(&mut bp, &mut m, passes);
    for (key, shape) in &m.shapes {
        assert_eq!(bp.shape(*key), Some(*shape));
        assert_eq!(bp.groups(*key), Some(m.groups[key]));
    }
    for key in &m.dead {
        assert_eq!(bp.shape(*key), None);
    }
}

fn apply(bp: &mut BroadPhase, m: &mut Model, op: &Op, passes: Passes) {
    match op {
        Op::InsertSphere(c, r, g) => {
            let (c, r) = (v(*c), r.get());
            let groups = g.map_or(CollisionGroups::ALL, |(a, b)| groups_of(a, b));
            let len = bp.len();
            let got = match g {
                Some(_) => bp.insert_sphere_with(c, r, groups),
                None => bp.insert_sphere(c, r),
            };
            match got {
                Ok(k) => m.add(
                    k,
                    Shape::Sphere {
                        center: c,
                        radius: r,
                    },
                    groups,
                ),
                Err(e) => {
                    assert!(!sphere_ok(c, r), "refused {e:?}");
                    assert_eq!(bp.len(), len, "a refused insert changed the count");
                }
            }
        }
        Op::InsertBody(lo, hi, is_static, g) => {
            let aabb = Aabb::new(v(*lo), v(*hi));
            let kind = if *is_static {
                BodyKind::Static
            } else {
                BodyKind::Dynamic
            };
            let groups = g.map_or(CollisionGroups::ALL, |(a, b)| groups_of(a, b));
            let got = match g {
                Some(_) => bp.insert_body_with(aabb, kind, groups),
                None => bp.insert_body(aabb, kind),
            };
            match (got, box_refusal(&aabb)) {
                (Ok(k), None) => m.add(k, Shape::Body { aabb, kind }, groups),
                (Err(e), Some(want)) => assert!(same_kind(&e, &want), "{e:?} for {want:?}"),
                (got, want) => panic!("insert_body {aabb:?}: {got:?}, expected {want:?}"),
            }
        }
        Op::UpdateSphere(i, c, r) => {
            let Some(key) = m.pick(*i) else { return };
            let (c, r) = (v(*c), r.get());
            let before = bp.shape(key);
            match (bp.update_sphere(key, c, r), m.sphere_refusal(key, c, r)) {
                (Ok(()), None) => {
                    m.shapes.insert(
                        key,
                        Shape::Sphere {
                            center: c,
                            radius: r,
                        },
                    );
                }
                (Err(e), Some(want)) => {
                    assert!(same_kind(&e, &want), "{e:?} for {want:?}");
                    assert_eq!(bp.shape(key), before, "a refused update changed the shape");
                }
                (got, want) => panic!("update_sphere: {got:?}, expected {want:?}"),
            }
        }
        Op::UpdateBody(i, lo, hi) => {
            let Some(key) = m.pick(*i) else { return };
            let aabb = Aabb::new(v(*lo), v(*hi));
            let before = bp.shape(key);
            match (bp.update_body(key, aabb), m.body_refusal(key, &aabb)) {
                (Ok(()), None) => {
                    let Some(Shape::Body { kind, .. }) = m.shapes.get(&key).copied() else {
                        unreachable!("the model said a live body")
                    };
                    m.shapes.insert(key, Shape::Body { aabb, kind });
                }
                (Err(e), Some(want)) => {
                    assert!(same_kind(&e, &want), "{e:?} for {want:?}");
                    assert_eq!(bp.shape(key), before, "a refused update changed the shape");
                }
                (got, want) => panic!("update_body: {got:?}, expected {want:?}"),
            }
        }
        Op::Remove(i) => {
            let Some(key) = m.pick(*i) else { return };
            if m.shapes.contains_key(&key) {
                bp.remove(key).expect("a live key refused");
                m.remove(key);
            } else {
                assert_eq!(bp.remove(key), Err(Error::UnknownProxy));
            }
        }
        Op::Nudge(i, x, y, z) => {
            if m.live.is_empty() {
                return;
            }
            let key = m.live[usize::from(*i) % m.live.len()];
            let d = Vec3::new(f32::from(x % 4), f32::from(y % 4), f32::from(z % 4)) * 0.25;
            let shape = m.shapes.get_mut(&key).expect("a live key");
            match shape {
                Shape::Sphere { center, radius } => {
                    let c = *center + d;
                    assert_eq!(bp.update_sphere(key, c, *radius).is_ok(), c.is_finite());
                    if c.is_finite() {
                        *center = c;
                    }
                }
                Shape::Body { aabb, .. } => {
                    let moved = Aabb::new(aabb.min + d, aabb.max + d);
                    let ok = box_refusal(&moved).is_none();
                    assert_eq!(bp.update_body(key, moved).is_ok(), ok);
                    if ok {
                        *aabb = moved;
                    }
                }
            }
        }
        Op::SetGroups(i, mem, fil) => {
            let Some(key) = m.pick(*i) else { return };
            let g = groups_of(*mem, *fil);
            if m.shapes.contains_key(&key) {
                bp.set_groups(key, g).expect("a live key refused");
                m.groups.insert(key, g);
                assert_eq!(bp.groups(key), Some(g));
            } else {
                assert_eq!(bp.set_groups(key, g), Err(Error::UnknownProxy));
                assert_eq!(bp.groups(key), None);
            }
        }
        Op::UpdateSpheres(n, entries) => {
            let batch: Vec<(ProxyKey, Vec3, f32)> = entries
                .iter()
                .take(usize::from(*n) % (MAX_BATCH + 1))
                .filter_map(|&(i, c, r)| Some((m.pick(i)?, v(c), r.get())))
                .collect();
            let first_bad = batch
                .iter()
                .enumerate()
                .find_map(|(i, &(k, c, r))| Some((i, m.sphere_refusal(k, c, r)?)));
            let before: Vec<Option<Shape>> = batch.iter().map(|e| bp.shape(e.0)).collect();
            match (bp.update_spheres(&batch), first_bad) {
                (Ok(()), None) => {
                    for &(k, c, r) in &batch {
                        m.shapes.insert(
                            k,
                            Shape::Sphere {
                                center: c,
                                radius: r,
                            },
                        );
                    }
                }
                (Err(BatchError { index, error }), Some((i, want))) => {
                    assert_eq!(index, i, "the first bad entry");
                    assert!(same_kind(&error, &want), "{error:?} for {want:?}");
                    let after: Vec<Option<Shape>> = batch.iter().map(|e| bp.shape(e.0)).collect();
                    assert_eq!(after, before, "a refused batch changed a shape");
                }
                (got, want) => panic!("update_spheres: {got:?}, expected {want:?}"),
            }
        }
        Op::UpdateCenters(n, centers, entries) => update_centers(bp, m, *n, *centers, entries),
        Op::InsertSpheres(n, entries) => {
            let batch: Vec<(Vec3, f32)> = entries
                .iter()
                .take(usize::from(*n) % (MAX_BATCH + 1))
                .map(|&(c, r)| (v(c), r.get()))
                .collect();
            let first_bad = batch.iter().position(|&(c, r)| !sphere_ok(c, r));
            let len = bp.len();
            match (bp.insert_spheres(&batch), first_bad) {
                (Ok(keys), None) => {
                    assert_eq!(keys.len(), batch.len(), "a key per entry");
                    for (&k, &(center, radius)) in keys.iter().zip(&batch) {
                        m.add(k, Shape::Sphere { center, radius }, CollisionGroups::ALL);
                    }
                }
                (Err(BatchError { index, .. }), Some(i)) => {
                    assert_eq!(index, i, "the first bad entry");
                    assert_eq!(bp.len(), len, "a refused batch inserted");
                }
                (got, want) => {
                    panic!("insert_spheres: {got:?}, expected the first bad at {want:?}")
                }
            }
        }
        Op::UpdateBodies(n, entries) => {
            let batch: Vec<(ProxyKey, Aabb)> = entries
                .iter()
                .take(usize::from(*n) % (MAX_BATCH + 1))
                .filter_map(|&(i, lo, hi)| Some((m.pick(i)?, Aabb::new(v(lo), v(hi)))))
                .collect();
            let first_bad = batch
                .iter()
                .enumerate()
                .find_map(|(i, (k, b))| Some((i, m.body_refusal(*k, b)?)));
            let before: Vec<Option<Shape>> = batch.iter().map(|e| bp.shape(e.0)).collect();
            match (bp.update_bodies(&batch), first_bad) {
                (Ok(()), None) => {
                    for &(k, aabb) in &batch {
                        let Some(Shape::Body { kind, .. }) = m.shapes.get(&k).copied() else {
                            unreachable!("the model said a live body")
                        };
                        m.shapes.insert(k, Shape::Body { aabb, kind });
                    }
                }
                (Err(BatchError { index, error }), Some((i, want))) => {
                    assert_eq!(index, i, "the first bad entry");
                    assert!(same_kind(&error, &want), "{error:?} for {want:?}");
                    let after: Vec<Option<Shape>> = batch.iter().map(|e| bp.shape(e.0)).collect();
                    assert_eq!(after, before, "a refused batch changed a shape");
                }
                (got, want) => panic!("update_bodies: {got:?}, expected {want:?}"),
            }
        }
        Op::QueryAabb(lo, hi, f, stop) => {
            let q = Aabb::new(v(*lo), v(*hi));
            let valid = box_refusal(&q).is_none();
            let qb = (q.min, q.max);
            let hit = |s: &Shape| valid && overlap(pair_box(s, m.margin), qb);
            check_visits(m, f, *stop, &hit, |filter, visit| {
                bp.query_aabb_with(&q, filter, visit)
            });
            let mut plain = Vec::new();
            bp.query_aabb(&q, |k| plain.push(k));
            check_plain(m, plain, &hit);
        }
        Op::QuerySphere(c, r, f, stop) => {
            let (x, r) = (v(*c), r.get());
            let valid = sphere_ok(x, r);
            let hit = |s: &Shape| {
                valid
                    && match *s {
                        Shape::Sphere { center, radius } => {
                            // In f64: the f32 squares overflow for far centres.
                            let d = center.as_dvec3() - x.as_dvec3();
                            let reach = f64::from(radius) + f64::from(r);
                            d.dot(d) <= reach * reach
                        }
                        Shape::Body { aabb, .. } => point_aabb_distance(x, &aabb) <= r,
                    }
            };
            check_visits(m, f, *stop, &hit, |filter, visit| {
                bp.query_sphere_with(x, r, filter, visit)
            });
            let mut plain = Vec::new();
            bp.query_sphere(x, r, |k| plain.push(k));
            check_plain(m, plain, &hit);
        }
        Op::CastRay(o, d, max_t, f) => {
            let (o, d, max_t) = (v(*o), v(*d), max_t.get());
            let valid = o.is_finite() && d.is_finite() && max_t >= 0.0;
            let inv = inverse_dir(d);
            let t_of = |s: &Shape| match *s {
                Shape::Sphere { center, radius } => ray_sphere(o, d, center, radius, max_t),
                Shape::Body { aabb, .. } => aabb.ray_entry(o, inv, max_t),
            };
            let pred = predicate(m, f);
            let filter = m.filter(f, &pred);
            let want = valid.then(|| first_hit(m, Some(f), &t_of)).flatten();
            assert_eq!(
                bp.cast_ray_with(o, d, max_t, &filter),
                want,
                "cast_ray_with"
            );
            let want = valid.then(|| first_hit(m, None, &t_of)).flatten();
            assert_eq!(bp.cast_ray(o, d, max_t), want, "cast_ray");
        }
        Op::CastSphere(c, r, d, max_t, f) => {
            let (c, r, d, max_t) = (v(*c), r.get(), v(*d), max_t.get());
            let valid = sphere_ok(c, r) && d.is_finite() && max_t.is_finite() && max_t >= 0.0;
            let t_of = |s: &Shape| match *s {
                Shape::Sphere { center, radius } => {
                    sphere_cast_sphere(c, r, d, max_t, center, radius)
                }
                Shape::Body { aabb, .. } => sphere_cast_aabb(c, r, d, max_t, &aabb),
            };
            let pred = predicate(m, f);
            let filter = m.filter(f, &pred);
            let want = valid.then(|| first_hit(m, Some(f), &t_of)).flatten();
            assert_eq!(
                bp.cast_sphere_with(c, r, d, max_t, &filter),
                want,
                "cast_sphere_with"
            );
            let want = valid.then(|| first_hit(m, None, &t_of)).flatten();
            assert_eq!(bp.cast_sphere(c, r, d, max_t), want, "cast_sphere");
        }
        Op::Nearest(p, k, f) => {
            let (p, k) = (v(*p), usize::from(*k % 16));
            let dist = |s: &Shape| match *s {
                Shape::Sphere { center, radius } => point_sphere_distance(p, center, radius),
                Shape::Body { aabb, .. } => point_aabb_distance(p, &aabb),
            };
            let nearest = |filter: Option<&Filter>| -> Vec<(ProxyKey, f32)> {
                if !p.is_finite() {
                    return Vec::new();
                }
                let mut all: Vec<(ProxyKey, f32)> = m
                    .sorted_keys()
                    .into_iter()
                    .filter(|&key| filter.is_none_or(|f| m.passes(f, key)))
                    .map(|key| (key, dist(&m.shapes[&key])))
                    .collect();
                all.sort_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
                all.truncate(k);
                all
            };
            let pred = predicate(m, f);
            let filter = m.filter(f, &pred);
            // A buffer holding stale entries: `nearest_into` clears it first.
            let mut out = vec![(ProxyKey::default(), -1.0); 3];
            bp.nearest_into(p, k, &filter, &mut out);
            assert_eq!(out, nearest(Some(f)), "nearest_into {k}");
            assert_eq!(bp.nearest(p, k), nearest(None), "nearest {k}");
        }
        Op::Snapshot { json, xor, cut } => snapshot(bp, m, *json, *xor, *cut),
        Op::Step => step_and_check(bp, m, passes),
    }
}

/// [`Op::UpdateCenters`]: the batch refused whole when the slices' lengths differ (at the
/// first index only one has) or at its first bad entry by the driver's own rule (a
/// non-finite centre, then a stale key, then a body's key); else every named sphere moved,
/// keeping its radius.
fn update_centers(
    bp: &mut BroadPhase,
    m: &mut Model,
    n: u8,
    centers: u8,
    entries: &[(u8, [F; 3]); MAX_BATCH],
) {
    let n = usize::from(n) % (MAX_BATCH + 1);
    let count = if centers % 4 == 0 {
        usize::from(centers / 4) % (MAX_BATCH + 1)
    } else {
        n
    };
    let keys: Vec<ProxyKey> = entries[..n].iter().filter_map(|e| m.pick(e.0)).collect();
    let cs: Vec<Vec3> = entries[..count].iter().map(|e| v(e.1)).collect();
    let first_bad = if keys.len() == cs.len() {
        keys.iter()
            .zip(&cs)
            .enumerate()
            .find_map(|(i, (&k, &c))| Some((i, m.sphere_refusal(k, c, 0.0)?)))
    } else {
        let (keys, values) = (keys.len(), cs.len());
        Some((keys.min(values), Error::LengthMismatch { keys, values }))
    };
    let before: Vec<Option<Shape>> = keys.iter().map(|&k| bp.shape(k)).collect();
    match (bp.update_centers(&keys, &cs), first_bad) {
        (Ok(()), None) => {
            for (k, &c) in keys.iter().zip(&cs) {
                let Some(Shape::Sphere { center, .. }) = m.shapes.get_mut(k) else {
                    unreachable!("the model said a live sphere")
                };
                *center = c;
            }
        }
        (Err(BatchError { index, error }), Some((i, want))) => {
            assert_eq!(index, i, "the first bad entry");
            assert!(same_kind(&error, &want), "{error:?} for {want:?}");
            if let Error::LengthMismatch { .. } = want {
                assert_eq!(error, want, "the lengths named");
            }
            let after: Vec<Option<Shape>> = keys.iter().map(|&k| bp.shape(k)).collect();
            assert_eq!(after, before, "a refused batch changed a shape");
        }
        (got, want) => panic!("update_centers: {got:?}, expected {want:?}"),
    }
}

/// The predicate the input describes: rejects by the model's serials, and checks it is shown
/// the model's shape of a live proxy.
fn predicate<'a>(m: &'a Model, f: &Filter) -> impl Fn(ProxyKey, &Shape) -> bool + 'a {
    let (modulus, residue) = f.predicate.unwrap_or((0, 0));
    move |key: ProxyKey, shape: &Shape| {
        assert_eq!(m.shapes.get(&key), Some(shape), "the predicate's shape");
        m.predicate_accepts(modulus, residue, key)
    }
}

/// The smallest `(t, key)` of `t_of` over the model's shapes that `filter` passes, as
/// `(key, t)`.
fn first_hit(
    m: &Model,
    filter: Option<&Filter>,
    t_of: &dyn Fn(&Shape) -> Option<f32>,
) -> Option<(ProxyKey, f32)> {
    m.sorted_keys()
        .into_iter()
        .filter(|&key| filter.is_none_or(|f| m.passes(f, key)))
        .filter_map(|key| Some((t_of(&m.shapes[&key])?, key)))
        .min_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)))
        .map(|(t, k)| (k, t))
}

/// Runs a filtered visiting query through `query` and checks it against the model's
/// matches (`hit`, then the filter): without `stop`, every match once and `Continue`; with
/// `stop = n`, the visitor breaks at its `n + 1`-th call, so it sees `min(n + 1, matches)`
/// distinct matches and `Break` comes back iff there were more than `n`.
fn check_visits(
    m: &Model,
    f: &Filter,
    stop: Option<u8>,
    hit: &dyn Fn(&Shape) -> bool,
    query: impl FnOnce(&QueryFilter<'_>, &mut dyn FnMut(ProxyKey) -> ControlFlow<()>) -> ControlFlow<()>,
) {
    let want: BTreeSet<ProxyKey> = m
        .sorted_keys()
        .into_iter()
        .filter(|k| hit(&m.shapes[k]) && m.passes(f, *k))
        .collect();
    let pred = predicate(m, f);
    let filter = m.filter(f, &pred);
    let mut seen = Vec::new();
    let flow = query(&filter, &mut |k| {
        seen.push(k);
        match stop {
            Some(n) if seen.len() > usize::from(n) => ControlFlow::Break(()),
            _ => ControlFlow::Continue(()),
        }
    });
    let distinct: BTreeSet<ProxyKey> = seen.iter().copied().collect();
    assert_eq!(distinct.len(), seen.len(), "a proxy visited twice");
    match stop {
        Some(n) if want.len() > usize::from(n) => {
            assert!(flow.is_break(), "the visitor's Break was not returned");
            assert_eq!(seen.len(), usize::from(n) + 1, "visits after a Break");
            assert!(distinct.is_subset(&want), "a visit outside the matches");
        }
        _ => {
            assert!(flow.is_continue());
            assert_eq!(distinct, want, "the filtered matches");
        }
    }
}

/// A plain query's visits equal the model's unfiltered matches, each once.
fn check_plain(m: &Model, mut got: Vec<ProxyKey>, hit: &dyn Fn(&Shape) -> bool) {
    got.sort_unstable();
    let want: Vec<ProxyKey> = m
        .sorted_keys()
        .into_iter()
        .filter(|k| hit(&m.shapes[k]))
        .collect();
    assert_eq!(got, want, "the plain query's matches");
}

/// Steps and checks pairs, events, the pass and the invariants against the model.
fn step_and_check(bp: &mut BroadPhase, m: &mut Model, passes: Passes) {
    let all: Vec<(ProxyKey, Shape, CollisionGroups)> = m
        .shapes
        .iter()
        .map(|(k, s)| (*k, *s, m.groups[k]))
        .collect();
    let expected = brute_pairs(&all, m.margin);
    let (now, before): (BTreeSet<KeyPair>, BTreeSet<KeyPair>) = (
        expected.iter().copied().collect(),
        m.prev.iter().copied().collect(),
    );
    let added: Vec<KeyPair> = now.difference(&before).copied().collect();
    let removed: Vec<KeyPair> = before.difference(&now).copied().collect();
    bp.step();
    assert_eq!(as_key_pairs(bp.pairs()), expected, "pairs");
    assert_eq!(as_key_pairs(bp.added()), added, "added");
    assert_eq!(as_key_pairs(bp.removed()), removed, "removed");
    let pass = bp.stats().pass;
    match passes {
        Passes::Full => assert!(matches!(pass, Pass::Full | Pass::Unchanged), "{pass:?}"),
        Passes::Incremental => assert!(pass != Pass::Full, "{pass:?}"),
        Passes::Adaptive => {}
    }
    bp.validate();
    for key in &m.live {
        assert!(bp.contains(*key), "a live key not contained");
    }
    for key in &m.dead {
        assert!(!bp.contains(*key), "a removed key contained");
    }
    assert!(!bp.contains(ProxyKey::default()), "the null key contained");
    m.prev = expected;
}

/// Saves `bp` in JSON or postcard. Undamaged, the snapshot must restore to a broadphase that
/// passes `validate()` and holds the model's shapes and groups; the driver carries on with it.
/// Damaged, it must give `Err` or a broadphase that passes `validate()` and pairs its own
/// shapes as the O(n²) loop does.
fn snapshot(bp: &mut BroadPhase, m: &Model, json: bool, xor: Option<(u16, u8)>, cut: Option<u16>) {
    let mut bytes = if json {
        serde_json::to_vec(&*bp).expect("a broadphase serialises")
    } else {
        postcard::to_allocvec(&*bp).expect("a broadphase serialises")
    };
    let load = |b: &[u8]| -> Option<BroadPhase> {
        if json {
            serde_json::from_slice(b).ok()
        } else {
            postcard::from_bytes(b).ok()
        }
    };
    let mut damaged = false;
    if let Some((at, x)) = xor.filter(|&(_, x)| x != 0) {
        let i = usize::from(at) % bytes.len();
        bytes[i] ^= x;
        damaged = true;
    }
    if let Some(at) = cut {
        let n = usize::from(at) % bytes.len();
        bytes.truncate(n);
        damaged = true;
    }
    if !damaged {
        let restored = load(&bytes).expect("a broadphase's own snapshot restores");
        restored.validate();
        assert_eq!(restored.len(), m.shapes.len());
        for (key, shape) in &m.shapes {
            assert_eq!(restored.shape(*key), Some(*shape));
            assert_eq!(restored.groups(*key), Some(m.groups[key]));
        }
        for key in &m.dead {
            assert_eq!(restored.shape(*key), None, "a removed key came back");
        }
        *bp = restored;
        return;
    }
    let Some(mut copy) = load(&bytes) else { return };
    copy.validate();
    let all: Vec<(ProxyKey, Shape, CollisionGroups)> = copy
        .iter()
        .map(|(k, s)| (k, s, copy.groups(k).expect("a listed key is live")))
        .collect();
    let margin = copy.config().margin;
    copy.step();
    copy.validate();
    assert_eq!(
        as_key_pairs(copy.pairs()),
        brute_pairs(&all, margin),
        "a restored snapshot's pairs"
    );
}
