//! The pairs of a tree and of two trees found by several tasks at once (feature
//! `parallel`): the descents' first items expanded on the calling thread until none is heavy,
//! then taken by the tasks, heaviest first, from one shared counter.

use super::Bvh;
use super::pairs::{
    Noted, PairScratch, Tree, cross_children, drain_cross, drain_own, own_children,
};
use crate::pair::ProxyKey;

/// Scratch of [`Bvh::for_each_pair_split`], owned by its caller and reused: the items handed
/// out (each list with a second buffer for its next round), the order tasks take them in, and
/// one [`PairScratch`] per task.
#[derive(Clone, Debug, Default)]
pub(crate) struct SplitScratch {
    own: [Vec<(u32, u32)>; 2],
    cross: [Vec<(u32, u32)>; 2],
    /// `(weight, item)` of every item, heaviest first; `item` indexes `own` then `cross`.
    order: Vec<(u32, u32)>,
    tasks: Vec<PairScratch>,
}

impl SplitScratch {
    /// Heap bytes held (capacities).
    pub(crate) fn heap_bytes(&self) -> usize {
        (self.own.iter().chain(&self.cross))
            .map(|v| v.capacity() * 8)
            .sum::<usize>()
            + self.order.capacity() * 8
            + self.tasks.capacity() * core::mem::size_of::<PairScratch>()
            + self
                .tasks
                .iter()
                .map(PairScratch::heap_bytes)
                .sum::<usize>()
    }

    /// Expands the items of both descents over `ta` and `ta` × `tb` for `tasks` tasks and
    /// orders them heaviest first (see [`Bvh::for_each_pair_split`]).
    fn prepare(&mut self, ta: &Tree, tb: &Tree, tasks: usize) {
        let SplitScratch {
            own: [own, own_next],
            cross: [cross, cross_next],
            order,
            ..
        } = self;
        own.clear();
        cross.clear();
        let mut total = 0u64;
        if let Some(root) = ta.nodes.first() {
            own.push((0, 0));
            total += u64::from(own_weight(ta, 0, 0));
            if tb
                .nodes
                .first()
                .is_some_and(|r| r.bounds().overlaps(&root.bounds()))
            {
                cross.push((0, 0));
                total += u64::from(cross_weight(ta, tb, 0, 0));
            }
        }
        let limit = (total / (tasks * ITEMS_PER_TASK) as u64).max(1) as u32;
        while own.len() + cross.len() < tasks * MAX_ITEMS_PER_TASK {
            let grew_own = expand_own(ta, limit, own, own_next);
            let grew_cross = expand_cross(ta, tb, limit, cross, cross_next);
            if !(grew_own || grew_cross) {
                break;
            }
        }
        order.clear();
        order.extend(
            own.iter()
                .map(|&(a, b)| own_weight(ta, a, b))
                .chain(cross.iter().map(|&(a, b)| cross_weight(ta, tb, a, b)))
                .zip(0..),
        );
        order.sort_unstable_by(|x, y| y.cmp(x));
    }
}

/// Items a split pair pass aims to make per task: an item weighs at most the whole
/// descents' weight over this many per task, so that the threads, taking the heaviest items
/// first, end within about one light item of each other.
const ITEMS_PER_TASK: usize = 8;

/// The most items a split pair pass makes per task, whatever their weights (a cap on the
/// serial expansion for trees whose cross items stay heavy).
const MAX_ITEMS_PER_TASK: usize = 64;

impl Bvh {
    /// The pairs of [`Bvh::for_each_pair`] and of [`Bvh::for_each_pair_with`]`(other)`, found
    /// in `out.len()` tasks over rayon's current pool: task `c` calls `emit(&mut out[c], a, b)`
    /// for each pair it finds, `a` in `self` (each pair is found by one task, once; which one
    /// depends on the threads' timing).
    ///
    /// The items of both descents are first expanded on the calling thread (an item is
    /// replaced by its children's items, as the descents themselves do) until none weighs
    /// more than `1 / (tasks · ITEMS_PER_TASK)` of their total or can be expanded. An item's
    /// weight is the node count of its subtree, the smaller one's for a cross item: a self
    /// item's descent costs about that, and a cross item's no more than a descent of its
    /// smaller side. Items partition the pairs, so each task then takes items, heaviest first,
    /// from one shared counter, and runs the serial descents from each with its own stack:
    /// a thread that lags (or is not scheduled) takes fewer, and no thread waits at the end
    /// for more than one item of another. The pending boxes' pairs go to task 0 first.
    pub(crate) fn for_each_pair_split<S, E>(
        &self,
        other: &Bvh,
        scratch: &mut SplitScratch,
        out: &mut [S],
        emit: &E,
    ) where
        S: Send,
        E: Fn(&mut S, ProxyKey, ProxyKey) + Sync,
    {
        use core::sync::atomic::{AtomicUsize, Ordering};
        use rayon::prelude::*;
        debug_assert!(
            !(self.has_deferred() || other.has_deferred()),
            "pairs of a tree with deferred enlargements"
        );
        let tasks = out.len();
        if tasks == 0 {
            return;
        }
        let (ta, tb) = (Tree::of(self), Tree::of(other));
        scratch.prepare(&ta, &tb, tasks);
        let SplitScratch {
            own: [own, _],
            cross: [cross, _],
            order,
            tasks: scratches,
        } = scratch;
        if scratches.len() < tasks {
            scratches.resize_with(tasks, PairScratch::default);
        }
        let (own, cross, order) = (&own[..], &cross[..], &order[..]);
        let next = AtomicUsize::new(0);
        let (ta, tb) = (&ta, &tb);
        out.par_iter_mut()
            .zip(&mut scratches[..tasks])
            .enumerate()
            .for_each(|(c, (o, s))| {
                let mut f = |a, b| emit(o, a, b);
                if c == 0 {
                    self.pending_self_pairs(&mut s.sweep_a, &mut f);
                    self.pending_cross_pairs(other, s, &mut f);
                }
                let mut noted = Noted::new();
                while let Some(&(_, item)) = order.get(next.fetch_add(1, Ordering::Relaxed)) {
                    let item = item as usize;
                    s.stack.clear();
                    if let Some(&own_item) = own.get(item) {
                        s.stack.push(own_item);
                        drain_own(ta, &mut s.stack, &mut noted, &mut f);
                    } else {
                        s.stack.push(cross[item - own.len()]);
                        drain_cross(ta, tb, &mut s.stack, &mut noted, &mut f);
                    }
                }
            });
    }
}

/// The node count of the subtree of `n`: in the depth-first array it ends where the subtree
/// of its last second child, down the right spine, does.
fn subtree_nodes(t: &Tree, n: u32) -> u32 {
    let mut m = n;
    while !t.nodes[m as usize].is_leaf() {
        m = t.nodes[m as usize].first;
    }
    m + 1 - n
}

/// The weight of a self-traversal item (see [`Bvh::for_each_pair_split`]).
fn own_weight(t: &Tree, a: u32, b: u32) -> u32 {
    if a == b {
        subtree_nodes(t, a)
    } else {
        cross_weight(t, t, a, b)
    }
}

/// The weight of a cross item (see [`Bvh::for_each_pair_split`]).
fn cross_weight(ta: &Tree, tb: &Tree, a: u32, b: u32) -> u32 {
    subtree_nodes(ta, a).min(subtree_nodes(tb, b))
}

/// Replaces the self-traversal items of `cur` that weigh more than `limit` by their
/// children's items (see [`drain_own`]), the others kept, with `next` as the second buffer;
/// true if any item was replaced.
fn expand_own(t: &Tree, limit: u32, cur: &mut Vec<(u32, u32)>, next: &mut Vec<(u32, u32)>) -> bool {
    next.clear();
    let mut grew = false;
    for &(a, b) in cur.iter() {
        let na = &t.nodes[a as usize];
        let light = own_weight(t, a, b) <= limit;
        if !light && a == b && !na.is_leaf() {
            own_children(t, a, na, next);
            grew = true;
        } else if !light && a != b && !(na.is_leaf() && t.nodes[b as usize].is_leaf()) {
            cross_children(t, t, a, b, next);
            grew = true;
        } else {
            next.push((a, b));
        }
    }
    core::mem::swap(cur, next);
    grew
}

/// [`expand_own`] for the cross items of `ta` × `tb`.
fn expand_cross(
    ta: &Tree,
    tb: &Tree,
    limit: u32,
    cur: &mut Vec<(u32, u32)>,
    next: &mut Vec<(u32, u32)>,
) -> bool {
    next.clear();
    let mut grew = false;
    for &(a, b) in cur.iter() {
        let leaves = ta.nodes[a as usize].is_leaf() && tb.nodes[b as usize].is_leaf();
        if leaves || cross_weight(ta, tb, a, b) <= limit {
            next.push((a, b));
        } else {
            cross_children(ta, tb, a, b, next);
            grew = true;
        }
    }
    core::mem::swap(cur, next);
    grew
}

#[cfg(test)]
mod tests {
    use super::super::BvhConfig;
    use super::super::pairs::PairScratch;
    use super::*;
    use crate::geom::Aabb;
    use crate::pair::Pair;
    use crate::rng::Rng;
    use glam::Vec3;
    use slotmap::SlotMap;

    /// A tree of `n` random boxes built, then changed so that every kind of primitive is
    /// there: boxes moved out of their leaves, pending inserts and tombstones.
    fn changed_tree(rng: &mut Rng, keys: &mut SlotMap<ProxyKey, ()>, n: usize) -> Bvh {
        let random_box = |rng: &mut Rng| {
            let c = rng.vec3_in(Vec3::splat(-20.0), Vec3::splat(20.0));
            Aabb::new(c, c + rng.vec3_in(Vec3::splat(0.1), Vec3::splat(2.5)))
        };
        let mut bvh = Bvh::new(BvhConfig {
            rebuild_after_changes: f32::INFINITY,
            ..BvhConfig::default()
        })
        .unwrap();
        let mut live = Vec::new();
        for _ in 0..n {
            let k = keys.insert(());
            bvh.insert_keyed(k, random_box(rng)).unwrap();
            live.push(k);
        }
        bvh.rebuild();
        for &k in live.iter().step_by(7) {
            bvh.update(k, random_box(rng)).unwrap();
        }
        for &k in live.iter().skip(3).step_by(11) {
            bvh.remove(k).unwrap();
        }
        for _ in 0..n / 20 {
            bvh.insert_keyed(keys.insert(()), random_box(rng)).unwrap();
        }
        bvh.validate();
        bvh
    }

    /// The items are expanded by weight and taken heaviest first, so no item holds more than
    /// a small share of the pairs (contiguous stretches of items would leave the diagonal
    /// ones, which hold most of the pairs, to one or two tasks), and the items together hold
    /// each pair once.
    #[test]
    fn split_items_are_light() {
        let mut rng = Rng::new(31);
        let config = BvhConfig {
            max_leaf_size: 32,
            traversal_cost: 16.0,
            ..BvhConfig::default()
        };
        let spread = |rng: &mut Rng, n: usize, half: f32| -> Vec<Aabb> {
            (0..n)
                .map(|_| {
                    let c = rng.vec3_in(Vec3::splat(-half), Vec3::splat(half));
                    Aabb::new(c, c + rng.vec3_in(Vec3::splat(0.2), Vec3::splat(1.6)))
                })
                .collect()
        };
        let (a, _) = Bvh::from_aabbs(config, &spread(&mut rng, 6000, 30.0)).unwrap();
        let (b, _) = Bvh::from_aabbs(config, &spread(&mut rng, 600, 30.0)).unwrap();
        let (ta, tb) = (Tree::of(&a), Tree::of(&b));
        let mut want = Vec::new();
        a.for_each_pair_using(&mut PairScratch::default(), |x, y| {
            want.push(Pair::new(x, y));
        });
        a.for_each_pair_with_using(&b, &mut PairScratch::default(), |x, y| {
            want.push(Pair::new(x, y));
        });
        want.sort_unstable();
        let mut scratch = SplitScratch::default();
        for tasks in [2, 8, 32] {
            scratch.prepare(&ta, &tb, tasks);
            let SplitScratch {
                own: [own, _],
                cross: [cross, _],
                order,
                ..
            } = &scratch;
            assert!(order.windows(2).all(|w| w[0] >= w[1]), "heaviest first");
            let (mut got, mut most, mut stack) = (Vec::new(), 0, Vec::new());
            for &(_, item) in order {
                let before = got.len();
                let mut f = |x, y| got.push(Pair::new(x, y));
                let item = item as usize;
                if let Some(&own_item) = own.get(item) {
                    stack.push(own_item);
                    drain_own(&ta, &mut stack, &mut Noted::new(), &mut f);
                } else {
                    stack.push(cross[item - own.len()]);
                    drain_cross(&ta, &tb, &mut stack, &mut Noted::new(), &mut f);
                }
                most = most.max(got.len() - before);
            }
            got.sort_unstable();
            assert_eq!(got, want, "tasks {tasks}");
            assert!(
                most * 2 * tasks <= want.len(),
                "tasks {tasks}: one item holds {most} of {} pairs",
                want.len()
            );
        }
    }

    /// The split descents find each pair of `a` × `a` and `a` × `b` once, whatever the task
    /// and thread counts, as brute force over the live boxes does.
    #[test]
    fn split_descents_find_every_pair_once() {
        let mut rng = Rng::new(29);
        let mut scratch = SplitScratch::default();
        for (n, m) in [(0, 0), (0, 5), (1, 0), (6, 3), (300, 40), (3000, 400)] {
            let mut keys = SlotMap::with_key();
            let a = changed_tree(&mut rng, &mut keys, n);
            let b = changed_tree(&mut rng, &mut keys, m);
            let (mut boxes_a, mut boxes_b) = (Vec::new(), Vec::new());
            a.for_each(|k, x| boxes_a.push((k, x)));
            b.for_each(|k, x| boxes_b.push((k, x)));
            let mut want = Vec::new();
            for (i, (ka, xa)) in boxes_a.iter().enumerate() {
                for (kb, xb) in boxes_a[i + 1..].iter().chain(&boxes_b) {
                    if xa.overlaps(xb) {
                        want.push(Pair::new(*ka, *kb));
                    }
                }
            }
            want.sort_unstable();
            for threads in [1, 2, 3, 8] {
                let pool = rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .build()
                    .unwrap();
                for tasks in [1, 2, 3, 8, 33] {
                    let mut out = vec![Vec::new(); tasks];
                    pool.install(|| {
                        a.for_each_pair_split(&b, &mut scratch, &mut out, &|o, x, y| {
                            o.push(Pair::new(x, y));
                        });
                    });
                    let mut got: Vec<Pair> = out.concat();
                    got.sort_unstable();
                    assert_eq!(got, want, "n {n} m {m} threads {threads} tasks {tasks}");
                }
            }
        }
    }
}
