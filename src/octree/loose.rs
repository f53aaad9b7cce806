//! All overlapping pairs of a [`Placement::Loose`](super::Placement::Loose) tree: same-level
//! neighbours, then cross-level pairs through the neighbours' occupied subtrees.
//!
//! Why neighbours suffice. On the integer grid (see `Octree::loose_node`) a sphere's range
//! lies inside its node's loose range `[k·S − S/2, k·S + S − 1 + S/2]` (cell `k`, `S` grid
//! cells per level-`L` cell), and a node's loose range lies inside its parent's. Overlapping
//! boxes have overlapping ranges, so if `a` at level `L` overlaps `b` at level `L' >= L`, the
//! loose range of `a`'s cell overlaps that of `b`'s level-`L` ancestor cell `k'`. Two level-`L`
//! loose ranges overlap iff `|k − k'|·S <= 2S − 1`, i.e. iff `|k − k'| <= 1` on every axis: `b`'s
//! node is in the subtree of one of the 27 cells around `a`'s (its own included).
//!
//! The pass. The spheres are radix-sorted by their node's key (`Octree::walk_key`: level,
//! then the cell in row-major order), so each occupied node is a run of the sorted array and a
//! level's nodes come in rows along x. Then, per occupied node:
//! - the pairs within its run (a sweep along x when long);
//! - the pairs with the 13 "forward" same-level neighbours, the offsets `(dx, dy, dz)` with
//!   `(dz, dy, dx)` lexicographically positive: of two neighbouring nodes exactly one sees the
//!   other forward, so each same-level pair is found once. They are the next node of the same
//!   row (`dx = 1`) and the cells `x − 1 ..= x + 1` of four rows, `(dy, dz)` = `(1, 0)`,
//!   `(−1, 1)`, `(0, 1)`, `(1, 1)`. The three cells of a row are one stretch of the sorted
//!   spheres, found by two pointers into the sorted runs per row; the keys they look for grow
//!   with the node's key, so each pointer passes over the runs once per pass, and no neighbour
//!   is looked up in the node storage. A run of a few spheres first lists the spheres of the
//!   five short stretches (most hold 0–2) and tests each own sphere against the list in one
//!   loop: a loop per stretch mispredicted its end about once per stretch. A run of many
//!   spheres (a crowded level: a settled pile holds ~8 per node) lists only the stretches'
//!   spheres that reach the union of its own boxes, one test each, and tests its spheres
//!   against those: in a pile about a third of them;
//! - if some sphere lives deeper, the pairs with every sphere deeper than the node in the
//!   subtrees of the 27 cells around it, found by descending the occupied subtrees (child
//!   masks) and pruning every node whose loose range misses the union of the run's ranges
//!   (which holds every range the run overlaps). A cross-level pair is found only from its
//!   shallower sphere's node, through the one neighbour cell that is its deeper sphere's
//!   ancestor, so once. Only then are the runs recorded in a per-node slot of the paged node
//!   storage (and cleared after the pass), for the descent to find them.
//!
//! Overflow spheres sit in the root, whose 27-cell neighbourhood is the root itself: they are
//! tested against the whole tree pruned by their clamped ranges, which overlap the range of
//! everything their boxes overlap.

use super::pairs::{self, Hot, SHORT_CROSS, SHORT_SELF, SHORT_SIDE, Tester, Work, entry, ord};
use super::place::{morton, node_index};
use super::{MAX_DEPTH, Octree};
use crate::ProxyKey;

/// The four forward neighbour rows `(dy, dz)` of a cell (see the module docs).
const ROWS: [[i32; 2]; 4] = [[1, 0], [-1, 1], [0, 1], [1, 1]];

/// Runs of at most this many spheres test their forward neighbours through one list.
const NEAR_OWN: usize = 4;
/// Neighbour ranges of at most this many spheres go into that list, longer ones are tested
/// on their own.
const NEAR_RANGE: usize = 4;
/// The list's room: every range at its longest, and the slack of the last range's writes.
const NEAR_CAP: usize = (1 + ROWS.len()) * NEAR_RANGE + NEAR_RANGE;

/// Buffers of the loose pair pass, reused by every pass; they never shrink.
#[derive(Clone, Debug, Default)]
pub(super) struct Scratch {
    /// The occupied nodes of a pass, in key order: node `k` has key `run_key[k]` and the sorted
    /// spheres `run_start[k]..run_start[k + 1]`; a sentinel ends both (key `u64::MAX`, start
    /// the sphere count). `run_slot[k]` is its slot in the node storage, filled only when some
    /// level below it is occupied.
    run_key: Vec<u64>,
    run_start: Vec<u32>,
    run_slot: Vec<u32>,
    /// By node slot ([`super::place::Nodes::slot`]): the node's run `[start, end)` during a
    /// pass, `[0, 0]` otherwise. Grows with the node pages.
    run_of: Vec<[u32; 2]>,
    /// The neighbours of a crowded run that reach its union box, as positions in the
    /// sorted spheres.
    dense: Vec<u32>,
}

/// The level and cell of a loose tree's node key (`Octree::walk_key`) in a tree of depth `d`.
#[inline]
fn cell_of(key: u64, d: u32) -> (u32, [u32; 3]) {
    let level = (key >> (3 * d)) as u32;
    let mask = (1u32 << level) - 1;
    let cell = key as u32;
    (
        level,
        [
            cell & mask,
            (cell >> level) & mask,
            (cell >> (2 * level)) & mask,
        ],
    )
}

/// A node on the descent stack.
#[derive(Clone, Copy, Debug, Default)]
struct Cell {
    level: u32,
    xyz: [u32; 3],
}

/// Capacity of the descent stack (one start cell at a time): a node's children are pushed when
/// it is popped, so at most 7 pending siblings per level below the start plus the 8 children
/// of the last popped node.
const STACK: usize = 7 * MAX_DEPTH as usize + 8;

impl<F: FnMut(ProxyKey, ProxyKey)> Tester<'_, F> {
    /// Every pair within `list`: all against all when short, else a sweep along x.
    fn within(&mut self, list: &[Hot], w: &mut Work) {
        if list.len() <= SHORT_SELF {
            self.all_pairs(list);
            return;
        }
        pairs::sweep_x(list, &mut w.sweep, |a, b| self.test(a, b));
    }

    /// Every pair across the disjoint lists `a` and `b`: all against all when small, else a
    /// merged sweep along x.
    #[inline]
    fn between(&mut self, a: &[Hot], b: &[Hot], w: &mut Work) {
        self.tests += (a.len() * b.len()) as u64;
        if let [x] = a {
            for y in b {
                self.emit_if(x, y);
            }
        } else if a.len() * b.len() <= SHORT_CROSS || a.len().min(b.len()) <= SHORT_SIDE {
            for x in a {
                for y in b {
                    self.emit_if(x, y);
                }
            }
        } else {
            self.tests -= (a.len() * b.len()) as u64;
            self.sweep_between(a, b, w);
        }
    }

    /// [`Self::between`] for long lists: sort both by `min.x` and sweep them merged.
    #[inline(never)]
    fn sweep_between(&mut self, a: &[Hot], b: &[Hot], w: &mut Work) {
        let (ea, eb) = (&mut w.sweep, &mut w.sweep_own);
        ea.clear();
        ea.extend(a.iter().enumerate().map(|(i, h)| entry(h.min.x, i)));
        ea.sort_unstable();
        eb.clear();
        eb.extend(b.iter().enumerate().map(|(i, h)| entry(h.min.x, i)));
        eb.sort_unstable();
        // In merged order, each entry scans the other list's entries not yet passed while they
        // start before it ends: a pair overlapping along x is met once.
        let (mut i, mut j) = (0, 0);
        while i < ea.len() && j < eb.len() {
            if ea[i] >> 32 <= eb[j] >> 32 {
                let x = &a[ea[i] as u32 as usize];
                let hi = u64::from(ord(x.max.x)) << 32 | u64::from(u32::MAX);
                for &y in eb[j..].iter().take_while(|&&y| y <= hi) {
                    self.test(x, &b[y as u32 as usize]);
                }
                i += 1;
            } else {
                let y = &b[eb[j] as u32 as usize];
                let hi = u64::from(ord(y.max.x)) << 32 | u64::from(u32::MAX);
                for &x in ea[i..].iter().take_while(|&&x| x <= hi) {
                    self.test(&a[x as u32 as usize], y);
                }
                j += 1;
            }
        }
    }
}

impl Octree {
    /// Calls `emit(a, b)` for every overlapping pair of a loose tree, once; records the AABB
    /// tests and the visited nodes in `s`.
    pub(super) fn loose_pairs(&self, s: &mut pairs::Scratch, emit: impl FnMut(ProxyKey, ProxyKey)) {
        s.tests = 0;
        s.nodes_visited = 0;
        if self.objs.is_empty() {
            return;
        }
        self.sort_into_walk_order(s);
        let pairs::Scratch {
            hot,
            node_key,
            keys,
            work,
            loose,
            ..
        } = s;
        let d = self.depth;
        // `deeper[L]`: some sphere lives below level `L`.
        let mut deeper = [false; MAX_DEPTH as usize + 1];
        let mut below = 0;
        for l in (0..=d as usize).rev() {
            deeper[l] = below > 0;
            below += self.per_level[l];
        }
        // Only a pass with cross-level pairs needs the runs by node slot.
        let cross = (0..=d as usize).any(|l| deeper[l] && self.per_level[l] > 0);
        if cross && loose.run_of.len() < self.nodes.head_len() {
            loose.run_of.resize(self.nodes.head_len(), [0, 0]);
        }
        let (run_key, run_start, run_slot, dense) = (
            &mut loose.run_key,
            &mut loose.run_start,
            &mut loose.run_slot,
            &mut loose.dense,
        );
        run_key.clear();
        run_start.clear();
        run_slot.clear();
        let n = hot.len();
        let mut i = 0;
        while i < n {
            let key = node_key[i];
            let j = i + node_key[i..].iter().take_while(|&&k| k == key).count();
            if cross {
                let (level, xyz) = cell_of(key, d);
                let slot = self
                    .nodes
                    .slot(node_index(level, morton(xyz)))
                    .expect("an occupied node's page exists");
                loose.run_of[slot] = [i as u32, j as u32];
                run_slot.push(slot as u32);
            }
            run_key.push(key);
            run_start.push(i as u32);
            i = j;
        }
        let runs = run_key.len();
        run_key.push(u64::MAX);
        run_start.push(n as u32);
        let (run_key, run_start) = (&run_key[..], &run_start[..]);
        let spheres =
            |from: usize, to: usize| &hot[run_start[from] as usize..run_start[to] as usize];
        // The first run whose key is at least `target`, from `p` on; `target` never exceeds
        // the sentinel. The first two steps are branch-free: most calls move by 0, 1 or 2.
        let seek = |p: &mut usize, target: u64| {
            *p += usize::from(run_key[*p] < target);
            *p += usize::from(run_key[*p] < target);
            while run_key[*p] < target {
                *p += 1;
            }
        };
        let mut t = Tester {
            keys,
            tests: 0,
            emit,
        };
        let mut visited = runs as u32;
        // Per forward row: the first run at or after its lowest and after its highest cell
        // looked for last.
        let mut first = [0usize; ROWS.len()];
        let mut past = [0usize; ROWS.len()];
        // The key offsets of the four rows at the current level.
        let (mut at_level, mut offsets) = (u32::MAX, [0u64; ROWS.len()]);
        for r in 0..runs {
            let own = spheres(r, r + 1);
            if own.len() > 1 {
                t.within(own, work);
            }
            let key = run_key[r];
            let (level, [x, y, z]) = cell_of(key, d);
            let side = 1u32 << level;
            if level != at_level {
                at_level = level;
                offsets = ROWS.map(|[dy, dz]| {
                    (i64::from(dy) * i64::from(side)
                        + i64::from(dz) * i64::from(side) * i64::from(side))
                        as u64
                });
            }
            // The next cell of the row (the next run, if its key is one more), then the cells
            // `x − 1 ..= x + 1` of each forward row, which are one stretch of the sorted
            // spheres: from the first run at or after the key of cell `x − 1` to the first
            // after `x + 1` (both clamped to the row). Each is a range of `hot`, often empty.
            let next = usize::from(x + 1 < side && run_key[r + 1] == key + 1);
            let mut ranges = [[0u32; 2]; 1 + ROWS.len()];
            ranges[0] = [run_start[r + 1], run_start[(r + 1 + next).min(runs)]];
            let (back, ahead) = (u64::from(x > 0), 1 + u64::from(x + 1 < side));
            let inside = [
                y + 1 < side,
                y > 0 && z + 1 < side,
                z + 1 < side,
                y + 1 < side && z + 1 < side,
            ];
            for k in 0..ROWS.len() {
                if !inside[k] {
                    continue;
                }
                let cell = key.wrapping_add(offsets[k]);
                seek(&mut first[k], cell - back);
                seek(&mut past[k], cell + ahead);
                ranges[1 + k] = [run_start[first[k]], run_start[past[k]]];
            }
            if own.len() <= NEAR_OWN {
                // A few own spheres: the short ranges' spheres are listed first, with no
                // branch on their lengths, and each own sphere is tested against the list in
                // one loop (one loop end to mispredict instead of one per range).
                let mut near = [0u32; NEAR_CAP];
                let mut len = 0;
                for &[lo, hi] in &ranges {
                    let count = hi.saturating_sub(lo) as usize;
                    if count <= NEAR_RANGE {
                        for (j, slot) in near[len..len + NEAR_RANGE].iter_mut().enumerate() {
                            *slot = lo + j as u32;
                        }
                        len += count;
                    } else {
                        t.between(own, &hot[lo as usize..hi as usize], work);
                    }
                }
                t.tests += (own.len() * len) as u64;
                for a in own {
                    for &b in &near[..len] {
                        t.emit_if(a, &hot[b as usize]);
                    }
                }
            } else {
                // Many own spheres (a crowded level, like a settled pile): the ranges'
                // spheres that reach the union of the own boxes are listed first, by one test
                // each and a store that the test's outcome keeps; only they meet every own
                // sphere. Ranges long enough to sweep are swept instead.
                let (mut umin, mut umax) = (own[0].min, own[0].max);
                for h in &own[1..] {
                    umin = umin.min(h.min);
                    umax = umax.max(h.max);
                }
                let union = Hot {
                    min: umin,
                    max: umax,
                    ..Hot::EMPTY
                };
                let total: u32 = ranges.iter().map(|&[lo, hi]| hi.saturating_sub(lo)).sum();
                if dense.len() < total as usize {
                    dense.resize(total as usize, 0);
                }
                let mut len = 0;
                for &[lo, hi] in &ranges {
                    let count = hi.saturating_sub(lo) as usize;
                    let range = &hot[lo as usize..lo as usize + count];
                    if own.len() * count > SHORT_CROSS {
                        t.between(own, range, work);
                        continue;
                    }
                    t.tests += count as u64;
                    for (b, h) in (lo..).zip(range) {
                        // `len` counts at most the entries before this one: below `total`.
                        dense[len] = b;
                        len += usize::from(h.overlaps(&union));
                    }
                }
                t.tests += (own.len() * len) as u64;
                for a in own {
                    for &b in &dense[..len] {
                        t.emit_if(a, &hot[b as usize]);
                    }
                }
            }
            if deeper[level as usize] {
                visited += self.descend((level, [x, y, z]), own, hot, &loose.run_of, &mut t, work);
            }
        }
        if cross {
            for &slot in run_slot.iter() {
                loose.run_of[slot as usize] = [0, 0];
            }
        }
        s.tests = t.tests;
        s.nodes_visited = visited;
    }

    /// The cross-level pairs of the spheres `own` of the node at cell `xyz` of `level`: every
    /// sphere placed below `level` in the subtrees of the 27 cells around `xyz`, pruned by the
    /// union of `own`'s ranges. Returns the number of nodes visited.
    fn descend<F: FnMut(ProxyKey, ProxyKey)>(
        &self,
        (level, xyz): (u32, [u32; 3]),
        own: &[Hot],
        hot: &[Hot],
        run_of: &[[u32; 2]],
        t: &mut Tester<'_, F>,
        w: &mut Work,
    ) -> u32 {
        let mut umin = [u16::MAX; 3];
        let mut umax = [0u16; 3];
        for h in own {
            for a in 0..3 {
                umin[a] = umin[a].min(h.qmin[a]);
                umax[a] = umax[a].max(h.qmax[a]);
            }
        }
        // Whether a node's loose range overlaps the union.
        let reaches = |c: &Cell| {
            let size = 1i32 << (self.grid - c.level);
            (0..3).all(|a| {
                let lo = c.xyz[a] as i32 * size - size / 2;
                let hi = lo + 2 * size - 1;
                lo <= i32::from(umax[a]) && i32::from(umin[a]) <= hi
            })
        };
        let side = 1i32 << level;
        let mut stack = [Cell::default(); STACK];
        let mut visited = 0;
        for dz in -1..=1 {
            for dy in -1..=1 {
                for dx in -1..=1 {
                    let cell = [0, 1, 2].map(|a| xyz[a] as i32 + [dx, dy, dz][a]);
                    if cell.iter().any(|&v| v < 0 || v >= side) {
                        continue;
                    }
                    let start = Cell {
                        level,
                        xyz: cell.map(|v| v as u32),
                    };
                    if !reaches(&start) {
                        continue;
                    }
                    stack[0] = start;
                    let mut len = 1;
                    let mut first = true;
                    while len > 0 {
                        len -= 1;
                        let cell = stack[len];
                        let Some(slot) = self.nodes.slot(node_index(cell.level, morton(cell.xyz)))
                        else {
                            continue;
                        };
                        if first {
                            first = false;
                        } else {
                            visited += 1;
                            let [a, b] = run_of[slot];
                            if a < b {
                                t.between(own, &hot[a as usize..b as usize], w);
                            }
                        }
                        let mask = self.nodes.mask_at(slot);
                        let mut m = mask;
                        while m != 0 {
                            let k = m.trailing_zeros();
                            m &= m - 1;
                            let child = Cell {
                                level: cell.level + 1,
                                xyz: [0, 1, 2].map(|a| cell.xyz[a] * 2 + ((k >> a) & 1)),
                            };
                            if reaches(&child) {
                                stack[len] = child;
                                len += 1;
                            }
                        }
                    }
                }
            }
        }
        visited
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cell_of_reads_the_row_major_key() {
        let d = 6;
        let key = (4u64 << (3 * d)) | (3 << 8) | (9 << 4) | 5;
        assert_eq!(cell_of(key, d), (4, [5, 9, 3]));
        assert_eq!(cell_of(0, d), (0, [0, 0, 0]));
        // Depth 10, deepest level: 30 cell bits below the level.
        let key = (10u64 << 30) | (1023 << 20) | 1023;
        assert_eq!(cell_of(key, 10), (10, [1023, 0, 1023]));
    }
}
