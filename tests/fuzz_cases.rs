//! Cases the fuzz target's logic found, replayed against the tests' own model: after every step
//! the pairs and events equal the model's, whatever the magnitudes (boxes reaching `3e38`, fat
//! boxes that overflow to infinity), and nothing panics. Both run the incremental pass, where
//! the cases were found.

mod common;

use broadleaf::{Aabb, BroadPhase, Config, Pass, Passes, Vec3};
use common::{Model, ModelShape};

fn body(min: [f32; 3], max: [f32; 3], is_static: bool) -> ModelShape {
    ModelShape::Body {
        aabb: Aabb::new(Vec3::from_array(min), Vec3::from_array(max)),
        is_static,
    }
}

fn sphere(center: [f32; 3], radius: f32) -> ModelShape {
    ModelShape::Sphere {
        center: Vec3::from_array(center),
        radius,
    }
}

/// A sphere of radius `3e38` has a box (and a fat box) reaching infinity; its query must not
/// meet the removed entries of the BVHs (tombstones until the next rebuild), whose box is the
/// empty box `+∞..−∞` that an infinite box would otherwise "overlap".
#[test]
fn an_infinite_box_meets_no_removed_entry() {
    let margin = 0.25;
    let mut bp = BroadPhase::new(Config {
        margin,
        passes: Passes::Incremental,
        ..Config::default()
    });
    let mut model = Model::new(margin);
    let mut keys = Vec::new();
    for i in 0..8 {
        let x = i as f32 * 1.5;
        keys.push(model.insert(
            &mut bp,
            body([x, -1.0, 0.0], [x + 2.0, 1.0, 1.0], i % 3 == 0),
        ));
    }
    model.check_step(&mut bp, "built");
    model.remove(&mut bp, keys[2]);
    model.remove(&mut bp, keys[5]);
    model.insert(&mut bp, sphere([-1.5, -0.75, -1.0], 3e38));
    model.check_step(&mut bp, "huge sphere inserted next to removed entries");
    model.check_step(&mut bp, "one more step");
}

/// Two bodies touching exactly at `y = 3e38` after growth by the margin (one reaching up to it,
/// one flat there) pair when the flat one leaves its fat box and queries the structures with
/// its new one: no rounding of the grown boxes near `f32::MAX` may lose the touch.
#[test]
fn boxes_touching_at_3e38_pair_incrementally() {
    let margin = 0.75;
    let mut bp = BroadPhase::new(Config {
        margin,
        skin: 0.5,
        passes: Passes::Incremental,
        ..Config::default()
    });
    let mut model = Model::new(margin);
    model.insert(&mut bp, body([7.5, 1.5, 5.25], [13.5, 3e38, 6.5], false));
    model.insert(&mut bp, sphere([-5.5, 6.0, -1.0], 7.0));
    let flat = model.insert(&mut bp, body([-4.0, 3e38, -1.75], [-1.0, 3e38, 2.0], true));
    model.insert(&mut bp, body([0.5, -0.75, -2.5], [7.5, 3e38, 2.0], false));
    model.insert(&mut bp, sphere([2.25, -6.0, -0.75], 4.75));
    model.check_step(&mut bp, "built");
    let moved = body([-4.25, 3e38, -2.5], [-1.25, 3e38, 1.25], true);
    model.update(&mut bp, flat, moved);
    model.check_step(&mut bp, "the flat body moved out of its fat box");
    let stats = bp.stats();
    assert_eq!(
        stats.pass,
        Pass::Incremental,
        "the move ran {:?}",
        stats.pass
    );
    assert_eq!(stats.escaped, 1, "the flat body's escape was not counted");
}
