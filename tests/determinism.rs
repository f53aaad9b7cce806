//! The same seeded scene and operations give bit-identical pair lists and events on every run:
//! a hash of 300 steps of a mixed scene (moving spheres, dynamic and static bodies, inserts and
//! removes) must equal a golden value. The golden value was computed from the brute-force
//! reference, so it also pins the exact pair set.

use broadleaf::scene::{DT, Gas, Rng};
use broadleaf::{Aabb, BodyKind, BroadPhase, Config, Pair, ProxyKey, Vec3};
use slotmap::Key;

const GOLDEN: u64 = 0x76df_1956_69f5_ec7b;

/// FNV-1a over the keys' FFI bits: stable across runs and platforms.
struct Fnv(u64);

impl Fnv {
    fn write(&mut self, x: u64) {
        for byte in x.to_le_bytes() {
            self.0 ^= u64::from(byte);
            self.0 = self.0.wrapping_mul(0x0100_0000_01b3);
        }
    }

    fn pairs(&mut self, tag: u64, pairs: &[Pair]) {
        self.write(tag);
        self.write(pairs.len() as u64);
        for p in pairs {
            self.write(p.a.data().as_ffi());
            self.write(p.b.data().as_ffi());
        }
    }
}

/// How to insert the unrelated proxies (far from everything and from each other).
#[derive(Clone, Copy)]
enum Unrelated {
    None,
    Forward,
    Reverse,
    Interleaved,
}

/// Runs the scene and hashes every step's `pairs`, `added` and `removed`. Unrelated proxies are
/// inserted after the scene's own, so they take no key the scene uses and pair with nothing:
/// the hash must not depend on them or on their order.
fn scene_hash(unrelated: Unrelated) -> u64 {
    scene_hash_with_skin(unrelated, 0.0)
}

/// [`scene_hash`] with `Config::skin`: the pair cache changes the cost, never the lists.
fn scene_hash_with_skin(unrelated: Unrelated, skin: f32) -> u64 {
    let mut gas = Gas::new(1500, 99);
    let mut bp = BroadPhase::new(Config {
        bounds: gas.bounds,
        octree_depth: 4,
        skin,
        ..Config::default()
    });
    let mut rng = Rng::new(5);
    let mut bodies: Vec<(ProxyKey, Aabb)> = Vec::new();
    let mut insert_bodies = |bp: &mut BroadPhase, rng: &mut Rng| {
        for i in 0..150 {
            let c = rng.vec3_in(gas.bounds.min, gas.bounds.max);
            let aabb = Aabb::from_center_half_extents(c, Vec3::splat(rng.range(0.1, 2.0)));
            let kind = if i % 5 == 0 {
                BodyKind::Static
            } else {
                BodyKind::Dynamic
            };
            bodies.push((bp.insert_body(aabb, kind).unwrap(), aabb));
        }
    };
    let mut spheres: Vec<ProxyKey> = gas
        .centers
        .iter()
        .map(|&c| bp.insert_sphere(c, gas.radius).unwrap())
        .collect();
    insert_bodies(&mut bp, &mut rng);
    // 200 spheres and 200 bodies on a line 10 km away, 10 m apart: they pair with nothing.
    let far = |i: u32| Vec3::new(1.0e4 + 10.0 * i as f32, -1.0e4, 0.0);
    let mut order: Vec<u32> = (0..400).collect();
    match unrelated {
        Unrelated::None => order.clear(),
        Unrelated::Forward => {}
        Unrelated::Reverse => order.reverse(),
        Unrelated::Interleaved => order.sort_by_key(|&i| (i % 7, i)),
    }
    for i in order {
        if i % 2 == 0 {
            bp.insert_sphere(far(i), 1.0).unwrap();
        } else {
            let aabb = Aabb::from_center_half_extents(far(i), Vec3::ONE);
            let kind = if i % 4 == 1 {
                BodyKind::Static
            } else {
                BodyKind::Dynamic
            };
            bp.insert_body(aabb, kind).unwrap();
        }
    }
    let mut h = Fnv(0xcbf2_9ce4_8422_2325);
    for step in 0..300 {
        gas.step(DT);
        for (i, &key) in spheres.iter().enumerate() {
            if key.is_null() {
                continue;
            }
            bp.update_sphere(key, gas.centers[i], gas.radius).unwrap();
        }
        for (key, aabb) in bodies.iter_mut().skip(step % 5).step_by(5) {
            let d = rng.vec3_in(Vec3::splat(-0.2), Vec3::splat(0.2));
            *aabb = Aabb::new(aabb.min + d, aabb.max + d);
            bp.update_body(*key, *aabb).unwrap();
        }
        // Remove one sphere and re-insert one that was removed earlier.
        let i = rng.below(spheres.len() as u32) as usize;
        if !spheres[i].is_null() {
            bp.remove(spheres[i]).unwrap();
            spheres[i] = ProxyKey::null();
        }
        let j = rng.below(spheres.len() as u32) as usize;
        if spheres[j].is_null() {
            spheres[j] = bp.insert_sphere(gas.centers[j], gas.radius).unwrap();
        }
        let out = bp.step();
        h.pairs(1, out.pairs);
        h.pairs(2, out.added);
        h.pairs(3, out.removed);
    }
    h.0
}

#[test]
fn three_hundred_steps_hash_to_the_golden_value() {
    let h = scene_hash(Unrelated::None);
    assert_eq!(
        h,
        scene_hash(Unrelated::None),
        "two runs in one process differ"
    );
    assert_eq!(h, GOLDEN, "pair lists changed: got {h:#x}");
}

#[test]
fn unrelated_proxies_in_any_insertion_order_change_nothing() {
    for order in [
        Unrelated::Forward,
        Unrelated::Reverse,
        Unrelated::Interleaved,
    ] {
        assert_eq!(scene_hash(order), GOLDEN);
    }
}

#[test]
fn the_pair_cache_gives_the_same_lists() {
    for skin in [0.02, 0.3, 2.0] {
        assert_eq!(
            scene_hash_with_skin(Unrelated::None, skin),
            GOLDEN,
            "skin {skin}"
        );
    }
    assert_eq!(scene_hash_with_skin(Unrelated::Reverse, 0.3), GOLDEN);
}
