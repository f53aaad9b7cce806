//! Full (re)build: top-down splits (module `split`) over a flat array of boxes partitioned in
//! place, with an explicit work stack and buffers reused across builds.

use super::node::Node;
use super::split::{Bounds, Split, Work, split};
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

/// Pushes the two halves of task `t`, split by `sp`, as the children of node `index`: the
/// second child first, so the first is popped next and lands right after its parent.
fn push_children(tasks: &mut Vec<Task>, t: &Task, index: u32, sp: Split) {
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
    /// The parallel build's top of the tree and one set of buffers per subtree task.
    #[cfg(feature = "parallel")]
    top: Vec<TopItem>,
    #[cfg(feature = "parallel")]
    subtrees: Vec<Subtree>,
}

impl BuildScratch {
    /// Heap bytes held (capacities).
    pub(crate) fn heap_bytes(&self) -> usize {
        use core::mem::size_of;
        (self.ids.capacity() + self.new_pos.capacity()) * 4
            + self.tasks.capacity() * size_of::<Task>()
            + self.keys.capacity() * 8
            + self.work.heap_bytes()
            + self.parallel_heap_bytes()
    }

    #[cfg(feature = "parallel")]
    fn parallel_heap_bytes(&self) -> usize {
        use core::mem::size_of;
        self.top.capacity() * size_of::<TopItem>()
            + self.subtrees.capacity() * size_of::<Subtree>()
            + self.subtrees.iter().map(Subtree::heap_bytes).sum::<usize>()
    }

    #[cfg(not(feature = "parallel"))]
    fn parallel_heap_bytes(&self) -> usize {
        0
    }
}

impl Bvh {
    /// Rebuilds the whole tree from the current boxes with [`BvhConfig::split`]: pending
    /// inserts join the tree, tombstones are dropped, and the SAH cost is remembered as the
    /// reference for [`Bvh::refit`]'s quality check. Keys stay valid. O(n log n); allocates
    /// only when the tree grew past its largest size so far.
    pub fn rebuild(&mut self) {
        self.deferred.clear();
        let mut s = core::mem::take(&mut self.scratch);
        self.drop_tombstones(&mut s.ids);
        let n = self.boxes.len();
        self.nodes.clear();
        self.parent.clear();
        self.leaf_of.clear();
        self.leaf_of.resize(n, NONE);
        build_tree(
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

/// Builds the depth-first array over `refs`: over rayon's current pool for a large tree with
/// the feature `parallel` (the same tree as on one thread), else [`build_nodes`].
fn build_tree(
    config: &BvhConfig,
    s: &mut BuildScratch,
    refs: &mut [SimdBox],
    nodes: &mut Vec<Node>,
    parent: &mut Vec<u32>,
    leaf_of: &mut [u32],
) {
    #[cfg(feature = "parallel")]
    {
        let threads = rayon::current_num_threads();
        if threads > 1 && refs.len() >= PARALLEL_BUILD_MIN {
            build_parallel(config, s, refs, nodes, parent, leaf_of, threads);
            return;
        }
    }
    build_nodes(
        config,
        &mut s.tasks,
        &mut s.work,
        refs,
        &mut s.ids,
        nodes,
        parent,
        leaf_of,
        &Bounds::of(refs),
    );
}

/// Builds the depth-first array over `refs` (whose bounds are `root`), reordering `refs` and
/// `ids` into tree order;
/// appends to `nodes` and `parent` (the root's parent is `NONE`), leaf starts and `leaf_of`
/// relative to `refs`.
///
/// Depth-first order with an explicit stack: a task's node gets the next free index when it
/// is popped; a split pushes the second child, then the first, so the first child is popped
/// next and lands at `parent + 1`. The second child is popped once the whole first subtree is
/// placed, and writes its index into the parent's `first`.
#[allow(clippy::too_many_arguments)] // reason: the parallel build runs it on parts of each buffer
fn build_nodes(
    config: &BvhConfig,
    tasks: &mut Vec<Task>,
    work: &mut Work,
    refs: &mut [SimdBox],
    ids: &mut [u32],
    nodes: &mut Vec<Node>,
    parent: &mut Vec<u32>,
    leaf_of: &mut [u32],
    root: &Bounds,
) {
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
        bounds: *root,
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
                push_children(tasks, &t, index, sp);
            }
        }
    }
}

/// Trees of fewer primitives are built on one thread: below this, handing out subtrees costs
/// more than it saves.
#[cfg(feature = "parallel")]
const PARALLEL_BUILD_MIN: usize = 1 << 15;

/// Subtrees the parallel build aims to hand each thread: their sizes differ (a split need not
/// halve), and rayon's work stealing evens the threads out only when each has several.
#[cfg(feature = "parallel")]
const SUBTREES_PER_THREAD: usize = 4;

/// One node of the parallel build's top, in depth-first order: an interior node split on the
/// calling thread, or a subtree left to a task. `parent` indexes the top; `second` as in
/// [`Task`].
#[cfg(feature = "parallel")]
#[derive(Clone, Copy, Debug)]
enum TopItem {
    Interior {
        aabb: crate::geom::Aabb,
        parent: u32,
        second: bool,
    },
    Subtree {
        task: Task,
    },
}

/// One subtree task's buffers, reused across builds: its stack and split scratch, and the
/// nodes it built (depth-first, indices and leaf starts relative to the subtree).
#[cfg(feature = "parallel")]
#[derive(Clone, Debug, Default)]
struct Subtree {
    tasks: Vec<Task>,
    work: Work,
    nodes: Vec<Node>,
    parent: Vec<u32>,
}

#[cfg(feature = "parallel")]
impl Subtree {
    fn heap_bytes(&self) -> usize {
        use core::mem::size_of;
        self.tasks.capacity() * size_of::<Task>()
            + self.work.heap_bytes()
            + self.nodes.capacity() * size_of::<Node>()
            + self.parent.capacity() * 4
    }
}

/// [`build_nodes`] over rayon's current pool, giving the same tree.
///
/// The top of the tree is split on the calling thread, in the same depth-first order as
/// [`build_nodes`], down to nodes of at most `n / (SUBTREES_PER_THREAD · threads)` primitives;
/// each such node becomes a subtree task. The tasks' primitive ranges are disjoint and, in
/// depth-first order, consecutive, so the boxes, ids and `leaf_of` are cut into one part per
/// task, and each task runs [`build_nodes`] on its parts with its own buffers. A node's split
/// depends only on its own primitives, so every node comes out as the serial build makes it.
/// Last, the top is written out in depth-first order with each subtree's nodes copied in at its
/// place, their indices shifted to where they landed.
#[cfg(feature = "parallel")]
fn build_parallel(
    config: &BvhConfig,
    s: &mut BuildScratch,
    refs: &mut [SimdBox],
    nodes: &mut Vec<Node>,
    parent: &mut Vec<u32>,
    leaf_of: &mut [u32],
    threads: usize,
) {
    let cutoff = (refs.len() / (SUBTREES_PER_THREAD * threads)).max(config.max_leaf_size as usize);
    split_top(config, s, refs, cutoff);
    build_subtrees(config, s, refs, leaf_of);
    write_top(&s.top, &s.subtrees, nodes, parent, leaf_of);
}

/// The top of the tree, split on the calling thread in [`build_nodes`]' depth-first order
/// into `s.top`: interior nodes, and a subtree task for each node of at most `cutoff`
/// primitives (or that does not split).
#[cfg(feature = "parallel")]
fn split_top(config: &BvhConfig, s: &mut BuildScratch, refs: &mut [SimdBox], cutoff: usize) {
    let BuildScratch {
        ids,
        tasks,
        work,
        top,
        ..
    } = s;
    work.prepare();
    top.clear();
    tasks.clear();
    tasks.push(Task {
        start: 0,
        end: refs.len() as u32,
        parent: NONE,
        second: false,
        bounds: Bounds::of(refs),
    });
    while let Some(t) = tasks.pop() {
        let index = top.len() as u32;
        let range = t.start as usize..t.end as usize;
        let sp = if range.len() <= cutoff {
            None
        } else {
            split(
                config,
                work,
                &mut refs[range.clone()],
                &mut ids[range.clone()],
                &t.bounds,
            )
        };
        // A top node that does not split is a subtree of one leaf, which its task makes.
        let Some(sp) = sp else {
            top.push(TopItem::Subtree { task: t });
            continue;
        };
        top.push(TopItem::Interior {
            aabb: t.bounds.boxes.aabb(),
            parent: t.parent,
            second: t.second,
        });
        push_children(tasks, &t, index, sp);
    }
}

/// Builds the subtrees of `s.top`'s tasks over rayon's current pool, each on its own part of
/// the buffers (the parts are consecutive in depth-first order) into its own `s.subtrees`.
#[cfg(feature = "parallel")]
fn build_subtrees(
    config: &BvhConfig,
    s: &mut BuildScratch,
    refs: &mut [SimdBox],
    leaf_of: &mut [u32],
) {
    use rayon::prelude::*;
    let BuildScratch {
        ids, top, subtrees, ..
    } = s;
    let count = top
        .iter()
        .filter(|i| matches!(i, TopItem::Subtree { .. }))
        .count();
    if subtrees.len() < count {
        subtrees.resize_with(count, Subtree::default);
    }
    let mut parts = Vec::with_capacity(count);
    let (mut r, mut i, mut l) = (&mut refs[..], &mut ids[..], &mut leaf_of[..]);
    for item in top.iter() {
        if let TopItem::Subtree { task } = item {
            let len = (task.end - task.start) as usize;
            let (r0, r1) = core::mem::take(&mut r).split_at_mut(len);
            let (i0, i1) = core::mem::take(&mut i).split_at_mut(len);
            let (l0, l1) = core::mem::take(&mut l).split_at_mut(len);
            parts.push((*task, r0, i0, l0));
            (r, i, l) = (r1, i1, l1);
        }
    }
    parts
        .into_par_iter()
        .zip(subtrees[..count].par_iter_mut())
        .for_each(|((task, r, i, l), sub)| {
            let Subtree {
                tasks,
                work,
                nodes,
                parent,
            } = sub;
            nodes.clear();
            parent.clear();
            build_nodes(config, tasks, work, r, i, nodes, parent, l, &task.bounds);
        });
}

/// Writes the top in depth-first order into `nodes` and `parent`, each subtree's nodes copied
/// in at its place with their indices shifted to where they landed (and `leaf_of` with them).
#[cfg(feature = "parallel")]
fn write_top(
    top: &[TopItem],
    subtrees: &[Subtree],
    nodes: &mut Vec<Node>,
    parent: &mut Vec<u32>,
    leaf_of: &mut [u32],
) {
    // `place[k]`: where top item `k` landed (an interior item's node, or a subtree's root).
    let mut place = Vec::with_capacity(top.len());
    let mut next_subtree = 0;
    for item in top {
        let index = nodes.len() as u32;
        place.push(index);
        let (p, second) = match *item {
            TopItem::Interior {
                aabb,
                parent: p,
                second,
            } => {
                nodes.push(Node::interior(&aabb));
                parent.push(top_parent(&place, p));
                (p, second)
            }
            TopItem::Subtree { task } => {
                let sub = &subtrees[next_subtree];
                next_subtree += 1;
                let p_node = top_parent(&place, task.parent);
                nodes.extend(sub.nodes.iter().map(|n| {
                    let mut n = *n;
                    n.first += if n.is_leaf() { task.start } else { index };
                    n
                }));
                parent.extend(
                    sub.parent
                        .iter()
                        .map(|&q| if q == NONE { p_node } else { q + index }),
                );
                let range = task.start as usize..task.end as usize;
                leaf_of[range].iter_mut().for_each(|x| *x += index);
                (task.parent, task.second)
            }
        };
        if second {
            nodes[place[p as usize] as usize].first = index;
        }
    }
}

/// The node a top item's parent (an index into the top, or `NONE`) landed at.
#[cfg(feature = "parallel")]
fn top_parent(place: &[u32], p: u32) -> u32 {
    if p == NONE { NONE } else { place[p as usize] }
}

#[cfg(all(test, feature = "parallel"))]
mod tests {
    use super::super::SplitMethod;
    use super::*;
    use crate::geom::Aabb;
    use crate::rng::Rng;
    use glam::Vec3;

    /// The tree's arrays that a build writes: nodes, parents, leaf of each box, keys, boxes.
    type Built = (Vec<Node>, Vec<u32>, Vec<u32>, Vec<ProxyKey>, Vec<SimdBox>);

    /// The tree's arrays that a build writes, for comparing two builds.
    fn built(bvh: &Bvh) -> Built {
        (
            bvh.nodes.clone(),
            bvh.parent.clone(),
            bvh.leaf_of.clone(),
            bvh.keys.clone(),
            bvh.boxes.clone(),
        )
    }

    /// The parallel build makes the very tree of the serial one (nodes, parents, primitive
    /// order, keys) at any thread count, for a first build and a rebuild after churn, for
    /// spread, clustered and coincident boxes and every split method; `validate()` holds.
    #[test]
    fn parallel_build_is_the_serial_build() {
        let n = PARALLEL_BUILD_MIN + 5_000;
        let mut rng = Rng::new(29);
        let spread = |rng: &mut Rng| {
            let c = rng.vec3_in(Vec3::splat(-60.0), Vec3::splat(60.0));
            Aabb::new(c, c + rng.vec3_in(Vec3::splat(0.1), Vec3::splat(2.5)))
        };
        let inputs: [Vec<Aabb>; 3] = [
            (0..n).map(|_| spread(&mut rng)).collect(),
            // Four tight clusters: many equal-width buckets stay empty.
            (0..n)
                .map(|i| {
                    let c =
                        Vec3::splat((i % 4) as f32 * 1000.0) + rng.vec3_in(Vec3::ZERO, Vec3::ONE);
                    Aabb::new(c, c + Vec3::splat(0.5))
                })
                .collect(),
            vec![Aabb::new(Vec3::ONE, Vec3::splat(2.0)); n],
        ];
        let pools: Vec<rayon::ThreadPool> = [1, 2, 3, 8]
            .iter()
            .map(|&t| {
                rayon::ThreadPoolBuilder::new()
                    .num_threads(t)
                    .build()
                    .unwrap()
            })
            .collect();
        for split in [
            SplitMethod::Sah,
            SplitMethod::Middle,
            SplitMethod::EqualCounts,
        ] {
            let config = BvhConfig {
                split,
                ..BvhConfig::default()
            };
            for (k, aabbs) in inputs.iter().enumerate() {
                let mut want = None;
                for pool in &pools {
                    let (mut bvh, keys) = pool.install(|| Bvh::from_aabbs(config, aabbs)).unwrap();
                    bvh.validate();
                    let first = built(&bvh);
                    // Churn, then a rebuild from the last tree order.
                    let mut r = Rng::new(k as u64);
                    for key in keys.iter().step_by(3) {
                        bvh.update(*key, spread(&mut r)).unwrap();
                    }
                    for key in keys.iter().skip(1).step_by(17) {
                        bvh.remove(*key).unwrap();
                    }
                    pool.install(|| bvh.rebuild());
                    bvh.validate();
                    let got = (first, built(&bvh));
                    match &want {
                        None => want = Some(got),
                        Some(w) => assert!(
                            *w == got,
                            "{split:?} input {k}: {} threads built another tree",
                            pool.current_num_threads()
                        ),
                    }
                }
            }
        }
    }
}
