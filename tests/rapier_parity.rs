//! broadleaf against rapier3d's broad phase in a real rapier simulation: at every step
//! `exact ⊆ ours ⊆ rapier` and `ours == exact`, with the mirror synced right before each
//! `PhysicsPipeline::step` (the poses rapier detects collisions at); with collision groups
//! copied from the colliders, `exact` applies the groups rule.
#![cfg(feature = "rapier")]

use broadleaf::fixtures::scene::Rng;
use broadleaf::pair::{self, Pair};
use broadleaf::rapier::{Comparison, Mirror};
use broadleaf::{Aabb, Config, Passes, Vec3, brute};
use rapier3d::prelude::*;
use std::collections::BTreeSet;

/// A rapier world and everything `PhysicsPipeline::step` needs.
struct World {
    pipeline: PhysicsPipeline,
    params: IntegrationParameters,
    islands: IslandManager,
    broad_phase: DefaultBroadPhase,
    narrow_phase: NarrowPhase,
    bodies: RigidBodySet,
    colliders: ColliderSet,
    impulse_joints: ImpulseJointSet,
    multibody_joints: MultibodyJointSet,
    soft_bodies: SoftBodySet,
    ccd: CCDSolver,
    gravity: Vector,
}

impl World {
    fn new(gravity: Vector) -> Self {
        World {
            pipeline: PhysicsPipeline::new(),
            params: IntegrationParameters::default(),
            islands: IslandManager::new(),
            broad_phase: DefaultBroadPhase::new(),
            narrow_phase: NarrowPhase::new(),
            bodies: RigidBodySet::new(),
            colliders: ColliderSet::new(),
            impulse_joints: ImpulseJointSet::new(),
            multibody_joints: MultibodyJointSet::new(),
            soft_bodies: SoftBodySet::new(),
            ccd: CCDSolver::new(),
            gravity,
        }
    }

    fn add(&mut self, body: RigidBodyBuilder, collider: ColliderBuilder) -> RigidBodyHandle {
        let h = self.bodies.insert(body);
        let co = collider.active_collision_types(ActiveCollisionTypes::all());
        self.colliders.insert_with_parent(co, h, &mut self.bodies);
        h
    }

    fn remove(&mut self, h: RigidBodyHandle) {
        self.bodies.remove(
            h,
            &mut self.islands,
            &mut self.colliders,
            &mut self.impulse_joints,
            &mut self.multibody_joints,
            &mut self.soft_bodies,
            true,
        );
    }

    fn step(&mut self) {
        self.pipeline.step(
            self.gravity,
            &self.params,
            &mut self.islands,
            &mut self.broad_phase,
            &mut self.narrow_phase,
            &mut self.bodies,
            &mut self.colliders,
            &mut self.impulse_joints,
            &mut self.multibody_joints,
            &mut self.soft_bodies,
            &mut self.ccd,
            &(),
            &(),
        );
    }
}

/// The failing step's details: every differing pair with its two colliders' boxes.
fn explain(step: usize, cmp: &Comparison, mirror: &mut Mirror, world: &World) -> String {
    let mut rapier = Vec::new();
    mirror.rapier_pairs(&world.narrow_phase, &mut rapier);
    let exact = mirror.exact_pairs();
    mirror.step();
    let ours = mirror.broadphase().pairs().to_vec();
    let (mut a, mut b) = (Vec::new(), Vec::new());
    let mut out = format!("step {step}: {cmp}\n");
    let mut list = |what: &str, pairs: &[Pair]| {
        for p in pairs.iter().take(10) {
            let boxes = [p.a, p.b].map(|k| (mirror.handle(k), mirror.broadphase().shape(k)));
            out += &format!("  {what}: {p:?} {boxes:?}\n");
        }
    };
    pair::diff(&rapier, &ours, &mut a, &mut b);
    list("ours, not rapier's (extra)", &a);
    pair::diff(&ours, &exact, &mut a, &mut b);
    list("exact, not ours", &a);
    list("ours, not exact", &b);
    pair::diff(&rapier, &exact, &mut a, &mut b);
    list("exact, not rapier's", &a);
    out
}

/// Builds the falling scene: a 16 m × 16 m box of fixed walls and floor, 2016 balls in a
/// jittered grid above it and 64 rotated dynamic cuboids between the layers.
fn falling_scene(rng: &mut Rng) -> (World, Vec<RigidBodyHandle>) {
    let mut w = World::new(Vector::new(0.0, -9.81, 0.0));
    let half = 8.0;
    let wall = |w: &mut World, c: Vec3, h: Vec3| {
        w.add(
            RigidBodyBuilder::fixed().translation(c),
            ColliderBuilder::cuboid(h.x, h.y, h.z),
        );
    };
    wall(
        &mut w,
        Vec3::new(0.0, -0.5, 0.0),
        Vec3::new(half + 1.0, 0.5, half + 1.0),
    );
    for s in [-1.0f32, 1.0] {
        wall(
            &mut w,
            Vec3::new(s * (half + 0.5), 12.0, 0.0),
            Vec3::new(0.5, 12.0, half + 1.0),
        );
        wall(
            &mut w,
            Vec3::new(0.0, 12.0, s * (half + 0.5)),
            Vec3::new(half + 1.0, 12.0, 0.5),
        );
    }
    let mut balls = Vec::new();
    for layer in 0..14 {
        for i in 0..12 {
            for j in 0..12 {
                let jitter = rng.vec3_in(Vec3::splat(-0.04), Vec3::splat(0.04));
                let c = Vec3::new(
                    -6.05 + 1.1 * i as f32,
                    1.0 + 1.25 * layer as f32,
                    -6.05 + 1.1 * j as f32,
                ) + jitter;
                balls.push(w.add(
                    RigidBodyBuilder::dynamic().translation(c),
                    ColliderBuilder::ball(0.5),
                ));
            }
        }
    }
    for _ in 0..64 {
        let c = rng.vec3_in(Vec3::new(-6.0, 20.0, -6.0), Vec3::new(6.0, 26.0, 6.0));
        let h = rng.vec3_in(Vec3::splat(0.2), Vec3::splat(0.8));
        let pose = Pose::from_parts(c, rng.rotation());
        w.add(
            RigidBodyBuilder::dynamic().pose(pose),
            ColliderBuilder::cuboid(h.x, h.y, h.z),
        );
    }
    (w, balls)
}

#[test]
fn falling_balls_and_boxes_match_rapier_at_every_step() {
    const STEPS: usize = 300;
    let mut rng = Rng::new(2024);
    let (mut world, mut balls) = falling_scene(&mut rng);
    assert!(balls.len() >= 2000);
    let mut mirror = Mirror::new(Config {
        bounds: Some(Aabb::new(
            Vec3::new(-10.0, -2.0, -10.0),
            Vec3::new(10.0, 30.0, 10.0),
        )),
        ..Config::default()
    });
    // A second mirror synced after the step (one step late), to show what that timing gives.
    let mut late = Mirror::new(*mirror.broadphase().config());
    // A third forced to the incremental pass (fat boxes of a fixed skin): the same contract
    // at every step.
    let mut incremental = Mirror::new(Config {
        skin: 0.05,
        passes: Passes::Incremental,
        ..*mirror.broadphase().config()
    });
    let (mut late_failures, mut max_pairs, mut max_rapier) = (0, 0, 0);
    for step in 0..STEPS {
        // Churn: remove 40 balls and drop 40 new ones in, so rapier reuses collider slots.
        if step % 50 == 25 {
            for _ in 0..40 {
                let i = rng.below(balls.len() as u32) as usize;
                world.remove(balls.swap_remove(i));
            }
            for _ in 0..40 {
                let c = rng.vec3_in(Vec3::new(-7.0, 18.0, -7.0), Vec3::new(7.0, 22.0, 7.0));
                balls.push(world.add(
                    RigidBodyBuilder::dynamic().translation(c),
                    ColliderBuilder::ball(0.5),
                ));
            }
        }
        let report = mirror.sync(&world.bodies, &world.colliders);
        assert_eq!(report.skipped, 0, "step {step}: {report:?}");
        incremental.sync(&world.bodies, &world.colliders);
        world.step();
        let cmp = mirror.compare(&world.narrow_phase);
        if !cmp.holds() {
            panic!("{}", explain(step, &cmp, &mut mirror, &world));
        }
        assert_eq!(mirror.len(), world.colliders.len());
        max_pairs = max_pairs.max(cmp.ours);
        max_rapier = max_rapier.max(cmp.rapier);

        let c = incremental.compare(&world.narrow_phase);
        if !c.holds() {
            panic!("skin 0.05: {}", explain(step, &c, &mut incremental, &world));
        }
        assert_eq!(
            c.ours, cmp.ours,
            "step {step}: the cache changed the pair count"
        );

        late.sync(&world.bodies, &world.colliders);
        let c = late.compare(&world.narrow_phase);
        late_failures += usize::from(c.rapier_lacks + c.extra + c.unmapped > 0);
    }
    // The pile must have formed: far more pairs than the initial grid's few.
    assert!(max_pairs > 4000, "max pairs {max_pairs}");
    println!(
        "{STEPS} steps: up to {max_pairs} exact pairs, up to {max_rapier} rapier pairs; \
         syncing after the step instead would break the contract at {late_failures} steps"
    );
}

/// Two kinematic balls closing in: synced before the rapier step, every comparison holds;
/// synced after it, rapier's pairs are those of the previous poses and the step the balls
/// first touch shows a pair rapier lacks.
#[test]
fn syncing_after_the_rapier_step_is_one_step_late() {
    let mut world = World::new(Vector::ZERO);
    let ball = |c: Vec3| {
        (
            RigidBodyBuilder::kinematic_position_based().translation(c),
            ColliderBuilder::ball(0.5),
        )
    };
    let (b, c) = ball(Vec3::ZERO);
    world.add(b, c);
    let (b, c) = ball(Vec3::new(3.0, 0.0, 0.0));
    let mover = world.add(b, c);
    let mut before = Mirror::new(Config::default());
    let mut after = Mirror::new(Config::default());
    let mut late = Vec::new();
    for k in 1..=8 {
        before.sync(&world.bodies, &world.colliders);
        let x = 3.0 - 0.5 * k as f32;
        world.bodies[mover].set_next_kinematic_translation(Vector::new(x, 0.0, 0.0));
        world.step();
        let cmp = before.compare(&world.narrow_phase);
        assert!(cmp.holds(), "step {k}: {cmp}");
        after.sync(&world.bodies, &world.colliders);
        late.push(after.compare(&world.narrow_phase));
    }
    // Step 4 brings the mover to x = 1: the balls touch, and rapier, which looked at x = 1.5,
    // has no pair yet.
    assert_eq!((late[3].exact, late[3].rapier), (1, 0), "{}", late[3]);
    assert_eq!((late[3].rapier_lacks, late[3].extra), (1, 1));
    assert!(late[..3].iter().all(Comparison::holds));
}

/// The recorded `pile` scene: the balls end up at rest inside the scene's bounds.
#[test]
fn recorded_pile_settles_inside_its_bounds() {
    let pile = broadleaf::fixtures::rapier_world::record_pile(400, 3, 200, 4);
    assert_eq!(pile.frames.len(), 4);
    let inside = pile.bounds.grown(1e-3);
    for f in &pile.frames {
        assert_eq!(f.len(), 400);
        assert!(f.iter().all(|&c| inside.contains_point(c)));
    }
    let moved = pile.frames[3]
        .iter()
        .zip(&pile.frames[2])
        .map(|(a, b)| a.distance(*b))
        .fold(0.0f32, f32::max);
    assert!(moved < 0.05, "still moving {moved} m per step");
}

/// The groups of the `k`-th ball of [`collision_groups_filter_like_rapier_at_every_step`]: four
/// groups `g = k % 4`, each colliding only with itself (`memberships = filter = g`), except
/// every 7th ball, a bridge in `g` and `g + 1` (both masks), and every 11th, in `g` with filter
/// `g | g + 1` under `InteractionTestMode::Or`: an `Or` ball of `g` and one of `g + 1` pass
/// rapier's test by one half of the rule only, the pairs the mirror's `And` rule drops.
fn ball_groups(k: usize) -> InteractionGroups {
    let g = (k % 4) as u32;
    let own = Group::from_bits_retain(1 << g);
    let next = Group::from_bits_retain(1 << ((g + 1) % 4));
    if k % 11 == 0 {
        InteractionGroups::new(own, own | next, InteractionTestMode::Or)
    } else if k % 7 == 0 {
        InteractionGroups::new(own | next, own | next, InteractionTestMode::And)
    } else {
        InteractionGroups::new(own, own, InteractionTestMode::And)
    }
}

/// Gives the ball `body`'s collider [`ball_groups`]`(k)`.
fn group_ball(world: &mut World, body: RigidBodyHandle, k: usize) {
    let co = world.bodies[body].colliders()[0];
    world.colliders[co].set_collision_groups(ball_groups(k));
}

/// The falling scene with collision groups: the balls in four groups that fall through each
/// other ([`ball_groups`]), the dynamic cuboids in a fifth group that pairs with the walls
/// (default groups, all / all) and each other but no ball; balls churned and regrouped as
/// the run goes. At every step the cross-check holds with the groups rule in `exact`, and the
/// test checks the mirror's filtering itself against rapier's colliders: of the overlapping
/// pairs (the brute force of the mirrored shapes without groups), exactly those that pass
/// rapier's `test_and` on the colliders' current groups are in `exact`, and every pair that
/// passes rapier's own `test` (Or mode included) is in rapier's pairs.
#[test]
fn collision_groups_filter_like_rapier_at_every_step() {
    const STEPS: usize = 200;
    let mut rng = Rng::new(2207);
    let (mut world, mut balls) = falling_scene(&mut rng);
    let mut next_ball = 0;
    for &b in &balls {
        group_ball(&mut world, b, next_ball);
        next_ball += 1;
    }
    let boxes = InteractionGroups::new(Group::GROUP_5, Group::ALL, InteractionTestMode::And);
    for (_, co) in world.colliders.iter_mut() {
        let on_dynamic = co.parent().is_some_and(|p| world.bodies[p].is_dynamic());
        if co.shape().as_cuboid().is_some() && on_dynamic {
            co.set_collision_groups(boxes);
        }
    }
    let mut mirror = Mirror::new(Config {
        bounds: Some(Aabb::new(
            Vec3::new(-10.0, -2.0, -10.0),
            Vec3::new(10.0, 30.0, 10.0),
        )),
        ..Config::default()
    });
    let (mut filtered, mut dropped_or, mut regrouped, mut or_mode, mut max_exact) = (0, 0, 0, 0, 0);
    let mut rapier = Vec::new();
    for step in 0..STEPS {
        if step % 50 == 25 {
            for _ in 0..40 {
                let i = rng.below(balls.len() as u32) as usize;
                world.remove(balls.swap_remove(i));
            }
            for _ in 0..40 {
                let c = rng.vec3_in(Vec3::new(-7.0, 18.0, -7.0), Vec3::new(7.0, 22.0, 7.0));
                let b = world.add(
                    RigidBodyBuilder::dynamic().translation(c),
                    ColliderBuilder::ball(0.5),
                );
                group_ball(&mut world, b, next_ball);
                next_ball += 1;
                balls.push(b);
            }
        }
        // Regroup: 30 balls take another ball's groups, before the step that sees it.
        if step % 40 == 10 {
            for _ in 0..30 {
                let b = balls[rng.below(balls.len() as u32) as usize];
                group_ball(&mut world, b, rng.below(1000) as usize);
            }
        }
        let report = mirror.sync(&world.bodies, &world.colliders);
        assert_eq!(report.skipped, 0, "step {step}: {report:?}");
        regrouped += report.regrouped;
        or_mode = or_mode.max(report.or_mode);
        world.step();
        let cmp = mirror.compare(&world.narrow_phase);
        if !cmp.holds() {
            panic!("{}", explain(step, &cmp, &mut mirror, &world));
        }
        max_exact = max_exact.max(cmp.exact);

        // The mirror's filtering against rapier's own rule on the colliders as they are.
        let exact: BTreeSet<Pair> = mirror.exact_pairs().into_iter().collect();
        mirror.rapier_pairs(&world.narrow_phase, &mut rapier);
        let bp = mirror.broadphase();
        let proxies: Vec<brute::Proxy> = world
            .colliders
            .iter()
            .map(|(h, co)| {
                let key = mirror.key(h).expect("every collider is mirrored");
                let fixed = co.parent().is_none_or(|p| world.bodies[p].is_fixed());
                brute::Proxy {
                    key,
                    aabb: bp.aabb(key).expect("a mirrored key is live"),
                    is_static: fixed && co.shape().as_ball().is_none(),
                }
            })
            .collect();
        for p in brute::sweep_pairs(&proxies) {
            let groups = [p.a, p.b].map(|k| {
                let h = mirror.handle(k).expect("a mirrored key");
                let g = world.colliders[h].collision_groups();
                let mirrored = mirror.groups(k).expect("a mirrored key");
                assert_eq!(
                    (mirrored.memberships, mirrored.filter),
                    (g.memberships.bits(), g.filter.bits()),
                    "step {step}: the mirror's groups of {h:?}"
                );
                g
            });
            let and = groups[0].test_and(groups[1]);
            assert_eq!(exact.contains(&p), and, "step {step}: {p:?} {groups:?}");
            if groups[0].test(groups[1]) {
                assert!(
                    rapier.binary_search(&p).is_ok(),
                    "step {step}: rapier lacks {p:?} {groups:?}"
                );
            }
            filtered += usize::from(!and);
            dropped_or += usize::from(!and && groups[0].test(groups[1]));
        }
    }
    println!(
        "{STEPS} steps: up to {max_exact} exact pairs; {filtered} overlapping pairs filtered by \
         groups in all, {dropped_or} of them Or×Or pairs rapier keeps; {regrouped} regroupings; \
         {or_mode} Or-mode colliders"
    );
    assert!(max_exact > 1000, "the balls must pile up: {max_exact}");
    assert!(
        filtered > 10_000,
        "groups must filter overlapping pairs: {filtered}"
    );
    assert!(dropped_or > 0, "the Or approximation must be exercised");
    assert!(
        regrouped >= 30,
        "regroupings must reach the mirror: {regrouped}"
    );
    assert!(or_mode > 100, "{or_mode}");
}
