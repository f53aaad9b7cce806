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
//! The pass. The spheres are radix-sorted into walk order as in the strict pass, so each
//! occupied node is a run of the walk-ordered array; the run is recorded in a per-node slot of
//! the paged node storage for the pass and cleared after it. Then, per occupied node:
//! - the pairs within its run (a sweep along x when long);
//! - the pairs with the 13 "forward" same-level neighbours, the offsets `(dx, dy, dz)` with
//!   `(dz, dy, dx)` lexicographically positive: of two neighbouring nodes exactly one sees the
//!   other forward, so each same-level pair is found once;
//! - if some sphere lives deeper, the pairs with every sphere deeper than the node in the
//!   subtrees of the 27 cells around it, found by descending the occupied subtrees (child
//!   masks) and pruning every node whose loose range misses the union of the run's ranges
//!   (which holds every range the run overlaps). A cross-level pair is found only from its
//!   shallower sphere's node, through the one neighbour cell that is its deeper sphere's
//!   ancestor, so once.
//!
//! Overflow spheres sit in the root, whose 27-cell neighbourhood is the root itself: they are
//! tested against the whole tree pruned by their clamped ranges, which overlap the range of
//! everything their boxes overlap.

use super::pairs::{self, Hot, SHORT_CROSS, SHORT_SELF, SHORT_SIDE, Tester, Work, entry, ord};
use super::place::{compact3, morton, node_index};
use super::{MAX_DEPTH, Octree};
use crate::ProxyKey;

/// An occupied node of a pass: its run `[start, end)` of walk-ordered spheres, its slot in the
/// node storage, its level, and its cell as Morton code and coordinates. 32 bytes.
#[derive(Clone, Copy, Debug)]
struct Run {
    start: u32,
    end: u32,
    slot: u32,
    level: u32,
    code: u32,
    xyz: [u32; 3],
}
const _: () = assert!(core::mem::size_of::<Run>() == 32);

/// Buffers of the loose pair pass, reused by every pass; they never shrink.
#[derive(Clone, Debug, Default)]
pub(super) struct Scratch {
    runs: Vec<Run>,
    /// By node slot ([`super::place::Nodes::slot`]): the node's run `[start, end)` during a
    /// pass, `[0, 0]` otherwise. Grows with the node pages.
    run_of: Vec<[u32; 2]>,
}

/// The 13 same-level neighbour offsets `(dx, dy, dz)` with `(dz, dy, dx)` lexicographically
/// positive (half of the 26, one of each opposite pair), as indices `offset + 1`.
const FORWARD: [[usize; 3]; 13] = [
    [2, 1, 1],
    [0, 2, 1],
    [1, 2, 1],
    [2, 2, 1],
    [0, 0, 2],
    [1, 0, 2],
    [2, 0, 2],
    [0, 1, 2],
    [1, 1, 2],
    [2, 1, 2],
    [0, 2, 2],
    [1, 2, 2],
    [2, 2, 2],
];

/// The bits of the x coordinate in a Morton code (every third bit from bit 0); y's are these
/// shifted by one, z's by two.
const DILATED_X: u32 = 0x0924_9249;

/// The coordinate held in the dilated bits `m` (a Morton code masked to one axis's bits
/// `axis`) minus one, plus zero and plus one, still dilated: adding 1 to a dilated integer
/// sets the gaps first so the carry runs through them (`(m | !axis) + 1`). Out-of-grid
/// results wrap; the caller checks the coordinate.
#[inline]
fn dilated_steps(m: u32, axis: u32) -> [u32; 3] {
    [
        m.wrapping_sub(1) & axis,
        m,
        (m | !axis).wrapping_add(1) & axis,
    ]
}

/// The Morton codes of the 13 [`FORWARD`] neighbours of the cell with code `code` (wrapped
/// where they leave the grid).
#[inline]
fn forward_codes(code: u32) -> [u32; 13] {
    let axis = [DILATED_X, DILATED_X << 1, DILATED_X << 2];
    let [x, y, z] = [0, 1, 2].map(|a| dilated_steps(code & axis[a], axis[a]));
    // `FORWARD` spelled out, so the compiler sees constant indices.
    [
        x[2] | y[1] | z[1],
        x[0] | y[2] | z[1],
        x[1] | y[2] | z[1],
        x[2] | y[2] | z[1],
        x[0] | y[0] | z[2],
        x[1] | y[0] | z[2],
        x[2] | y[0] | z[2],
        x[0] | y[1] | z[2],
        x[1] | y[1] | z[2],
        x[2] | y[1] | z[2],
        x[0] | y[2] | z[2],
        x[1] | y[2] | z[2],
        x[2] | y[2] | z[2],
    ]
}

/// Bit `k` set iff the `k`-th [`FORWARD`] neighbour of cell `xyz` is in a grid of `top + 1`
/// cells per axis.
fn forward_inside(xyz: [u32; 3], top: u32) -> u16 {
    let ok = xyz.map(|c| [c > 0, true, c < top]);
    FORWARD
        .iter()
        .enumerate()
        .filter(|(_, [dx, dy, dz])| ok[0][*dx] && ok[1][*dy] && ok[2][*dz])
        .fold(0, |m, (k, _)| m | 1 << k)
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
        let slots = self.nodes.head_len();
        if loose.run_of.len() < slots {
            loose.run_of.resize(slots, [0, 0]);
        }
        loose.runs.clear();
        let n = hot.len();
        let mut i = 0;
        while i < n {
            let key = node_key[i];
            let j = i + node_key[i..].iter().take_while(|&&k| k == key).count();
            let level = (key & 15) as u32;
            let code = ((key >> 4) as u32) >> (3 * (d - level));
            let slot = self
                .nodes
                .slot(node_index(level, code))
                .expect("an occupied node's page exists");
            loose.run_of[slot] = [i as u32, j as u32];
            loose.runs.push(Run {
                start: i as u32,
                end: j as u32,
                slot: slot as u32,
                level,
                code,
                xyz: [compact3(code), compact3(code >> 1), compact3(code >> 2)],
            });
            i = j;
        }
        // `deeper[L]`: some sphere lives below level `L`.
        let mut deeper = [false; MAX_DEPTH as usize + 1];
        let mut below = 0;
        for l in (0..=d as usize).rev() {
            deeper[l] = below > 0;
            below += self.per_level[l];
        }
        let mut t = Tester {
            keys,
            tests: 0,
            emit,
        };
        let mut visited = loose.runs.len() as u32;
        for r in &loose.runs {
            let own = &hot[r.start as usize..r.end as usize];
            if own.len() > 1 {
                t.within(own, work);
            }
            // The neighbours' Morton codes by dilated arithmetic, and (unless the cell is
            // interior, the common case) which of them are in the grid.
            let top = (1u32 << r.level) - 1;
            let base = node_index(r.level, 0);
            let codes = forward_codes(r.code);
            let inside = if r.xyz.iter().all(|&c| c > 0 && c < top) {
                u16::MAX
            } else {
                forward_inside(r.xyz, top)
            };
            for (k, &code) in codes.iter().enumerate() {
                if inside & (1 << k) == 0 {
                    continue;
                }
                if let Some(slot) = self.nodes.slot(base + code) {
                    let [a, b] = loose.run_of[slot];
                    if a < b {
                        t.between(own, &hot[a as usize..b as usize], work);
                    }
                }
            }
            if deeper[r.level as usize] {
                visited += self.descend(r, own, hot, &loose.run_of, &mut t, work);
            }
        }
        for r in &loose.runs {
            loose.run_of[r.slot as usize] = [0, 0];
        }
        s.tests = t.tests;
        s.nodes_visited = visited;
    }

    /// The cross-level pairs of run `r` (spheres `own`): every sphere placed below `r`'s level
    /// in the subtrees of the 27 cells around `r`'s cell, pruned by the union of `own`'s
    /// ranges. Returns the number of nodes visited.
    fn descend<F: FnMut(ProxyKey, ProxyKey)>(
        &self,
        r: &Run,
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
        let side = 1i32 << r.level;
        let mut stack = [Cell::default(); STACK];
        let mut visited = 0;
        for dz in -1..=1 {
            for dy in -1..=1 {
                for dx in -1..=1 {
                    let xyz = [0, 1, 2].map(|a| r.xyz[a] as i32 + [dx, dy, dz][a]);
                    if xyz.iter().any(|&v| v < 0 || v >= side) {
                        continue;
                    }
                    let start = Cell {
                        level: r.level,
                        xyz: xyz.map(|v| v as u32),
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
    fn forward_codes_are_the_forward_offsets() {
        let c = [5u32, 9, 3];
        let codes = forward_codes(morton(c));
        for (k, off) in FORWARD.iter().enumerate() {
            let n = [0, 1, 2].map(|a| (c[a] as i32 + off[a] as i32 - 1) as u32);
            assert_eq!(codes[k], morton(n), "offset {off:?}");
        }
        // Each unordered neighbour pair once: the offsets and their negations cover all 26.
        let mut all: Vec<[i32; 3]> = FORWARD
            .iter()
            .flat_map(|o| {
                let d = o.map(|v| v as i32 - 1);
                [d, d.map(|v| -v)]
            })
            .collect();
        all.sort_unstable();
        all.dedup();
        assert_eq!(all.len(), 26);
        assert_eq!(forward_inside([0, 0, 0], 7), 0b1_1011_0000_1101);
        assert_eq!(forward_inside([3, 3, 3], 7), 0x1FFF);
    }
}
