//! The whole-tree invariant check.

use super::cell::{Cell, level_of};
use super::{MAX_DEPTH, NONE, Octree};

impl Octree {
    /// Checks every invariant and panics with a message naming the first one broken: each
    /// sphere's box, cell range, node and walk key are what placement gives for its stored
    /// sphere, and its node obeys the placement rule checked from its definition (strict: the
    /// box's lattice range lies in the node's cell and straddles a mid plane of it, unless the
    /// node is deepest; loose: the centre lies in the node's cell, the radius within half the
    /// cell size, the box's lattice range inside the node's loose bounds, and no deeper level
    /// would take it); every node list is doubly linked and reaches exactly the spheres that
    /// name its node; a child bit is set iff the child's subtree holds a sphere; per-level,
    /// overflow and key-map counts agree. O(n + occupied nodes); for tests and debugging.
    #[doc(hidden)]
    pub fn validate(&self) {
        assert!(
            self.deferred.is_empty(),
            "relinks deferred past the step that deferred them"
        );
        let n = self.objs.len();
        assert_eq!(self.links.len(), n, "links and objects differ in length");
        assert_eq!(
            self.versions.len(),
            n,
            "versions and objects differ in length"
        );
        let live = self.objs.iter().filter(|o| o.node != NONE).count();
        assert_eq!(live, self.live, "live count");
        assert!(
            self.objs.last().is_none_or(|o| o.node != NONE),
            "a hole at the end"
        );
        let mut per_level = [0u32; MAX_DEPTH as usize + 1];
        let mut overflow = 0;
        for (id, o) in self.objs.iter().enumerate() {
            if o.node == NONE {
                assert_eq!(self.versions[id], 0, "a hole at id {id} keeps a key");
                continue;
            }
            let key = self.key_of(id as u32);
            assert_eq!(
                self.id_of(key),
                Some(id as u32),
                "key map disagrees at id {id}"
            );
            let (c, r) = (o.center, o.radius);
            let at = self.lattice.locate(c, r);
            self.lattice.check_rule(id, c, r, &at, o.node);
            assert_eq!(
                o.node,
                at.node(),
                "id {id} is not in the node placement gives"
            );
            assert_eq!(
                o.walk_key,
                self.lattice.walk_key(at.node()) as u32,
                "stale walk key at id {id}"
            );
            per_level[level_of(at.node()) as usize] += 1;
            overflow += u32::from(at.outside());
        }
        assert_eq!(per_level, self.per_level, "per-level counts disagree");
        assert_eq!(overflow, self.overflow, "overflow count disagrees");
        self.check_lists();
    }

    /// Walks every occupied node from the root through the child masks, checking each child
    /// bit and each node list.
    fn check_lists(&self) {
        let n = self.live;
        let mut reached = 0usize;
        let occupied = |child: &Cell| {
            assert!(
                !self.nodes.is_empty(child.node()),
                "the child bit of node {} is set but its subtree is empty",
                child.node()
            );
            true
        };
        self.nodes.walk(Cell::ROOT, occupied, |cell, slot| {
            let node = cell.node();
            let mut prev = NONE;
            let mut i = self.nodes.head_at(slot);
            while i != NONE {
                assert!(
                    self.objs.get(i as usize).is_some_and(|o| o.node != NONE),
                    "node {node} links to dead id {i}"
                );
                let o = &self.objs[i as usize];
                assert_eq!(
                    o.node, node,
                    "id {i} is listed in node {node} but names {}",
                    o.node
                );
                let link = self.links[i as usize];
                assert_eq!(link.prev, prev, "broken back link at id {i}");
                reached += 1;
                assert!(
                    reached <= n,
                    "node lists hold more entries than spheres (a cycle?)"
                );
                prev = i;
                i = link.next;
            }
            assert!(
                cell.level < self.lattice.depth || self.nodes.mask(node) == 0,
                "deepest node {node} has children"
            );
        });
        assert_eq!(reached, n, "some spheres are in no reachable node list");
    }
}

#[cfg(test)]
mod tests {
    use super::super::Octree;
    use crate::geom::Aabb;
    use glam::Vec3;

    #[test]
    #[should_panic(expected = "not in the node placement gives")]
    fn validate_catches_a_misplaced_sphere() {
        let mut t = Octree::new(Aabb::new(Vec3::splat(-1.0), Vec3::ONE), 3).unwrap();
        t.insert(Vec3::splat(0.5), 0.01).unwrap();
        t.objs[1].node = 0;
        t.validate();
    }

    #[test]
    fn validate_accepts_an_empty_deep_tree() {
        let t = Octree::new(Aabb::new(Vec3::splat(-1.0), Vec3::ONE), 10).unwrap();
        t.validate();
    }
}
