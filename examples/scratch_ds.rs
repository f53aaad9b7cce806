use broadleaf::bvh::{Bvh, BvhConfig};
use broadleaf::scene::Bodies;
use std::time::Instant;
fn main() {
    let b = Bodies::new(10_000, 1);
    let dynb: Vec<_> = b.dynamic.iter().map(|o| o.aabb()).collect();
    let stat: Vec<_> = b.statics.iter().map(|o| o.aabb()).collect();
    for (leaf, trav) in [
        (8u32, 4.0f32),
        (16, 8.0),
        (16, 12.0),
        (16, 16.0),
        (32, 8.0),
        (32, 16.0),
        (32, 32.0),
        (24, 12.0),
    ] {
        let cfg = BvhConfig {
            max_leaf_size: leaf,
            traversal_cost: trav,
            ..BvhConfig::default()
        };
        let (mut d, _) = Bvh::from_aabbs(cfg, &dynb).unwrap();
        let (st, _) = Bvh::from_aabbs(cfg, &stat).unwrap();
        let (mut bs, mut bw) = (f64::MAX, f64::MAX);
        let (mut n1, mut n2) = (0, 0);
        for _ in 0..200 {
            n1 = 0;
            n2 = 0;
            let t = Instant::now();
            d.for_each_pair(|_, _| n1 += 1);
            bs = bs.min(t.elapsed().as_nanos() as f64 / 11001.0);
            let t = Instant::now();
            d.for_each_pair_with(&st, |_, _| n2 += 1);
            bw = bw.min(t.elapsed().as_nanos() as f64 / 11001.0);
        }
        print!("leaf {leaf} trav {trav}: ");
        println!("self {bs:.1} ns/obj ({n1}) with {bw:.1} ns/obj ({n2})");
    }
}
