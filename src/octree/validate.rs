//! The whole-tree invariant check.

use super::place::node_index;
use super::{MAX_DEPTH, NONE, Octree, Placement};

impl Octree {
    /// Checks every invariant and panics with a message naming the first one broken: each
    /// sphere's box, cell range, node and walk key are what placement gives for its stored
    /// sphere; in loose mode, every sphere outside the root has its centre in its node's cell,
    /// its radius within half the cell size, its box's grid range inside the node's loose
    /// bounds, and no deeper level would take it; every node list is doubly linked and reaches exactly the spheres that name its node; a child
    /// bit is set iff the child's subtree holds a sphere; per-level, overflow and key-map counts
    /// agree. O(n + occupied nodes); for tests and debugging.
    pub fn validate(&self) {
        let n = self.objs.len();
        assert_eq!(
            self.spheres.len(),
            n,
            "spheres and objects differ in length"
        );
        assert_eq!(self.keys.len(), n, "keys and objects differ in length");
        assert_eq!(self.ids.len(), n, "key map and objects differ in length");
        let mut per_level = [0u32; MAX_DEPTH as usize + 1];
        let mut overflow = 0;
        for (id, o) in self.objs.iter().enumerate() {
            let key = self.keys[id];
            assert_eq!(
                self.ids.get(key),
                Some(&(id as u32)),
                "key map disagrees at id {id}"
            );
            let (c, r) = self.spheres[id];
            let (aabb, qmin, qmax, node, outside) = self.locate(c, r);
            assert_eq!(o.aabb, aabb, "stored box of id {id} is not centre ± radius");
            assert_eq!(
                (o.qmin, o.qmax),
                (qmin, qmax),
                "stale cell range at id {id}"
            );
            if self.placement == Placement::Loose {
                self.check_loose_rule(id, o.node, outside);
            }
            assert_eq!(o.node, node, "id {id} is not in the node placement gives");
            assert_eq!(o.walk_key, self.walk_key(node), "stale walk key at id {id}");

            per_level[self.nodes.level_of(node) as usize] += 1;
            overflow += u32::from(outside);
        }
        assert_eq!(per_level, self.per_level, "per-level counts disagree");
        assert_eq!(overflow, self.overflow, "overflow count disagrees");

        // Walk every occupied node from the root through the child masks.
        let mut reached = 0usize;
        let mut stack = vec![(0u32, 0u32)];
        while let Some((level, code)) = stack.pop() {
            let node = node_index(level, code);
            let mut prev = NONE;
            let mut i = self.nodes.head(node);
            while i != NONE {
                assert!((i as usize) < n, "node {node} links to dead id {i}");
                let o = &self.objs[i as usize];
                assert_eq!(
                    o.node, node,
                    "id {i} is listed in node {node} but names {}",
                    o.node
                );
                assert_eq!(o.prev, prev, "broken back link at id {i}");
                reached += 1;
                assert!(
                    reached <= n,
                    "node lists hold more entries than spheres (a cycle?)"
                );
                prev = i;
                i = o.next;
            }
            let mask = self.nodes.mask(node);
            assert!(
                level < self.depth || mask == 0,
                "deepest node {node} has children"
            );
            for c in 0..8 {
                if mask & (1 << c) != 0 {
                    let child = node_index(level + 1, code * 8 + c);
                    assert!(
                        !self.nodes.is_empty(child),
                        "child bit {c} of node {node} is set but its subtree is empty"
                    );
                    stack.push((level + 1, code * 8 + c));
                }
            }
        }
        assert_eq!(reached, n, "some spheres are in no reachable node list");
    }
}

impl Octree {
    /// The loose placement rule for sphere `id` in `node`, checked from the definitions
    /// rather than by re-running the O(1) placement.
    fn check_loose_rule(&self, id: usize, node: u32, outside: bool) {
        let (c, r) = self.spheres[id];
        let o = &self.objs[id];
        let level = self.nodes.level_of(node);
        let code = node - node_index(level, 0);
        let cell = [0, 1, 2].map(|a| super::place::compact3(code >> a));
        let fits = |l: u32| r <= self.half_cell[l as usize];
        let qc = self.quantize(c);
        // How far the box's grid range reaches from the centre's grid cell: the range fits the
        // loose bounds of any level-`L` cell holding the centre iff this is `<= 2^(depth − L)`.
        let reach = (0..3)
            .map(|a| {
                u32::from(qc[a] - o.qmin[a].min(qc[a])).max(u32::from(o.qmax[a].max(qc[a]) - qc[a]))
            })
            .max()
            .unwrap_or(0);
        let reach_fits = |l: u32| reach <= 1 << (self.depth - l);
        if outside {
            assert_eq!(node, 0, "overflow sphere {id} is not in the root");
            assert!(
                !fits(0) || !self.bounds.contains_point(c) || !reach_fits(0),
                "sphere {id} fits the root but is counted as overflow"
            );
            return;
        }
        assert!(
            self.bounds.contains_point(c),
            "sphere {id} has its centre outside the bounds but is not overflow"
        );
        assert!(fits(level), "sphere {id} is too big for level {level}");
        let s = self.grid - level;
        let size = 1i64 << s;
        for a in 0..3 {
            assert_eq!(
                u32::from(qc[a]) >> s,
                cell[a],
                "sphere {id}'s centre is not in its node's cell"
            );
            let lo = i64::from(cell[a]) * size - size / 2;
            let hi = i64::from(cell[a]) * size + size - 1 + size / 2;
            assert!(
                lo <= i64::from(o.qmin[a]) && i64::from(o.qmax[a]) <= hi,
                "sphere {id}'s box leaves its node's loose bounds"
            );
        }
        assert!(
            level == self.depth || !fits(level + 1) || !reach_fits(level + 1),
            "sphere {id} would fit a deeper level than {level}"
        );
    }
}

#[cfg(test)]
mod tests {
    use crate::octree::Octree;
    use crate::{Aabb, Vec3};

    #[test]
    #[should_panic(expected = "not in the node placement gives")]
    fn validate_catches_a_misplaced_sphere() {
        let mut t = Octree::new(Aabb::new(Vec3::splat(-1.0), Vec3::ONE), 3).unwrap();
        t.insert(Vec3::splat(0.5), 0.01).unwrap();
        t.objs[0].node = 0;
        t.validate();
    }

    #[test]
    fn validate_accepts_an_empty_deep_tree() {
        let t = Octree::new(Aabb::new(Vec3::splat(-1.0), Vec3::ONE), 10).unwrap();
        t.validate();
    }
}
