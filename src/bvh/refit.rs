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
    fn refit_tightens_what_update_enlarged() {
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

    #[test]
    fn cost_of_a_lone_leaf_is_its_count() {
        let boxes = [unit_at(0.0), unit_at(0.5)];
        let (bvh, _) = Bvh::from_aabbs(BvhConfig::default(), &boxes).unwrap();
        assert_eq!(bvh.nodes.len(), 1);
        assert_eq!(bvh.sah_cost(), 2.0);
    }
}
