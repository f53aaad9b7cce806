//! Unit tests of placement, bookkeeping and the pair walk's cost; the randomized oracle tests
//! live in `tests/octree.rs`.

use super::*;
use crate::brute::{self, Proxy};
// The unit tests' scene is the benchmarks' own: test builds get `fixtures` through the
// crate's dev-dependency on itself.
use crate::fixtures::scene::Gas;

fn unit() -> Aabb {
    Aabb::new(Vec3::splat(-1.0), Vec3::ONE)
}

const BOTH: [Placement; 2] = [Placement::Strict, Placement::Loose];

fn sorted_pairs(t: &mut Octree) -> Vec<Pair> {
    let mut out = Vec::new();
    t.pairs_into(&mut out);
    crate::pair::sort_dedup(&mut out);
    out
}

fn proxies(t: &Octree) -> Vec<Proxy> {
    let mut out = Vec::new();
    t.for_each(|k, b| out.push(Proxy::new(k, b)));
    out
}

/// The keys `t.query_aabb(q)` finds, sorted.
fn queried(t: &Octree, q: &Aabb) -> Vec<ProxyKey> {
    let mut got = Vec::new();
    t.query_aabb(q, |k| got.push(k));
    got.sort_unstable();
    got
}

#[test]
fn rtcd_example_straddler_stays_at_root() {
    let mut t = Octree::new(unit(), 1).unwrap();
    let big = t.insert(Vec3::ZERO, 0.5).unwrap();
    let small = t.insert(Vec3::splat(-0.5), 0.1).unwrap();
    assert_eq!(t.level_of(big), Some(0));
    assert_eq!(t.level_of(small), Some(1));
    // Octant 0 is the node right after the root.
    assert_eq!(t.objs[t.id_of(small).unwrap() as usize].node, 1);
    assert_eq!(t.stats().per_level[..2], [1, 1]);
    t.validate();
}

#[test]
fn depth_out_of_range_and_bad_bounds_are_refused() {
    assert_eq!(
        Octree::new(unit(), MAX_DEPTH + 1).unwrap_err(),
        Error::DepthOutOfRange {
            depth: MAX_DEPTH + 1,
            max: MAX_DEPTH
        }
    );
    let flat = Aabb::new(Vec3::ZERO, Vec3::new(1.0, 0.0, 1.0));
    assert!(matches!(
        Octree::new(flat, 3),
        Err(Error::InvalidBounds { .. })
    ));
    let nan = Aabb::new(Vec3::ZERO, Vec3::new(1.0, f32::NAN, 1.0));
    assert!(matches!(
        Octree::new(nan, 3),
        Err(Error::InvalidBounds { .. })
    ));
}

#[test]
fn depth_ten_is_cheap_and_works() {
    for p in BOTH {
        let mut t = Octree::with_placement(unit(), MAX_DEPTH, p).unwrap();
        let a = t.insert(Vec3::splat(0.3), 0.0001).unwrap();
        let b = t.insert(Vec3::splat(0.3001), 0.0001).unwrap();
        let c = t.insert(Vec3::splat(-0.7), 0.0001).unwrap();
        assert_eq!(t.level_of(a), Some(MAX_DEPTH));
        assert_eq!(sorted_pairs(&mut t), vec![Pair::new(a, b)]);
        // Few pages touched: the node arrays stay tiny although the tree has 1.2 G nodes.
        assert!(t.nodes.head_len() <= 3 * 11 * 4096);
        t.remove(c).unwrap();
        t.validate();
    }
}

#[test]
fn outside_spheres_go_to_the_root_and_still_pair() {
    for p in BOTH {
        let mut t = Octree::with_placement(unit(), 3, p).unwrap();
        let out = t.insert(Vec3::new(5.0, 0.5, 0.5), 4.2).unwrap();
        let far = t.insert(Vec3::splat(100.0), 1.0).unwrap();
        let inside = t.insert(Vec3::new(0.85, 0.5, 0.5), 0.05).unwrap();
        assert_eq!(t.level_of(out), Some(0));
        assert_eq!(t.level_of(far), Some(0));
        assert_eq!(t.stats().overflow, 2);
        assert_eq!(sorted_pairs(&mut t), vec![Pair::new(out, inside)]);
        t.update(out, Vec3::ZERO, 0.1).unwrap();
        assert_eq!(t.stats().overflow, 1);
        t.validate();
    }
}

#[test]
fn a_move_inside_the_node_only_stores_the_sphere() {
    for p in BOTH {
        let mut t = Octree::with_placement(unit(), 2, p).unwrap();
        let k = t.insert(Vec3::splat(0.7), 0.05).unwrap();
        let node = t.objs[t.id_of(k).unwrap() as usize].node;
        t.update(k, Vec3::splat(0.75), 0.06).unwrap();
        assert_eq!(t.objs[t.id_of(k).unwrap() as usize].node, node);
        assert_eq!(t.sphere(k), Some((Vec3::splat(0.75), 0.06)));
        t.update(k, Vec3::splat(-0.75), 0.06).unwrap();
        assert_ne!(t.objs[t.id_of(k).unwrap() as usize].node, node);
        t.validate();
    }
}

#[test]
fn bad_input_leaves_the_tree_unchanged() {
    for p in BOTH {
        let mut t = Octree::with_placement(unit(), 3, p).unwrap();
        let keys: Vec<_> = (0..20)
            .map(|i| t.insert(Vec3::splat(i as f32 * 0.1 - 1.0), 0.08).unwrap())
            .collect();
        let before = sorted_pairs(&mut t);
        let boxes: Vec<_> = keys.iter().map(|&k| t.aabb(k)).collect();
        let nan = Vec3::new(f32::NAN, 0.0, 0.0);
        let inf = Vec3::new(0.0, f32::INFINITY, 0.0);
        assert!(matches!(t.insert(nan, 1.0), Err(Error::NonFinite { .. })));
        assert!(matches!(t.insert(inf, 1.0), Err(Error::NonFinite { .. })));
        assert!(matches!(
            t.insert(Vec3::ZERO, f32::NAN),
            Err(Error::NonFinite { .. })
        ));
        assert_eq!(t.insert(Vec3::ZERO, -1.0), Err(Error::NegativeRadius(-1.0)));
        assert!(matches!(
            t.update(keys[3], nan, 1.0),
            Err(Error::NonFinite { .. })
        ));
        assert_eq!(
            t.update(keys[3], Vec3::ZERO, -0.5),
            Err(Error::NegativeRadius(-0.5))
        );
        let stale = keys[5];
        t.remove(stale).unwrap();
        assert_eq!(t.remove(stale), Err(Error::UnknownProxy));
        assert_eq!(t.update(stale, Vec3::ZERO, 1.0), Err(Error::UnknownProxy));
        t.insert_keyed(stale, Vec3::ZERO, 0.1).unwrap();
        t.remove(stale).unwrap();
        let after_remove: Vec<_> = before
            .iter()
            .copied()
            .filter(|p| p.a != stale && p.b != stale)
            .collect();
        assert_eq!(sorted_pairs(&mut t), after_remove);
        for (k, b) in keys.iter().zip(&boxes) {
            if *k != stale {
                assert_eq!(t.aabb(*k), *b);
            }
        }
        assert_eq!(t.len(), 19);
        t.validate();
    }
}

#[test]
fn remove_relinks_the_moved_object() {
    for p in BOTH {
        let mut t = Octree::with_placement(unit(), 2, p).unwrap();
        let keys: Vec<_> = (0..50)
            .map(|i| {
                t.insert(Vec3::splat((i % 7) as f32 * 0.25 - 0.75), 0.1)
                    .unwrap()
            })
            .collect();
        for &k in keys.iter().step_by(3) {
            t.remove(k).unwrap();
            t.validate();
        }
        assert_eq!(sorted_pairs(&mut t), brute::pairs(&proxies(&t)));
    }
}

#[test]
fn gas_pairs_match_the_sweep_reference() {
    for p in BOTH {
        let mut g = Gas::new(3000, 11);
        let depth = p.depth_for(&g.bounds, g.radius);
        let mut t = Octree::with_placement(g.bounds, depth, p).unwrap();
        let keys: Vec<_> = g
            .centers
            .iter()
            .map(|&c| t.insert(c, g.radius).unwrap())
            .collect();
        for _ in 0..3 {
            g.step(0.2);
            for (&k, &c) in keys.iter().zip(&g.centers) {
                t.update(k, c, g.radius).unwrap();
            }
            t.validate();
            assert_eq!(
                sorted_pairs(&mut t),
                brute::sweep_pairs(&proxies(&t)),
                "{p:?}"
            );
        }
    }
}

/// RTCD 7.3.6 with looseness 2: the level depends only on the radius (the deepest whose half
/// cell holds it), the cell only on the centre, so a sphere on a split plane still goes deep.
#[test]
fn loose_placement_follows_the_radius_and_the_centre() {
    let mut t = Octree::with_placement(unit(), 3, Placement::Loose).unwrap();
    assert_eq!(t.placement(), Placement::Loose);
    // Cells at levels 0..=3 are 2, 1, 0.5, 0.25 wide: half cells 1, 0.5, 0.25, 0.125.
    let node_of = |t: &Octree, k: ProxyKey| t.objs[t.id_of(k).unwrap() as usize].node;
    let small = t.insert(Vec3::splat(-0.5), 0.1).unwrap();
    assert_eq!(t.level_of(small), Some(3));
    // The centre −0.5 is the low corner of cell 2 of 8 (`[-0.5, -0.25)`) on each axis.
    assert_eq!(node_of(&t, small), cell::Cell::at(3, [2, 2, 2]).node());
    // On the root's three planes: strict keeps it in the root, loose puts it at level 3, in
    // the cell whose low corner is the centre.
    let on_planes = t.insert(Vec3::ZERO, 0.1).unwrap();
    assert_eq!(t.level_of(on_planes), Some(3));
    assert_eq!(node_of(&t, on_planes), cell::Cell::at(3, [4, 4, 4]).node());
    let mut strict = Octree::new(unit(), 3).unwrap();
    let k = strict.insert(Vec3::ZERO, 0.1).unwrap();
    assert_eq!(strict.level_of(k), Some(0));
    // The level is the deepest whose half cell is at least the radius, wherever the centre.
    for (r, level) in [
        (0.125, 3),
        (0.126, 2),
        (0.25, 2),
        (0.3, 1),
        (0.5, 1),
        (0.6, 0),
        (1.0, 0),
    ] {
        for c in [
            Vec3::splat(-0.99),
            Vec3::new(0.01, -0.3, 0.9),
            Vec3::splat(0.999),
        ] {
            let k = t.insert(c, r).unwrap();
            assert_eq!(t.level_of(k), Some(level), "radius {r} at {c}");
        }
    }
    // Zero radius goes to the deepest level; a diameter above the shortest side or a centre
    // outside the bounds goes to the root as overflow.
    let point = t.insert(Vec3::new(0.9, 0.9, -0.9), 0.0).unwrap();
    assert_eq!(t.level_of(point), Some(3));
    assert_eq!(t.stats().overflow, 0);
    let big = t.insert(Vec3::ZERO, 1.01).unwrap();
    let out = t.insert(Vec3::new(1.05, 0.0, 0.0), 0.01).unwrap();
    assert_eq!((t.level_of(big), t.level_of(out)), (Some(0), Some(0)));
    assert_eq!(t.stats().overflow, 2);
    t.update(out, Vec3::new(0.95, 0.0, 0.0), 0.01).unwrap();
    assert_eq!(t.level_of(out), Some(3));
    assert_eq!(t.stats().overflow, 1);
    t.validate();
    assert_eq!(sorted_pairs(&mut t), brute::pairs(&proxies(&t)));
    t.remove(big).unwrap();
    assert_eq!(t.stats().overflow, 0);
    t.validate();
}

#[test]
#[should_panic(expected = "would fit a deeper level")]
fn validate_catches_a_loose_sphere_placed_too_shallow() {
    let mut t = Octree::with_placement(unit(), 3, Placement::Loose).unwrap();
    let k = t.insert(Vec3::splat(0.3), 0.01).unwrap();
    let id = t.id_of(k).unwrap();
    // Relink it in its level-2 ancestor: the box still fits, but the rule says level 3.
    let node = cell::Cell::at(2, [2, 2, 2]).node();
    t.unlink(id);
    t.per_level[3] -= 1;
    t.per_level[2] += 1;
    t.link(id, node);
    t.validate();
}

/// The loose depth for gas puts every sphere on one level, in cells about one diameter wide.
#[test]
fn loose_gas_lands_on_one_level() {
    let g = Gas::new(20_000, 3);
    let depth = depth_for_loose(&g.bounds, g.radius);
    assert_eq!(depth, depth_for(&g.bounds, g.radius) + 1);
    let mut t = Octree::with_placement(g.bounds, depth, Placement::Loose).unwrap();
    for &c in &g.centers {
        t.insert(c, g.radius).unwrap();
    }
    assert_eq!(t.stats().per_level[depth as usize], g.len() as u32);
    let pairs = sorted_pairs(&mut t);
    assert_eq!(pairs, brute::sweep_pairs(&proxies(&t)));
    // 13 forward neighbour cells of about 0.6 spheres each, plus the own cell.
    let tests = t.stats().aabb_tests;
    assert!(tests < 10 * g.len() as u64, "{tests} AABB tests");
}

/// The clustered scene must not make the walk quadratic: the AABB tests stay within a small
/// multiple of spheres + pairs (the naive walk does hundreds per sphere here).
#[test]
fn clustered_pair_pass_is_not_quadratic() {
    let g = Gas::clustered(20_000, 5);
    for (p, depth) in [
        (Placement::Strict, depth_for(&g.bounds, g.radius)),
        (Placement::Loose, depth_for_loose(&g.bounds, g.radius)),
    ] {
        let mut t = Octree::with_placement(g.bounds, depth, p).unwrap();
        for &c in &g.centers {
            t.insert(c, g.radius).unwrap();
        }
        let pairs = sorted_pairs(&mut t);
        assert_eq!(pairs, brute::sweep_pairs(&proxies(&t)));
        let tests = t.stats().aabb_tests;
        let budget = 12 * (g.len() + pairs.len()) as u64;
        assert!(
            tests < budget,
            "{p:?}: {tests} AABB tests for {} spheres and {} pairs",
            g.len(),
            pairs.len()
        );
    }
}

/// The pair pass radix-sorts a 32-bit walk key up to depth 9 and `(walk key, id)` pairs at
/// depth 10, and splits long own lists into parts down to the deepest level: every depth, with
/// crowds, big, zero-radius, coincident and outside spheres, must give the brute-force set.
#[test]
fn walk_order_pairs_match_brute_force_at_every_depth() {
    let mut rng = crate::rng::Rng::new(17);
    for (depth, p) in [0, 1, 3, 8, 9, MAX_DEPTH]
        .into_iter()
        .flat_map(|d| BOTH.map(|p| (d, p)))
    {
        let mut t = Octree::with_placement(unit(), depth, p).unwrap();
        for i in 0..600 {
            let (c, r) = match i % 6 {
                // A crowd in one small region, so deep lists are long.
                0 | 1 => (rng.vec3_in(Vec3::splat(0.1), Vec3::splat(0.12)), 0.003),
                // Straddlers of the root planes.
                2 => (
                    Vec3::new(0.0, rng.range(-1.0, 1.0), rng.range(-1.0, 1.0)),
                    0.02,
                ),
                3 => (
                    rng.vec3_in(Vec3::splat(-1.5), Vec3::splat(1.5)),
                    rng.range(0.0, 0.05),
                ),
                4 => (Vec3::splat(0.25), 0.0),
                _ => (
                    rng.vec3_in(Vec3::splat(-1.0), Vec3::ONE),
                    rng.range(0.0, 0.6),
                ),
            };
            t.insert(c, r).unwrap();
        }
        t.validate();
        assert_eq!(
            sorted_pairs(&mut t),
            brute::pairs(&proxies(&t)),
            "depth {depth} {p:?}"
        );
    }
}

/// A pass prepared with a lent second buffer finds the pairs of an unprepared one, in both
/// placements at a narrow and a wide (depth 10) walk key: the lent buffer is left empty and the
/// tree's own is never grown; a pass nobody prepared sorts with the tree's own. A change after
/// a pass (and a region's re-root) is seen by the next prepared pass.
#[test]
fn a_pass_prepared_with_a_lent_buffer_finds_the_same_pairs() {
    let mut rng = crate::rng::Rng::new(29);
    for (depth, p) in [5, MAX_DEPTH]
        .into_iter()
        .flat_map(|d| BOTH.map(|p| (d, p)))
    {
        let mut t = Octree::with_placement(unit(), depth, p).unwrap();
        let mut keys = Vec::new();
        for _ in 0..400 {
            let c = rng.vec3_in(Vec3::splat(-1.2), Vec3::splat(1.2));
            keys.push(t.insert(c, rng.range(0.0, 0.08)).unwrap());
        }
        let mut lent = Vec::new();
        for round in 0..3 {
            t.prepare_pass(&mut lent, 1);
            assert!(lent.is_empty() && lent.capacity() >= 400, "{p:?} {round}");
            let prepared = sorted_pairs(&mut t);
            assert_eq!(t.own_sort_buffer(), 0, "{p:?} depth {depth} round {round}");
            assert_eq!(prepared, brute::pairs(&proxies(&t)), "{p:?} {round}");
            for &k in keys.iter().step_by(3) {
                let c = rng.vec3_in(Vec3::splat(-1.2), Vec3::splat(1.2));
                t.update(k, c, rng.range(0.0, 0.08)).unwrap();
            }
        }
        assert_eq!(sorted_pairs(&mut t), brute::pairs(&proxies(&t)), "{p:?}");
        assert!(t.own_sort_buffer() >= 400, "{p:?} depth {depth}");
        t.validate();
    }
    let gas = gas_at(Vec3::splat(3000.0), 3000, 5);
    for p in BOTH {
        let (mut t, _) = growing_with(p, &gas);
        let mut lent = Vec::new();
        t.prepare_pass(&mut lent, 1);
        assert_eq!(sorted_pairs(&mut t), brute::pairs(&proxies(&t)), "{p:?}");
        assert!(t.stats().reroots > 0 && t.own_sort_buffer() == 0, "{p:?}");
    }
}

/// `n` gas spheres (r = 0.5, 10 % fill) in a cube centred at `center`.
fn gas_at(center: Vec3, n: usize, seed: u64) -> Gas {
    let edge = crate::fixtures::scene::cube_edge(n, 0.5, 0.1);
    Gas::in_box(n, seed, 0.5, center, Vec3::splat(edge))
}

/// A growing tree of placement `p` holding `gas`'s spheres, and their keys in `gas`'s order.
fn growing_with(p: Placement, gas: &Gas) -> (Octree, Vec<ProxyKey>) {
    let mut t = Octree::growing(p);
    let keys = gas
        .centers
        .iter()
        .map(|&c| t.insert(c, gas.radius).unwrap())
        .collect();
    (t, keys)
}

/// A growing tree's first pass re-roots it around its spheres, wherever they are: none is
/// left outside, the median sphere's cells are a fixed multiple of its diameter (loose) or
/// the deepest cells two to four diameters (strict), at the origin as 3 km or 100 km away.
#[test]
fn a_growing_tree_roots_around_its_spheres_wherever_they_are() {
    for p in BOTH {
        let mut cells = Vec::new();
        for center in [Vec3::ZERO, Vec3::new(3000.0, 0.0, 0.0), Vec3::splat(1e5)] {
            let gas = gas_at(center, 4000, 3);
            let (mut t, keys) = growing_with(p, &gas);
            assert!(t.is_growing());
            assert_eq!(t.stats().reroots, 0);
            assert_eq!(sorted_pairs(&mut t), brute::pairs(&proxies(&t)), "{p:?}");
            t.validate();
            let st = t.stats();
            assert_eq!((st.reroots, st.overflow), (1, 0), "{p:?} at {center:?}");
            let side = t.bounds().extent();
            assert!(
                side.max_element() - side.min_element() <= 1e-5 * side.x,
                "a cube"
            );
            assert!(side.x < 200.0, "{p:?}: region {:?}", t.bounds());
            let cell = match p {
                Placement::Strict => side.x / (1u32 << t.depth()) as f32,
                Placement::Loose => side.x / (1u32 << t.level_of(keys[0]).unwrap()) as f32,
            };
            cells.push(cell);
            match p {
                Placement::Strict => assert!((2.0..4.0).contains(&cell), "{cell}"),
                Placement::Loose => assert!((1.0..2.0).contains(&cell), "{cell}"),
            }
        }
        // The same cells wherever the world is.
        assert!(cells.iter().all(|&c| c == cells[0]), "{p:?}: {cells:?}");
    }
}

/// One sphere teleported to 1e7 m does not blow the region up to 1e7 m (which would put every
/// other sphere in one cell): it stays outside, alone; many outliers (more than half the
/// overflow limit) are covered instead.
#[test]
fn one_outlier_does_not_inflate_the_region() {
    for p in BOTH {
        let gas = gas_at(Vec3::ZERO, 5000, 4);
        let (mut t, keys) = growing_with(p, &gas);
        t.maintain();
        let side = t.bounds().extent().x;
        t.update(keys[7], Vec3::splat(1e7), 0.5).unwrap();
        // Force a re-root with the outlier present: more than twice the spheres.
        for &c in &gas.centers {
            t.insert(c + Vec3::splat(0.25), 0.5).unwrap();
        }
        t.insert(Vec3::ZERO, 0.5).unwrap();
        let mut pairs = sorted_pairs(&mut t);
        assert_eq!(t.stats().reroots, 2, "{p:?}");
        assert_eq!(t.stats().overflow, 1, "{p:?}: the outlier alone is outside");
        assert!(t.bounds().extent().x <= side, "{p:?}: {:?}", t.bounds());
        assert_eq!(pairs, brute::pairs(&proxies(&t)));
        t.validate();
        // Many outliers: the region covers them all.
        for (i, &k) in keys[..1000].iter().enumerate() {
            t.update(k, Vec3::splat(1e7) + Vec3::X * i as f32, 0.5)
                .unwrap();
        }
        pairs.clear();
        t.pairs_into(&mut pairs);
        crate::pair::sort_dedup(&mut pairs);
        assert_eq!(t.stats().overflow, 0, "{p:?}");
        assert!(t.bounds().extent().x > 1e7, "{p:?}");
        assert_eq!(pairs, brute::pairs(&proxies(&t)));
        t.validate();
    }
}

/// A world drifting steadily: after every pass the overflow is within the limit, and re-roots
/// are amortised: far fewer than the steps.
#[test]
fn a_drifting_world_keeps_its_overflow_bounded() {
    for p in BOTH {
        let mut gas = gas_at(Vec3::ZERO, 6400, 5);
        let (mut t, keys) = growing_with(p, &gas);
        let steps = 200;
        for s in 0..steps {
            gas.step(1.0 / 60.0);
            let shift = Vec3::new(1.0, -0.5, 0.25) * s as f32;
            for (&k, &c) in keys.iter().zip(&gas.centers) {
                t.update(k, c + shift, 0.5).unwrap();
            }
            let mut n = 0;
            t.for_each_pair(|_, _| n += 1);
            let st = t.stats();
            assert!(
                st.overflow as usize <= region::overflow_limit(t.len()),
                "{p:?} step {s}"
            );
        }
        t.validate();
        assert_eq!(sorted_pairs(&mut t), brute::pairs(&proxies(&t)));
        let reroots = t.stats().reroots;
        assert!(
            (2..=steps as u32 / 8).contains(&reroots),
            "{p:?}: {reroots} re-roots"
        );
    }
}

/// A world whose spheres keep their sizes and span is audited by its sample alone; once the
/// radii grow by half, the next audit computes a full proposal.
#[test]
fn an_unchanged_world_is_audited_by_its_sample() {
    for p in BOTH {
        let gas = gas_at(Vec3::ZERO, 2000, 6);
        let (mut t, keys) = growing_with(p, &gas);
        t.maintain();
        // The audits at calls 16, 48, 112, 240 and 496 after the re-root.
        for _ in 0..500 {
            t.maintain();
        }
        assert_eq!(t.regrow.full_audits, 0, "{p:?}");
        assert_eq!(t.stats().reroots, 1, "{p:?}");
        for (&k, &c) in keys.iter().zip(&gas.centers) {
            t.update(k, c, 0.75).unwrap();
        }
        // The next audit, at call 1008.
        for _ in 0..520 {
            t.maintain();
        }
        assert_eq!(t.regrow.full_audits, 1, "{p:?}");
        assert_eq!(sorted_pairs(&mut t), brute::pairs(&proxies(&t)));
        t.validate();
    }
}

/// When the spheres shrink a hundredfold, an audit notices the cells no longer fit them and
/// re-roots; a fixed-region tree never re-roots.
#[test]
fn an_audit_refits_the_cells_to_shrunk_spheres() {
    for p in BOTH {
        let gas = gas_at(Vec3::ZERO, 2000, 6);
        let (mut t, keys) = growing_with(p, &gas);
        t.maintain();
        let before = t.lattice.typical_cell(0.5);
        for (&k, &c) in keys.iter().zip(&gas.centers) {
            t.update(k, c * 0.01, 0.005).unwrap();
        }
        for _ in 0..64 {
            t.maintain();
        }
        let after = t.lattice.typical_cell(0.005);
        assert!(after * 20.0 < before, "{p:?}: {before} -> {after}");
        assert_eq!(t.stats().overflow, 0);
        assert_eq!(sorted_pairs(&mut t), brute::pairs(&proxies(&t)));
        t.validate();
    }
    let mut fixed = Octree::new(unit(), 3).unwrap();
    fixed.insert(Vec3::splat(100.0), 1.0).unwrap();
    fixed.maintain();
    fixed.pairs_into(&mut Vec::new());
    assert!(!fixed.is_growing());
    assert_eq!((fixed.stats().reroots, fixed.bounds()), (0, unit()));
}

/// Updates whose relinks are deferred (`update_live_deferred`) leave the lists exactly as
/// updating each sphere at once does, whichever operation catches them up: a prepared pass
/// (serial, or split with the relinks beside the sort), a pass nobody prepared, an insert, a
/// remove or a plain update. After each, the tree validates and its pairs and a box query
/// equal brute force over the latest spheres.
#[test]
fn deferred_relinks_leave_the_lists_as_immediate_ones() {
    let mut rng = crate::rng::Rng::new(41);
    for p in BOTH {
        for catch_up in 0..6 {
            let mut now = Octree::with_placement(unit(), 5, p).unwrap();
            let mut keys = Vec::new();
            for _ in 0..300 {
                let c = rng.vec3_in(Vec3::splat(-1.1), Vec3::splat(1.1));
                keys.push(now.insert(c, rng.range(0.0, 0.1)).unwrap());
            }
            let mut later = now.clone();
            for round in 0..4 {
                for &k in keys.iter().skip(round).step_by(2) {
                    let c = rng.vec3_in(Vec3::splat(-1.1), Vec3::splat(1.1));
                    let r = rng.range(0.0, 0.1);
                    now.update(k, c, r).unwrap();
                    later.update_live_deferred(k, c, r);
                }
                assert!(
                    !later.deferred.is_empty(),
                    "{p:?} {round}: nothing moved node"
                );
                let mut lent = Vec::new();
                match catch_up {
                    0 => later.prepare_pass(&mut lent, 1),
                    1 => later.prepare_pass(&mut lent, 2),
                    2 => {
                        sorted_pairs(&mut later);
                    }
                    3 => {
                        let c = rng.vec3_in(Vec3::splat(-1.0), Vec3::splat(1.0));
                        let k = later.insert(c, 0.05).unwrap();
                        assert_eq!(now.insert(c, 0.05).unwrap(), k);
                    }
                    4 => {
                        let k = keys.swap_remove(round);
                        later.remove(k).unwrap();
                        now.remove(k).unwrap();
                    }
                    _ => {
                        let (k, c) = (keys[round], Vec3::splat(0.3));
                        later.update(k, c, 0.02).unwrap();
                        now.update(k, c, 0.02).unwrap();
                    }
                }
                later.flush_relinks();
                assert!(later.deferred.is_empty(), "{p:?} {catch_up}: not caught up");
                assert_eq!(
                    format!("{:?}{:?}", later.links, later.nodes),
                    format!("{:?}{:?}", now.links, now.nodes),
                    "{p:?} catch-up {catch_up} round {round}"
                );
                later.validate();
                let want = brute::pairs(&proxies(&later));
                assert_eq!(sorted_pairs(&mut later), want, "{p:?} {catch_up} {round}");
                let q = Aabb::new(Vec3::splat(-0.4), Vec3::splat(0.5));
                let (got, want) = (queried(&later, &q), brute::query_aabb(&proxies(&later), &q));
                assert_eq!(got, want, "{p:?} {catch_up} {round}: query");
            }
        }
    }
}

/// A tree of depth 4 over `unit()` with a sphere in every cell of levels 0 to 4, and the
/// spheres as `(key, center, radius)`.
fn full_levels(p: Placement) -> (Octree, Vec<(ProxyKey, Vec3, f32)>) {
    let mut t = Octree::with_placement(unit(), 4, p).unwrap();
    let mut spheres = Vec::new();
    for level in 0..=4u32 {
        let side = 1u32 << level;
        let cell = 2.0 / side as f32;
        // Small enough for `level` under both placements, too large for the next one.
        let radius = cell * 0.2;
        for z in 0..side {
            for y in 0..side {
                for x in 0..side {
                    let at = |i: u32| -1.0 + (i as f32 + 0.5) * cell;
                    let c = Vec3::new(at(x), at(y), at(z));
                    spheres.push((t.insert(c, radius).unwrap(), c, radius));
                }
            }
        }
    }
    t.validate();
    (t, spheres)
}

/// A ray or sphere cast gathers each piece's list heads before it walks them, walking a full
/// gather at once: in a tree with every cell of levels 0 to 4 occupied, casts whose pieces
/// reach from a few cells to hundreds find what brute force finds.
#[test]
fn casts_over_full_levels_find_what_brute_force_finds() {
    for p in BOTH {
        let (t, spheres) = full_levels(p);
        let mut rng = crate::rng::Rng::new(8);
        for q in 0..600 {
            let o = Vec3::new(
                rng.range(-1.5, 1.5),
                rng.range(-1.5, 1.5),
                rng.range(-1.5, 1.5),
            );
            let d = (Vec3::new(
                rng.range(-1.0, 1.0),
                rng.range(-1.0, 1.0),
                rng.range(-1.0, 1.0),
            ) + Vec3::splat(1e-3))
            .normalize();
            let max_t = rng.range(0.0, 4.0);
            let want = brute::cast_ray_spheres(&spheres, o, d, max_t);
            assert_eq!(
                t.cast_ray(o, d, max_t),
                want,
                "{p:?} ray {q}: {o} {d} {max_t}"
            );
            // Radii up to half the region: a piece then reaches hundreds of cells.
            let radius = [0.0, 0.05, 0.3, 1.0][q % 4];
            let want = brute::closest(spheres.iter().filter_map(|&(k, c, r)| {
                crate::geom::sphere_cast_sphere(o, radius, d, max_t, c, r).map(|t| (k, t))
            }));
            assert_eq!(
                t.cast_sphere(o, radius, d, max_t),
                want,
                "{p:?} cast {q}: {o} {radius} {d} {max_t}"
            );
        }
    }
}

/// A direct box query gathers the list heads of every cell it reaches on every occupied
/// level before it walks them: with every cell of levels 0 to 4 holding a sphere, queries
/// that reach up to the most cells read directly (and just past that, where the walk takes
/// over) find exactly the spheres brute force finds.
#[test]
fn direct_queries_over_full_levels_find_what_brute_force_finds() {
    for p in BOTH {
        let (t, _) = full_levels(p);
        let all = proxies(&t);
        let mut rng = crate::rng::Rng::new(7);
        for q in 0..4000 {
            // Half-widths from a sliver to a third of the region: the reaching cells run from
            // a few to past the direct queries' limit.
            let half = Vec3::new(
                rng.range(0.01, 0.35),
                rng.range(0.01, 0.35),
                rng.range(0.01, 0.35),
            );
            let center = Vec3::new(
                rng.range(-1.0, 1.0),
                rng.range(-1.0, 1.0),
                rng.range(-1.0, 1.0),
            );
            let bx = Aabb::new(center - half, center + half);
            let (got, want) = (queried(&t, &bx), brute::query_aabb(&all, &bx));
            assert_eq!(got, want, "{p:?}, query {q}: {bx:?}");
        }
    }
}
