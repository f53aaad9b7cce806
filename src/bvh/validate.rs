//! The whole-tree invariant check tests run after every mutation.

use super::{Bvh, NONE};
use slotmap::Key;

impl Bvh {
    /// Panics with a message naming the broken invariant unless: the side arrays agree in
    /// length; every node is reached from the root exactly once, in depth-first layout (first
    /// child at `n + 1`, second child after it, `parent` pointing back); every node box
    /// contains its children's boxes and every leaf box its primitives' current boxes; every
    /// tree primitive lies in exactly one leaf and `leaf_of` names it; keys and the key map
    /// agree; tombstones hold [`Aabb::EMPTY`](crate::Aabb::EMPTY) and live boxes are finite
    /// and not inverted. O(n); for tests and debugging.
    #[doc(hidden)]
    pub fn validate(&self) {
        assert!(
            self.deferred.is_empty(),
            "leaves grown by update_box_deferred whose ancestors were not grown"
        );
        let n_nodes = self.nodes.len();
        assert_eq!(
            self.keys.len(),
            self.boxes.len(),
            "keys and boxes differ in length"
        );
        assert!(
            self.tree_len <= self.boxes.len(),
            "tree_len past the primitives"
        );
        assert_eq!(
            self.parent.len(),
            n_nodes,
            "parent and nodes differ in length"
        );
        assert_eq!(
            self.leaf_of.len(),
            self.tree_len,
            "leaf_of and tree_len differ"
        );
        assert_eq!(
            n_nodes == 0,
            self.tree_len == 0,
            "nodes exist iff tree primitives do"
        );
        self.check_nodes();
        self.check_primitives();
        assert_eq!(self.lanes.len(), self.tree_len, "lanes and tree_len differ");
        for (i, b) in self.boxes[..self.tree_len].iter().enumerate() {
            assert_eq!(
                self.lanes.get(i),
                *b,
                "primitive {i}: lanes differ from its box"
            );
        }
    }

    /// Walks the tree from the root: depth-first layout, parent links, boxes containing their
    /// children and primitives, every node and tree primitive reached once.
    fn check_nodes(&self) {
        let n_nodes = self.nodes.len();
        let mut node_seen = vec![false; n_nodes];
        let mut prim_seen = vec![false; self.tree_len];
        let mut stack = Vec::new();
        if n_nodes > 0 {
            assert_eq!(self.parent[0], NONE, "the root has a parent");
            stack.push(0u32);
        }
        while let Some(n) = stack.pop() {
            let nu = n as usize;
            assert!(!node_seen[nu], "node {n} reached twice");
            node_seen[nu] = true;
            let node = &self.nodes[nu];
            let aabb = node.aabb();
            if node.is_leaf() {
                let range = node.range();
                assert!(
                    range.end <= self.tree_len,
                    "leaf {n} range {range:?} out of the tree"
                );
                for i in range {
                    assert!(!prim_seen[i], "primitive {i} in two leaves");
                    prim_seen[i] = true;
                    assert_eq!(self.leaf_of[i], n, "leaf_of[{i}] does not name leaf {n}");
                    assert!(
                        aabb.contains(&self.boxes[i].aabb()),
                        "leaf {n} box {aabb:?} does not contain primitive {i} box {:?}",
                        self.boxes[i]
                    );
                }
            } else {
                let (a, b) = node.children(n);
                assert!(
                    (b as usize) < n_nodes && b > a,
                    "interior {n}: second child {b} not after the first {a}"
                );
                for c in [a, b] {
                    assert_eq!(self.parent[c as usize], n, "parent of {c} is not {n}");
                    let child = self.nodes[c as usize].aabb();
                    assert!(
                        aabb.contains(&child),
                        "node {n} box {aabb:?} does not contain child {c} box {child:?}"
                    );
                    stack.push(c);
                }
            }
        }
        if let Some(n) = node_seen.iter().position(|&s| !s) {
            panic!("node {n} is unreachable");
        }
        if let Some(i) = prim_seen.iter().position(|&s| !s) {
            panic!("tree primitive {i} is in no leaf");
        }
    }

    /// Keys against the key map, tombstones against their count and box, live boxes valid.
    fn check_primitives(&self) {
        let mut live = 0;
        let mut tombstones = 0;
        for (i, (key, aabb)) in self.keys.iter().zip(&self.boxes).enumerate() {
            if key.is_null() {
                assert!(i < self.tree_len, "pending primitive {i} is a tombstone");
                assert_eq!(
                    *aabb,
                    crate::geom::SimdBox::EMPTY,
                    "tombstone {i} has a box"
                );
                tombstones += 1;
                continue;
            }
            live += 1;
            assert_eq!(
                self.ids.get(*key),
                Some(&(i as u32)),
                "key map disagrees at {i}"
            );
            assert!(
                crate::geom::check_aabb(&aabb.aabb()).is_ok(),
                "live primitive {i} has a bad box {aabb:?}"
            );
        }
        assert_eq!(live, self.ids.len(), "key map holds keys of no primitive");
        assert_eq!(tombstones, self.tombstones, "tombstone count is off");
    }
}
