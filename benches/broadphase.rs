//! Criterion benchmarks of one broadphase step. Each iteration advances the seeded scene by
//! `DT` (`Gas::step`, a few ns per sphere, included in the figure), applies every sphere's new
//! centre with `Octree::update`, and collects all pairs with `pairs_into` into a cleared,
//! reused `Vec`. Throughput is spheres, so criterion's elements/s inverts to ns/object/step.

use broadleaf::octree::{Octree, depth_for};
use broadleaf::scene::{DT, Gas};
use broadleaf::{Pair, ProxyKey};
use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use std::hint::black_box;

fn octree_step(c: &mut Criterion) {
    let mut group = c.benchmark_group("octree");
    let scenes = [
        ("gas", Gas::new(10_000, 1)),
        ("gas", Gas::new(100_000, 1)),
        ("clustered", Gas::clustered(100_000, 1)),
    ];
    for (name, scene) in scenes {
        let mut gas = scene;
        let depth = depth_for(&gas.bounds, gas.radius);
        let mut tree = Octree::new(gas.bounds, depth).expect("scene bounds are valid");
        let keys: Vec<ProxyKey> = gas
            .centers
            .iter()
            .map(|&c| tree.insert(c, gas.radius).expect("scene spheres are valid"))
            .collect();
        let mut pairs: Vec<Pair> = Vec::new();
        group.throughput(Throughput::Elements(gas.len() as u64));
        group.bench_function(BenchmarkId::new(name, gas.len()), |b| {
            b.iter(|| {
                gas.step(DT);
                for (&k, &c) in keys.iter().zip(&gas.centers) {
                    tree.update(k, c, gas.radius)
                        .expect("live key, valid sphere");
                }
                pairs.clear();
                tree.pairs_into(&mut pairs);
                black_box(pairs.len())
            });
        });
    }
    group.finish();
}

criterion_group!(benches, octree_step);
criterion_main!(benches);
