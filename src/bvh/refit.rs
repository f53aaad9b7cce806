//! Keeping node boxes valid after updates: enlarging on `update`, tightening in one reverse
//! sweep on `refit`, and the quality measure that decides when to rebuild instead.

use super::node::Node;
use super::{Bvh, NONE};
use crate::geom::{Aabb, SimdBox};

impl Bvh {
    /// Brings every node box to the exact union of its children, in one reverse sweep over the
    /// depth-first array (children come after their parent). Rebuilds instead when the pending
    /// inserts and removals since the last build exceed [`BvhConfig::rebuild_after_changes`],
    /// and rebuilds after the sweep when the SAH cost exceeds
    /// [`BvhConfig::rebuild_threshold`] × the cost at build. No allocation.
    ///
    /// [`BvhConfig::rebuild_after_changes`]: super::BvhConfig::rebuild_after_changes
    /// [`BvhConfig::rebuild_threshold`]: super::BvhConfig::rebuild_threshold
    pub fn refit(&mut self) {
        // The sweep (or the rebuild) sets every box from its children: nothing stays deferred.
        self.deferred.clear();
        if self.changes_force_rebuild() {
            self.rebuild();
            return;
        }
        let cost = self.refit_nodes();
        self.cost_last = cost;
        self.refits += 1;
        if self.cost_at_build > 0.0 && cost > self.config.rebuild_threshold * self.cost_at_build {
            self.rebuild();
        }
    }

    /// True when the pending inserts plus tombstones exceed the configured fraction of the
    /// primitive count at the last build (any change counts when that count was 0).
    fn changes_force_rebuild(&self) -> bool {
        let changes = self.pending() + self.tombstones;
        let built = self.tree_len.max(1);
        changes > 0 && changes as f32 > self.config.rebuild_after_changes * built as f32
    }

    /// The reverse sweep; returns the SAH cost of the refitted tree, summed in the same sweep.
    fn refit_nodes(&mut self) -> f32 {
        let trav = self.config.traversal_cost;
        let mut total = 0.0f64;
        for n in (0..self.nodes.len()).rev() {
            let node = self.nodes[n];
            let aabb = if node.is_leaf() {
                self.boxes[node.range()]
                    .iter()
                    .fold(SimdBox::EMPTY, |acc, b| acc.union(b))
                    .aabb()
            } else {
                let (a, b) = node.children(n as u32);
                self.nodes[a as usize]
                    .aabb()
                    .union(&self.nodes[b as usize].aabb())
            };
            total += node_cost(&aabb, node.count, trav);
            self.nodes[n].set_aabb(&aabb);
        }
        normalise(total, &self.nodes)
    }

    /// The SAH cost of the tree as it is, `(C_t·Σ_interior S(n) + Σ_leaf N(n)·S(n)) / S(root)`
    /// with `C_t` = [`BvhConfig::traversal_cost`]: the expected cost, in box tests, of a query
    /// that reaches the root (tombstones count as primitives). 0 for an empty tree and for a
    /// root of zero area (all boxes on a line or a point), whose quality then never triggers a
    /// rebuild. O(nodes).
    ///
    /// [`BvhConfig::traversal_cost`]: super::BvhConfig::traversal_cost
    #[must_use]
    pub fn sah_cost(&self) -> f32 {
        let trav = self.config.traversal_cost;
        let total = self
            .nodes
            .iter()
            .map(|n: &Node| node_cost(&n.aabb(), n.count, trav))
            .sum();
        normalise(total, &self.nodes)
    }

    /// Enlarges the ancestors of every leaf grown by [`Bvh::update_box_deferred`] since the
    /// last call, refit or rebuild, which makes the tree exact again (only looser, as after
    /// [`Bvh::update`]). Each walk up stops at the first ancestor that already contains its
    /// leaf's box, as [`Bvh::enlarge_ancestors`] does, so a leaf noted twice costs one test
    /// the second time. No allocation.
    pub(crate) fn enlarge_deferred(&mut self) {
        let mut deferred = core::mem::take(&mut self.deferred);
        for &leaf in &deferred {
            let b = self.nodes[leaf as usize].bounds();
            self.enlarge_ancestors(self.parent[leaf as usize], &b);
        }
        deferred.clear();
        self.deferred = deferred;
    }

    /// Grows `leaf` and its ancestors until one already contains `aabb`: if the parent
    /// contains its child's old box and `aabb`, it contains their union, and so does every
    /// further ancestor.
    pub(super) fn enlarge_ancestors(&mut self, leaf: u32, b: &SimdBox) {
        let mut n = leaf;
        while n != NONE {
            let node = &mut self.nodes[n as usize];
            let old = node.bounds();
            if old.contains(b) {
                return;
            }
            node.set_box(&old.union(b));
            n = self.parent[n as usize];
        }
    }
}

/// A node's term of the SAH cost: `N·S` for a leaf of `N`, `C_t·S` for an interior node.
#[inline]
fn node_cost(aabb: &Aabb, count: u32, trav: f32) -> f64 {
    let weight = if count > 0 { count as f32 } else { trav };
    f64::from(aabb.surface_area()) * f64::from(weight)
}

/// `total / S(root)`, or 0 for no tree or a root of zero area.
fn normalise(total: f64, nodes: &[Node]) -> f32 {
    let Some(root) = nodes.first() else {
        return 0.0;
    };
    let root_area = f64::from(root.aabb().surface_area());
    if root_area <= 0.0 {
        return 0.0;
    }
    (total / root_area) as f32
}

#[cfg(test)]
mod tests {
    use super::super::BvhConfig;
    use super::*;
    use glam::Vec3;

    fn unit_at(x: f32) -> Aabb {
        Aabb::new(Vec3::new(x, 0.0, 0.0), Vec3::new(x + 1.0, 1.0, 1.0))
    }

    #[test]
    fn refit_tightens_what_update_grew() {
        let boxes: Vec<Aabb> = (0..64).map(|i| unit_at(2.0 * i as f32)).collect();
        let (mut bvh, keys) = Bvh::from_aabbs(BvhConfig::default(), &boxes).unwrap();
        let root_before = bvh.nodes[0].aabb();
        bvh.update(keys[0], unit_at(-50.0)).unwrap();
        bvh.validate();
        assert_eq!(bvh.nodes[0].aabb().min.x, -50.0);
        bvh.update(keys[0], unit_at(0.0)).unwrap();
        bvh.refit();
        bvh.validate();
        assert_eq!(bvh.nodes[0].aabb(), root_before);
        assert_eq!(bvh.stats().refits, 1);
    }

    /// Boxes written without enlarging (`update_box_deferred`), mixed with plain updates,
    /// give the brute-force pairs and a valid tree once the ancestors are grown once
    /// (`enlarge_deferred`) or the tree refitted, whichever comes; nothing stays deferred.
    #[test]
    fn deferred_enlargement_then_one_walk_or_refit_is_exact() {
        use crate::brute::{self, Proxy};
        use crate::pair::{Pair, sort_dedup};
        use crate::rng::Rng;
        let mut rng = Rng::new(41);
        let random_box = |rng: &mut Rng, spread: f32| {
            let c = rng.vec3_in(Vec3::splat(-spread), Vec3::splat(spread));
            Aabb::new(c, c + rng.vec3_in(Vec3::splat(0.1), Vec3::splat(2.0)))
        };
        for (n, leaf) in [(1, 8), (5, 8), (300, 4), (2000, 32)] {
            let mut model: Vec<Aabb> = (0..n).map(|_| random_box(&mut rng, 15.0)).collect();
            let config = BvhConfig {
                max_leaf_size: leaf,
                traversal_cost: leaf as f32 / 2.0,
                rebuild_threshold: 1e6,
                ..BvhConfig::default()
            };
            let (mut bvh, keys) = Bvh::from_aabbs(config, &model).unwrap();
            for round in 0..12 {
                for (i, &k) in keys.iter().enumerate() {
                    match rng.next_u32() % 8 {
                        // Small steps (mostly within the leaf), jumps across the scene, and
                        // plain updates in between.
                        0..=2 => {
                            let d = rng.vec3_in(Vec3::splat(-0.5), Vec3::splat(0.5));
                            model[i] = Aabb::new(model[i].min + d, model[i].max + d);
                            bvh.update_box_deferred(k, &SimdBox::new(&model[i]))
                                .unwrap();
                        }
                        3 => {
                            model[i] = random_box(&mut rng, 40.0);
                            bvh.update_box_deferred(k, &SimdBox::new(&model[i]))
                                .unwrap();
                        }
                        4 => {
                            model[i] = random_box(&mut rng, 15.0);
                            bvh.update(k, model[i]).unwrap();
                        }
                        _ => {}
                    }
                }
                if round % 3 == 2 {
                    bvh.refit();
                } else {
                    bvh.enlarge_deferred();
                }
                assert!(!bvh.has_deferred());
                bvh.validate();
                let mut got = Vec::new();
                bvh.pairs_into(&mut got);
                let len = got.len();
                sort_dedup(&mut got);
                assert_eq!(len, got.len(), "a pair reported twice");
                let proxies: Vec<Proxy> = keys
                    .iter()
                    .zip(&model)
                    .map(|(&k, &b)| Proxy::new(k, b))
                    .collect();
                let want: Vec<Pair> = brute::pairs(&proxies);
                assert_eq!(got, want, "n {n} leaf {leaf} round {round}");
            }
        }
    }

    #[test]
    fn cost_of_a_lone_leaf_is_its_count() {
        let boxes = [unit_at(0.0), unit_at(0.5)];
        let (bvh, _) = Bvh::from_aabbs(BvhConfig::default(), &boxes).unwrap();
        assert_eq!(bvh.nodes.len(), 1);
        assert_eq!(bvh.sah_cost(), 2.0);
    }
}
