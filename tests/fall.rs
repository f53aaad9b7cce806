//! The `fall` scene's pairs equal an exact count: a small drop recorded from rapier
//! (`fixtures::rapier_world::record_fall`) and replayed through `BroadPhase::update_centers`
//! (the changed balls only, and every ball every frame), with the walls as static bodies, has
//! at every frame exactly the pairs of an O(n²) loop over the recorded centres and the walls.
#![cfg(feature = "rapier")]

use broadleaf::fixtures::rapier_world::{FallRecording, record_fall};
use broadleaf::fixtures::sim::DropConfig;
use broadleaf::{Aabb, BodyKind, BroadPhase, Config, Pair, ProxyKey, Vec3};

/// Balls of the small drop and the frames recorded: the balls fall, land and settle in it.
const BALLS: usize = 300;
const FRAMES: usize = 150;

fn recording() -> FallRecording {
    record_fall(&DropConfig::new(BALLS, 0.5, 7), FRAMES).expect("the drop's settings are valid")
}

/// Every pair of boxes that overlap (touching counts), static × static left out, sorted.
fn exact(boxes: &[(ProxyKey, Aabb, bool)]) -> Vec<Pair> {
    let mut out = Vec::new();
    for (i, &(a, ba, sa)) in boxes.iter().enumerate() {
        for &(b, bb, sb) in &boxes[i + 1..] {
            if !(sa && sb) && ba.overlaps(&bb) {
                out.push(Pair::new(a, b));
            }
        }
    }
    out.sort_unstable();
    out
}

/// Replays `rec` from its frames and asserts the pairs at every frame; `every` sends all balls
/// each frame instead of the changed ones. Returns the pair count of each frame.
fn replay_matches_exact(rec: &FallRecording, every: bool) -> Vec<usize> {
    let mut bp = BroadPhase::new(Config::default());
    let margin = bp.config().margin;
    let walls: Vec<ProxyKey> = rec
        .walls
        .iter()
        .map(|&w| bp.insert_body(w, BodyKind::Static).expect("finite wall"))
        .collect();
    let (ids, starts) = rec.changed(0);
    assert_eq!(ids.len(), rec.balls(), "frame 0 lists every ball");
    let balls: Vec<ProxyKey> = starts
        .iter()
        .map(|&c| bp.insert_sphere(c, rec.radius).expect("finite ball"))
        .collect();
    let mut centers = starts.to_vec();
    let (mut keys, mut batch) = (Vec::new(), Vec::new());
    let mut counts = Vec::new();
    for k in 0..rec.frames() {
        let (ids, moved) = rec.changed(k);
        for (&i, &c) in ids.iter().zip(moved) {
            centers[i as usize] = c;
        }
        keys.clear();
        batch.clear();
        if every {
            keys.extend_from_slice(&balls);
            batch.extend_from_slice(&centers);
        } else {
            keys.extend(ids.iter().map(|&i| balls[i as usize]));
            batch.extend_from_slice(moved);
        }
        bp.update_centers(&keys, &batch).expect("a valid batch");
        bp.step();
        bp.validate();
        let grow = |b: Aabb| Aabb::new(b.min - Vec3::splat(margin), b.max + Vec3::splat(margin));
        let boxes: Vec<(ProxyKey, Aabb, bool)> = balls
            .iter()
            .zip(&centers)
            .map(|(&key, &c)| (key, Aabb::from_center_radius(c, rec.radius + margin), false))
            .chain(
                walls
                    .iter()
                    .zip(&rec.walls)
                    .map(|(&key, &w)| (key, grow(w), true)),
            )
            .collect();
        assert_eq!(
            bp.pairs(),
            exact(&boxes).as_slice(),
            "frame {k}, every {every}"
        );
        counts.push(bp.pairs().len());
    }
    counts
}

#[test]
fn fall_pairs_equal_an_exact_count_at_every_frame() {
    let rec = recording();
    assert_eq!(rec.frames(), FRAMES);
    assert_eq!(rec.balls(), BALLS);
    let changed = replay_matches_exact(&rec, false);
    let every = replay_matches_exact(&rec, true);
    assert_eq!(changed, every);
    // The drop is a real one: the balls meet the floor and each other.
    assert!(changed.iter().any(|&c| c > BALLS), "{changed:?}");
}

#[test]
fn fall_lists_the_moved_balls_and_finds_the_falling_phase() {
    let rec = recording();
    let mut centers = rec.changed(0).1.to_vec();
    for k in 1..rec.frames() {
        let (ids, moved) = rec.changed(k);
        assert!(
            ids.windows(2).all(|w| w[0] < w[1]),
            "frame {k}: ids increase"
        );
        for (&i, &c) in ids.iter().zip(moved) {
            assert_ne!(
                centers[i as usize], c,
                "frame {k}: ball {i} is listed unmoved"
            );
            centers[i as usize] = c;
        }
    }
    // Every ball falls from the start.
    assert_eq!(rec.changed(1).0.len(), BALLS);
    let phases = rec.phases();
    assert!(
        phases.settling > 0 && phases.settling < rec.frames(),
        "{phases:?}"
    );
    assert!(
        rec.mean_speed[..phases.settling]
            .iter()
            .any(|&v| v > 2.0 * broadleaf::fixtures::rapier_world::FALLING_END_SPEED),
        "{:?}",
        rec.mean_speed
    );
}
