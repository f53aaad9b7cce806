//! The physics loop end to end: 1000 spheres dropped into a box come to rest inside it, the run
//! is bit-for-bit repeatable, and the octree (both placements) and BVH paths see the same pairs
//! at every step: the pair set the test builds itself from the spheres and walls the world
//! handed its broadphase (centres copied before the step, radii, growths), grown by the margin
//! by the test.

mod common;

use broadleaf::fixtures::sim::{DropConfig, IndexKind, SphereDrop, World};
use broadleaf::octree::Placement;
use broadleaf::{Aabb, Pair, Vec3, brute};
use common::Fnv;

const N: usize = 1000;
const RADIUS: f32 = 0.5;
const SEED: u64 = 7;
const DT: f32 = 1.0 / 60.0;
/// 6 s of simulated time: the spheres fall for about 2 s and are still after about 5 s.
const STEPS: usize = 360;

fn drop_scene(index: IndexKind) -> SphereDrop {
    drop_scene_placed(index, Placement::Strict)
}

fn drop_scene_placed(index: IndexKind, placement: Placement) -> SphereDrop {
    let mut config = DropConfig::new(N, RADIUS, SEED);
    config.world.index = index;
    config.world.broadphase.octree_placement = placement;
    config.build().unwrap()
}

/// A proxy of the world by what it is, independent of the keys (which are per broadphase).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
enum Id {
    Sphere(usize),
    Box(usize),
}

fn id(world: &World, key: broadleaf::ProxyKey) -> Id {
    match world.sphere_of(key) {
        Some(i) => Id::Sphere(i),
        None => Id::Box(world.box_keys().iter().position(|&k| k == key).unwrap()),
    }
}

fn pairs_by_id(world: &World) -> Vec<(Id, Id)> {
    let mut out: Vec<(Id, Id)> = world
        .pairs()
        .iter()
        .map(|p| {
            let (a, b) = (id(world, p.a), id(world, p.b));
            (a.min(b), a.max(b))
        })
        .collect();
    out.sort_unstable();
    out
}

/// The pair set the step just taken must report, from the test's own record of what the world
/// handed its broadphase: each sphere at its centre from before the step (`centers`, copied
/// by the test) with radius `radii()[i] + growth()[i]`, as a sphere (octree) or as that
/// sphere's box (BVH); every wall as the static box the test's scene gave. The test grows each
/// box by the configured margin itself (a sphere's radius, a box's faces) and feeds
/// `brute::sweep_pairs`; nothing is read from the broadphase.
fn expected_pairs(world: &World, centers: &[Vec3]) -> Vec<Pair> {
    let margin = world.config().broadphase.margin;
    let grown = |b: Aabb| Aabb::new(b.min - Vec3::splat(margin), b.max + Vec3::splat(margin));
    let spheres = world.sphere_keys().iter().enumerate().map(|(i, &key)| {
        let radius = world.radii()[i] + world.growth()[i];
        let aabb = match world.config().index {
            IndexKind::Octree => Aabb::from_center_radius(centers[i], radius + margin),
            IndexKind::Bvh => grown(Aabb::from_center_radius(centers[i], radius)),
        };
        brute::Proxy {
            key,
            aabb,
            is_static: false,
        }
    });
    let walls = world
        .box_keys()
        .iter()
        .zip(world.boxes())
        .map(|(&key, &b)| brute::Proxy {
            key,
            aabb: grown(b),
            is_static: true,
        });
    brute::sweep_pairs(&spheres.chain(walls).collect::<Vec<_>>())
}

/// The deepest overlap of the final positions, sphere–sphere and sphere–wall, measured from
/// scratch (not from the world's own stats).
fn deepest_overlap(scene: &SphereDrop) -> f32 {
    let w = &scene.world;
    let keys = w.sphere_keys();
    let proxies: Vec<brute::Proxy> = (0..w.len())
        .map(|i| {
            brute::Proxy::new(
                keys[i],
                broadleaf::Aabb::from_center_radius(w.positions()[i], w.radii()[i]),
            )
        })
        .collect();
    let mut deepest = 0.0f32;
    for p in brute::sweep_pairs(&proxies) {
        let (i, j) = (w.sphere_of(p.a).unwrap(), w.sphere_of(p.b).unwrap());
        let d = w.positions()[i].distance(w.positions()[j]);
        deepest = deepest.max(w.radii()[i] + w.radii()[j] - d);
    }
    // Walls and floor; the top is open.
    let (lo, hi) = (scene.interior.min, scene.interior.max);
    for (c, r) in w.positions().iter().zip(w.radii()) {
        for into_wall in [
            lo.y - (c.y - r),
            lo.x - (c.x - r),
            c.x + r - hi.x,
            lo.z - (c.z - r),
            c.z + r - hi.z,
        ] {
            deepest = deepest.max(into_wall);
        }
    }
    deepest
}

fn position_bits(world: &World) -> Vec<u32> {
    world
        .positions()
        .iter()
        .chain(world.velocities())
        .flat_map(|v| v.to_array().map(f32::to_bits))
        .collect()
}

/// FNV-1a over the bits of every position and velocity.
fn hash(bits: &[u32]) -> u64 {
    let mut h = Fnv::new();
    for &b in bits {
        h.write(u64::from(b));
    }
    h.0
}

#[test]
fn a_thousand_dropped_spheres_settle_inside_the_box_deterministically() {
    let mut runs = Vec::new();
    for _ in 0..2 {
        let mut scene = drop_scene(IndexKind::Octree);
        let mut peak = 0.0f64;
        for _ in 0..STEPS {
            let stats = scene.world.step(DT).unwrap();
            peak = peak.max(stats.kinetic_energy);
            // The solver's own view stays shallow at every step, not only at the end.
            assert!(stats.max_penetration < 0.1 * RADIUS, "{stats:?}");
        }
        runs.push((scene, peak));
    }
    let (scene, peak) = &runs[0];
    let world = &scene.world;

    // Nobody left the box: every centre is inside the container.
    for (i, c) in world.positions().iter().enumerate() {
        assert!(scene.interior.contains_point(*c), "sphere {i} escaped: {c}");
    }
    // At rest: the root-mean-square speed is below 2 cm/s, and the energy fell by far.
    let v_rms = (world
        .velocities()
        .iter()
        .map(|v| v.length_squared())
        .sum::<f32>()
        / N as f32)
        .sqrt();
    assert!(v_rms < 0.02, "v_rms = {v_rms} m/s");
    assert!(
        world.kinetic_energy() < 1e-3 * peak,
        "{} vs peak {peak}",
        world.kinetic_energy()
    );
    // Overlaps stay a small fraction of the radius.
    let deepest = deepest_overlap(scene);
    assert!(deepest < 0.1 * RADIUS, "deepest overlap {deepest} m");
    // The pile is a pile: it lies low in the box.
    let top = world
        .positions()
        .iter()
        .map(|c| c.y)
        .fold(f32::MIN, f32::max);
    assert!(top < 0.6 * scene.interior.max.y, "top of the pile at {top}");

    let (a, b) = (position_bits(world), position_bits(&runs[1].0.world));
    assert_eq!(hash(&a), hash(&b));
    assert_eq!(a, b);
}

#[test]
fn octree_and_bvh_paths_give_the_same_pairs_at_every_step() {
    let mut octree = drop_scene(IndexKind::Octree);
    let mut loose = drop_scene_placed(IndexKind::Octree, Placement::Loose);
    let mut bvh = drop_scene(IndexKind::Bvh);
    let mut total = 0usize;
    for step in 0..STEPS {
        let before = |scene: &SphereDrop| scene.world.positions().to_vec();
        let (at_o, at_l, at_b) = (before(&octree), before(&loose), before(&bvh));
        octree.world.step(DT).unwrap();
        loose.world.step(DT).unwrap();
        bvh.world.step(DT).unwrap();
        let (po, pb) = (pairs_by_id(&octree.world), pairs_by_id(&bvh.world));
        assert_eq!(po, pb, "step {step}");
        assert_eq!(pairs_by_id(&loose.world), pb, "step {step}");
        assert_eq!(
            octree.world.pairs(),
            expected_pairs(&octree.world, &at_o),
            "step {step}"
        );
        assert_eq!(
            loose.world.pairs(),
            expected_pairs(&loose.world, &at_l),
            "step {step}"
        );
        assert_eq!(
            bvh.world.pairs(),
            expected_pairs(&bvh.world, &at_b),
            "step {step}"
        );
        total += po.len();
    }
    assert!(total > STEPS * N, "the spheres did meet: {total} pairs");
    assert_eq!(position_bits(&octree.world), position_bits(&bvh.world));
    assert_eq!(position_bits(&loose.world), position_bits(&bvh.world));
}

#[test]
fn the_drop_scenes_octree_follows_its_spheres() {
    // 4000 spheres of radius 0.5 in a container about 21 m wide and 25 m tall (the Config's
    // region hint): after the first step every sphere is inside the octree's region, and the
    // cells fit the spheres for either placement (loose: every sphere at a level whose cells
    // are between one and four diameters; strict: the deepest cells at least two diameters).
    for placement in [Placement::Strict, Placement::Loose] {
        let mut config = DropConfig::new(4000, RADIUS, SEED);
        config.world.broadphase.octree_placement = placement;
        let mut scene = config.build().unwrap();
        scene.world.step(DT).unwrap();
        let octree = scene.world.broadphase().octree();
        let stats = octree.stats();
        assert_eq!(stats.overflow, 0, "{placement:?}: {stats:?}");
        let side = octree.bounds().extent().x;
        let cell = |level: u32| side / (1u32 << level) as f32;
        match placement {
            Placement::Strict => {
                let deepest = cell(octree.depth());
                assert!((4.0 * RADIUS..8.0 * RADIUS).contains(&deepest), "{deepest}");
            }
            Placement::Loose => {
                for &key in scene.world.sphere_keys() {
                    let c = cell(octree.level_of(key).unwrap());
                    assert!((2.0 * RADIUS..8.0 * RADIUS).contains(&c), "{c}");
                }
            }
        }
    }
}
