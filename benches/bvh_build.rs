//! The BVH build of 1M random boxes: broadleaf's binned SAH build (`Bvh::from_aabbs`, default
//! `BvhConfig`) beside obvhs's PLOC builder (search distance `Medium`, sort precision `U64`,
//! the settings its own examples default to), both on the same boxes. Before timing, prints
//! each tree's SAH cost computed by one formula, `(C_t·Σ_interior S(n) + Σ_leaf N(n)·S(n)) /
//! S(root)` with broadleaf's default `C_t` (the formula of `Bvh::sah_cost`, repeated here over
//! obvhs's nodes). `BVH_BUILD_N` sets the number of boxes (default 1 000 000).
//!
//! ```text
//! cargo bench --bench bvh_build
//! ```

use broadleaf::fixtures::scene::Rng;
use broadleaf::{Aabb, Bvh, BvhConfig, Vec3};
use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use obvhs::ploc::{PlocBuilder, PlocSearchDistance, SortPrecision};
use std::hint::black_box;

/// Boxes built when `BVH_BUILD_N` is not set.
const DEFAULT_N: usize = 1_000_000;

/// `n` boxes: centres uniform in a cube sized so the boxes fill about a tenth of it, half
/// extents uniform in `[0.1, 1)` m per axis (seeded, the same every run).
fn boxes(n: usize) -> Vec<Aabb> {
    let mut rng = Rng::new(0x6276_685f_6275_696c);
    let edge = (n as f32 * 8.0).cbrt() * 0.55 / 0.1f32.cbrt();
    let half = Vec3::splat(0.5 * edge);
    (0..n)
        .map(|_| {
            let c = rng.vec3_in(-half, half);
            let h = rng.vec3_in(Vec3::splat(0.1), Vec3::splat(1.0));
            Aabb::from_center_half_extents(c, h)
        })
        .collect()
}

fn to_obvhs(b: &Aabb) -> obvhs::aabb::Aabb {
    obvhs::aabb::Aabb::new(b.min.into(), b.max.into())
}

fn ploc(builder: &mut PlocBuilder, aabbs: &[obvhs::aabb::Aabb]) -> obvhs::bvh2::Bvh2 {
    let indices = (0..aabbs.len() as u32).collect();
    builder.build(
        PlocSearchDistance::Medium,
        aabbs,
        indices,
        SortPrecision::U64,
        1,
    )
}

fn surface_area(min: Vec3, max: Vec3) -> f64 {
    let e = (max - min).max(Vec3::ZERO).as_dvec3();
    2.0 * (e.x * e.y + e.y * e.z + e.z * e.x)
}

/// The SAH cost of obvhs's tree by `Bvh::sah_cost`'s formula (in `f64`).
fn obvhs_sah(bvh: &obvhs::bvh2::Bvh2, traversal_cost: f32) -> f64 {
    let area = |n: &obvhs::bvh2::node::Bvh2Node| {
        let a = n.aabb();
        surface_area(a.min.into(), a.max.into())
    };
    let total: f64 = bvh
        .nodes
        .iter()
        .map(|n| {
            let weight = if n.is_leaf() {
                f64::from(n.prim_count)
            } else {
                f64::from(traversal_cost)
            };
            weight * area(n)
        })
        .sum();
    bvh.nodes.first().map_or(0.0, |root| total / area(root))
}

fn build(c: &mut Criterion) {
    let n = std::env::var("BVH_BUILD_N")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(DEFAULT_N);
    let ours_boxes = boxes(n);
    let theirs_boxes: Vec<_> = ours_boxes.iter().map(to_obvhs).collect();
    let config = BvhConfig::default();

    let (ours, _) = Bvh::from_aabbs(config, &ours_boxes).expect("finite boxes");
    let mut builder = PlocBuilder::with_capacity(n);
    let theirs = ploc(&mut builder, &theirs_boxes);
    println!(
        "SAH cost, {n} boxes: broadleaf binned SAH {:.3}, obvhs PLOC {:.3} (C_t = {})",
        ours.sah_cost(),
        obvhs_sah(&theirs, config.traversal_cost),
        config.traversal_cost
    );

    let mut g = c.benchmark_group("bvh_build");
    g.sample_size(10);
    g.throughput(Throughput::Elements(n as u64));
    g.bench_function("broadleaf_binned_sah", |b| {
        b.iter(|| black_box(Bvh::from_aabbs(config, &ours_boxes)))
    });
    g.bench_function("obvhs_ploc", |b| {
        b.iter(|| black_box(ploc(&mut builder, &theirs_boxes)))
    });
    g.finish();
}

criterion_group!(benches, build);
criterion_main!(benches);
