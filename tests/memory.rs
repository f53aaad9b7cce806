//! Each structure pays only for what it holds (`heap_bytes`): a world of bodies (reserved for
//! as bodies, stepped) leaves the octree as small as an empty broadphase's, and a world of
//! spheres leaves both BVHs so; the broadphase counts its octree's bytes in its own. The pair
//! lists themselves are checked against brute force by `tests/oracle.rs`; this file only
//! checks who holds the bytes.

use broadleaf::{Aabb, BodyKind, BroadPhase, Config, Passes, Vec3};

/// A point of an `n`-wide grid with spacing `step`, slot `i`.
fn grid(i: usize, n: usize, step: f32) -> Vec3 {
    let (x, y, z) = (i % n, (i / n) % n, i / (n * n));
    Vec3::new(x as f32, y as f32, z as f32) * step
}

#[test]
fn bodies_pay_nothing_in_the_octree() {
    let empty = BroadPhase::new(Config::default());
    let mut bp = BroadPhase::new(Config::default());
    bp.reserve(0, 3000);
    for i in 0..3000 {
        let c = grid(i, 15, 1.5);
        let kind = if i % 3 == 0 {
            BodyKind::Static
        } else {
            BodyKind::Dynamic
        };
        bp.insert_body(Aabb::new(c, c + Vec3::splat(2.0)), kind)
            .unwrap();
    }
    for _ in 0..3 {
        bp.step();
    }
    assert!(!bp.pairs().is_empty());
    assert_eq!(bp.octree().heap_bytes(), empty.octree().heap_bytes());
    assert!(bp.bvh(BodyKind::Dynamic).heap_bytes() > empty.bvh(BodyKind::Dynamic).heap_bytes());
}

#[test]
fn spheres_pay_nothing_in_the_bvhs() {
    let empty = BroadPhase::new(Config::default());
    let mut bp = BroadPhase::new(Config::default());
    bp.reserve(3000, 0);
    let keys: Vec<_> = (0..3000)
        .map(|i| bp.insert_sphere(grid(i, 15, 1.5), 0.8).unwrap())
        .collect();
    for step in 0..3 {
        for (i, &k) in keys.iter().enumerate() {
            let c = grid(i, 15, 1.5) + Vec3::splat(0.01 * step as f32);
            bp.update_sphere(k, c, 0.8).unwrap();
        }
        bp.step();
    }
    assert!(!bp.pairs().is_empty());
    for kind in [BodyKind::Dynamic, BodyKind::Static] {
        assert_eq!(bp.bvh(kind).heap_bytes(), empty.bvh(kind).heap_bytes());
    }
    assert!(bp.octree().heap_bytes() > empty.octree().heap_bytes());
    // The broadphase counts its octree's bytes in its own, beside its slots and pair lists.
    assert!(bp.heap_bytes() > bp.octree().heap_bytes());
}

/// The first step adds every pair at once; once the world settles, the event lists give that
/// room back instead of keeping the first step's peak. The full pass is forced: a world this
/// slow would otherwise enter the incremental regime, whose candidate lists take room of
/// their own.
#[test]
fn event_lists_give_back_the_first_steps_peak() {
    let mut bp = BroadPhase::new(Config {
        passes: Passes::Full,
        ..Config::default()
    });
    let keys: Vec<_> = (0..3000)
        .map(|i| bp.insert_sphere(grid(i, 15, 1.5), 0.8).unwrap())
        .collect();
    bp.step();
    let first = bp.added().len();
    assert_eq!(first, bp.pairs().len());
    let peak = bp.heap_bytes();
    for step in 1..4 {
        for (i, &k) in keys.iter().enumerate() {
            let c = grid(i, 15, 1.5) + Vec3::splat(0.001 * step as f32);
            bp.update_sphere(k, c, 0.8).unwrap();
        }
        bp.step();
        assert!(bp.added().is_empty() && bp.removed().is_empty());
    }
    // `added` (16 bytes a pair) alone held the first step's pairs; it keeps at most an
    // eighth of the proxies' worth of room.
    let kept = 3000 / 8;
    assert!(first > 4 * kept, "the world has too few pairs to tell");
    assert!(
        bp.heap_bytes() + (first - kept) * 16 <= peak,
        "{} bytes after settling, {peak} at the first step's peak of {first} pairs",
        bp.heap_bytes()
    );
}
