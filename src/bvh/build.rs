//! Full (re)build: top-down splits (module `split`) over a flat array of boxes partitioned in
//! place, with an explicit work stack and buffers reused across builds.

use super::node::Node;
use super::split::{Bounds, Work, split};
use super::{Bvh, BvhConfig, NONE};
use crate::geom::SimdBox;
use crate::pair::ProxyKey;
use slotmap::Key;

/// A node still to be made: the primitive range `start..end`, the parent to link it to, and
/// the bounds of its boxes and centroids (computed by whoever split the parent).
#[derive(Clone, Copy, Debug)]
struct Task {
    start: u32,
    end: u32,
    parent: u32,
    /// True for a second child: its index must be written into the parent's `first`.
    second: bool,
    bounds: Bounds,
}

/// Buffers every build reuses, so a rebuild allocates only when the tree grew.
#[derive(Clone, Debug, Default)]
pub(crate) struct BuildScratch {
    /// `ids[i]`: the primitive index (before the build) of the box now at `boxes[i]`.
    ids: Vec<u32>,
    tasks: Vec<Task>,
    keys: Vec<ProxyKey>,
    /// By primitive index before the build: its index after (`NONE` for a tombstone).
    new_pos: Vec<u32>,
    work: Work,
}

impl BuildScratch {
    /// Heap bytes held (capacities).
    pub(crate) fn heap_bytes(&self) -> usize {
        use core::mem::size_of;
        (self.ids.capacity() + self.new_pos.capacity()) * 4
            + self.tasks.capacity() * size_of::<Task>()
            + self.keys.capacity() * 8
            + self.work.heap_bytes()
    }
}

impl Bvh {
    /// Rebuilds the whole tree from the current boxes with [`BvhConfig::split`]: pending
    /// inserts join the tree, tombstones are dropped, and the SAH cost is remembered as the
    /// reference for [`Bvh::refit`]'s quality check. Keys stay valid. O(n log n); allocates
    /// only when the tree grew past its largest size so far.
    pub fn rebuild(&mut self) {
        let mut s = core::mem::take(&mut self.scratch);
        self.drop_tombstones(&mut s.ids);
        let n = self.boxes.len();
        self.nodes.clear();
        self.parent.clear();
        self.leaf_of.clear();
        self.leaf_of.resize(n, NONE);
        build_nodes(
            &self.config,
            &mut s,
            &mut self.boxes,
            &mut self.nodes,
            &mut self.parent,
            &mut self.leaf_of,
        );
        self.renumber(&mut s);
        self.lanes.fill(&self.boxes[..n]);
        self.tree_len = n;
        self.tombstones = 0;
        self.cost_at_build = self.sah_cost();
        self.cost_last = self.cost_at_build;
        self.rebuilds += 1;
        self.scratch = s;
    }

    /// Drops the tombstones' boxes (the build partitions `boxes` itself), noting in `ids` the
    /// primitive index each remaining box came from.
    fn drop_tombstones(&mut self, ids: &mut Vec<u32>) {
        ids.clear();
        if self.tombstones == 0 {
            ids.extend(0..self.boxes.len() as u32);
            return;
        }
        let mut n = 0;
        for i in 0..self.boxes.len() {
            if !self.keys[i].is_null() {
                self.boxes[n] = self.boxes[i];
                ids.push(i as u32);
                n += 1;
            }
        }
        self.boxes.truncate(n);
    }

    /// Renumbers the primitives after a build (`s.ids[i]`: the old index of the box now at
    /// `i`): primitive index = position in tree order, so a leaf's range indexes `boxes` and
    /// `keys` directly and traversals read contiguous memory.
    /// - The new position of each old primitive is noted first, then the old keys are read in
    ///   their own order and stored at their new places: stores to scattered places stall less
    ///   than loads from them (a first build's keys lie in insertion order, so its map updates
    ///   go in order too).
    /// - A rebuild of a tree whose boxes barely moved leaves most primitives in place, and
    ///   their entries in `ids` need no update.
    /// - Both buffers are overwritten whole (with no tombstones every old index gets a new one;
    ///   the live keys fill `0..n`), so they are only resized, which writes nothing when the
    ///   length stays.
    fn renumber(&mut self, s: &mut BuildScratch) {
        if self.tombstones != 0 {
            s.new_pos.clear();
        }
        s.new_pos.resize(self.keys.len(), NONE);
        for (i, &old) in s.ids.iter().enumerate() {
            s.new_pos[old as usize] = i as u32;
        }
        s.keys.resize(self.boxes.len(), ProxyKey::null());
        for (old, (&key, &i)) in self.keys.iter().zip(&s.new_pos).enumerate() {
            // Tombstones (null keys) got no new position.
            if i != NONE {
                s.keys[i as usize] = key;
                if i != old as u32 {
                    self.ids[key] = i;
                }
            }
        }
        core::mem::swap(&mut self.keys, &mut s.keys);
    }
}

/// Builds the depth-first array over `refs`, reordering `refs` and `s.ids` into tree order.
///
/// Depth-first order with an explicit stack: a task's node gets the next free index when it
/// is popped; a split pushes the second child, then the first, so the first child is popped
/// next and lands at `parent + 1`. The second child is popped once the whole first subtree is
/// placed, and writes its index into the parent's `first`.
fn build_nodes(
    config: &BvhConfig,
    s: &mut BuildScratch,
    refs: &mut [SimdBox],
    nodes: &mut Vec<Node>,
    parent: &mut Vec<u32>,
    leaf_of: &mut [u32],
) {
    let BuildScratch {
        ids, tasks, work, ..
    } = s;
    if refs.is_empty() {
        return;
    }
    work.prepare();
    tasks.clear();
    tasks.push(Task {
        start: 0,
        end: refs.len() as u32,
        parent: NONE,
        second: false,
        bounds: Bounds::of(refs),
    });
    while let Some(t) = tasks.pop() {
        let index = nodes.len() as u32;
        if t.second {
            nodes[t.parent as usize].first = index;
        }
        parent.push(t.parent);
        let range = t.start as usize..t.end as usize;
        let aabb = t.bounds.boxes.aabb();
        match split(
            config,
            work,
            &mut refs[range.clone()],
            &mut ids[range.clone()],
            &t.bounds,
        ) {
            None => {
                nodes.push(Node::leaf(&aabb, t.start, t.end - t.start));
                leaf_of[range].fill(index);
            }
            Some(sp) => {
                nodes.push(Node::interior(&aabb));
                let mid = t.start + sp.mid as u32;
                tasks.push(Task {
                    start: mid,
                    end: t.end,
                    parent: index,
                    second: true,
                    bounds: sp.right,
                });
                tasks.push(Task {
                    start: t.start,
                    end: mid,
                    parent: index,
                    second: false,
                    bounds: sp.left,
                });
            }
        }
    }
}
