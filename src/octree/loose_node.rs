//! The loose pair pass's work per occupied node (the pass is derived in the module docs of
//! `loose`): the pairs within the node's run, with its forward same-level neighbours (few or
//! many spheres), and with the spheres of the deeper subtrees around it.

use super::cell::Cell;
use super::loose::RunKey;
use super::placement::LooseKey;
use super::strict::Parts;
use super::walk::{Hot, Run, SHORT_CROSS, SHORT_SELF, Sweeps, Tester};
use super::{MAX_DEPTH, Octree};
use crate::geom::SimdBox;
use crate::pair::ProxyKey;
/// The four forward neighbour rows `(dy, dz)` of a cell (see the module docs).
const ROWS: [[i32; 2]; 4] = [[1, 0], [-1, 1], [0, 1], [1, 1]];

/// The forward stretches of a node: the rest of its own row, then one per row of [`ROWS`].
const STRETCHES: usize = 1 + ROWS.len();

/// Runs of at most this many spheres test their forward neighbours through one list; longer
/// runs first filter the neighbours by the union of their boxes, which costs a test per
/// neighbour and pays once it saves more than that.
const NEAR_OWN: usize = 4;
/// Neighbour stretches of at most this many spheres go into that list, longer ones are tested
/// on their own: most stretches of a level whose cells hold about one sphere hold 0–2.
const NEAR_RANGE: usize = 4;
/// The list's room: every stretch at its longest, and the slack of the last stretch's writes.
const NEAR_CAP: usize = STRETCHES * NEAR_RANGE + NEAR_RANGE;
/// The least room of the list of a crowded run's neighbours, in spheres (4 KB).
const DENSE_FLOOR: usize = 1024;

/// The state of one loose pass over the sorted spheres.
pub(super) struct Pass<'a, F, K> {
    tree: &'a Octree,
    /// The walk order: boxes, and the sorted list whose low halves are the ids.
    boxes: &'a [SimdBox],
    ids: &'a [u64],
    run_key: &'a [K],
    run_start: &'a [u32],
    run_of: &'a [[u32; 2]],
    pub(super) t: Tester<'a, F>,
    sweeps: &'a mut Sweeps,
    dense: &'a mut Vec<u32>,
    parts: &'a mut Parts,
    /// Per forward row: the first run at or after its lowest cell, and the first after its
    /// highest cell, looked for last.
    first: [usize; ROWS.len()],
    past: [usize; ROWS.len()],
    /// The level whose key offsets of the forward rows `offsets` holds.
    at_level: u32,
    offsets: [u64; ROWS.len()],
    /// The positions of the spheres of a few-sphere run's short forward stretches; only the
    /// entries a run writes are read, so it is never cleared.
    near: [u32; NEAR_CAP],
}

/// Tests every sphere of `own` against the spheres at the walk positions `listed` of `boxes`
/// and `ids`.
#[inline]
fn test_listed<F: FnMut(ProxyKey, ProxyKey)>(
    t: &mut Tester<'_, F>,
    own: Run<'_>,
    (boxes, ids): (&[SimdBox], &[u64]),
    listed: &[u32],
) {
    t.tests += (own.len() * listed.len()) as u64;
    for (i, a) in own.boxes.iter().enumerate() {
        for &b in listed {
            if a.overlaps(&boxes[b as usize]) {
                t.emit_ids(own.ids[i] as u32, ids[b as usize] as u32);
            }
        }
    }
}

/// Moves `p` to the first run whose key is at least `target`; `target` never exceeds the
/// sentinel. The first two steps are branch-free: most calls move by 0, 1 or 2. The target
/// is compared in the keys' own width, so that a `u32` key is compared where it lies.
#[inline]
fn seek<K: RunKey>(keys: &[K], p: &mut usize, target: u64) {
    let target = K::from_key(target);
    *p += usize::from(keys[*p] < target);
    *p += usize::from(keys[*p] < target);
    while keys[*p] < target {
        *p += 1;
    }
}

impl<'a, F: FnMut(ProxyKey, ProxyKey), K: RunKey> Pass<'a, F, K> {
    /// A pass over the sorted spheres `walk` (boxes, and ids in the low halves) whose occupied
    /// nodes are `runs` (each node's key, first sphere, and its run by node slot; see
    /// `loose::Scratch`), testing with `t` and the task's scratch.
    pub(super) fn new(
        tree: &'a Octree,
        (boxes, ids): (&'a [SimdBox], &'a [u64]),
        (run_key, run_start, run_of): (&'a [K], &'a [u32], &'a [[u32; 2]]),
        t: Tester<'a, F>,
        (sweeps, dense, parts): (&'a mut Sweeps, &'a mut Vec<u32>, &'a mut Parts),
    ) -> Self {
        Pass {
            tree,
            boxes,
            ids,
            run_key,
            run_start,
            run_of,
            t,
            sweeps,
            dense,
            parts,
            first: [0; ROWS.len()],
            past: [0; ROWS.len()],
            at_level: u32::MAX,
            offsets: [0; ROWS.len()],
            near: [0; NEAR_CAP],
        }
    }

    /// Walk positions `lo..hi`.
    #[inline]
    fn run(&self, lo: usize, hi: usize) -> Run<'a> {
        Run::of(self.boxes, self.ids, lo, hi)
    }

    /// Points the forward rows' seek pointers at or before where the first seeks of a pass
    /// that starts at run `r` will stop (the pointers only move forward): the first run at
    /// or after the lowest key a forward row of `r`'s cell can have, one below the row's
    /// offset added to `r`'s key. Later runs look for larger keys.
    #[cfg(feature = "parallel")]
    pub(super) fn start_at(&mut self, r: usize) {
        let key = self.run_key[r].get();
        let (level, _) = LooseKey(key).cell(self.tree.lattice.depth);
        for (k, [dy, dz]) in ROWS.into_iter().enumerate() {
            let off = LooseKey::offset(level, [0, dy, dz]);
            let low = key.wrapping_add(off).saturating_sub(1).max(key);
            let at = self.run_key.partition_point(|&x| x.get() < low);
            (self.first[k], self.past[k]) = (at, at);
        }
    }

    /// Every pair of run `r` with itself, its forward neighbours and (where `deeper` says some
    /// sphere lives below its level) its neighbours' subtrees. Returns the subtree nodes
    /// visited.
    #[inline]
    pub(super) fn node(&mut self, r: usize, deeper: &[bool; MAX_DEPTH as usize + 1]) -> u32 {
        let run_start = self.run_start;
        let key = LooseKey(self.run_key[r].get());
        let (lo, hi) = (run_start[r] as usize, run_start[r + 1] as usize);
        let own = self.run(lo, hi);
        let (level, xyz) = key.cell(self.tree.lattice.depth);
        if level == 0 && own.len() > SHORT_SELF {
            // The root's spheres, with the cell ranges and ids the subdivision copies.
            let lattice = &self.tree.lattice;
            let copies = own.boxes.iter().zip(own.ids).map(|(b, &x)| {
                let aabb = b.aabb();
                Hot {
                    bx: *b,
                    qmin: lattice.quantize(aabb.min),
                    qmax: lattice.quantize(aabb.max),
                    id: x as u32,
                }
            });
            self.parts
                .own_pairs_of(&mut self.t, copies, [0; 3], lattice.bits, self.sweeps);
        } else if own.len() > 1 {
            self.t.within(own, self.sweeps);
        }
        let stretches = self.forward(r, key, level, xyz);
        if own.len() <= NEAR_OWN {
            self.near_few(own, &stretches);
        } else {
            self.near_many(own, &stretches);
        }
        if !deeper[level as usize] {
            0
        } else if level == 0 {
            // One descent per root sphere, each pruned by its own range.
            (lo..hi)
                .map(|i| self.descend(0, xyz, self.run(i, i + 1)))
                .sum()
        } else {
            self.descend(level, xyz, own)
        }
    }

    /// The forward stretches of run `r` (cell `xyz` of `level`) as ranges of the sorted
    /// spheres, often empty: the next cell of the row (the next run, if its key is one more),
    /// then the cells `x − 1 ..= x + 1` of each forward row, which are one stretch: from the
    /// first run at or after the key of cell `x − 1` to the first after `x + 1` (both clamped
    /// to the row).
    #[inline]
    fn forward(
        &mut self,
        r: usize,
        key: LooseKey,
        level: u32,
        [x, y, z]: [u32; 3],
    ) -> [[u32; 2]; STRETCHES] {
        let side = 1u32 << level;
        if level != self.at_level {
            self.at_level = level;
            self.offsets = ROWS.map(|[dy, dz]| LooseKey::offset(level, [0, dy, dz]));
        }
        let (run_key, run_start) = (self.run_key, self.run_start);
        let runs = run_key.len() - 1;
        let next = usize::from(x + 1 < side && run_key[r + 1].get() == key.0 + 1);
        let mut stretches = [[0u32; 2]; STRETCHES];
        stretches[0] = [run_start[r + 1], run_start[(r + 1 + next).min(runs)]];
        let (back, ahead) = (u64::from(x > 0), 1 + u64::from(x + 1 < side));
        let inside = [
            y + 1 < side,
            y > 0 && z + 1 < side,
            z + 1 < side,
            y + 1 < side && z + 1 < side,
        ];
        let (mut first, mut past, offsets) = (self.first, self.past, self.offsets);
        for k in 0..ROWS.len() {
            if !inside[k] {
                continue;
            }
            let cell = key.0.wrapping_add(offsets[k]);
            seek(run_key, &mut first[k], cell - back);
            seek(run_key, &mut past[k], cell + ahead);
            stretches[1 + k] = [run_start[first[k]], run_start[past[k]]];
        }
        (self.first, self.past) = (first, past);
        stretches
    }

    /// The forward pairs of a run of a few spheres: the short stretches' spheres are listed
    /// first, with no branch on their lengths, and each own sphere is tested against the list
    /// in one loop; long stretches are tested on their own.
    #[inline]
    fn near_few(&mut self, own: Run<'_>, stretches: &[[u32; 2]; STRETCHES]) {
        let mut len = 0;
        for &[lo, hi] in stretches {
            let count = hi.saturating_sub(lo) as usize;
            if count <= NEAR_RANGE {
                for (j, slot) in self.near[len..len + NEAR_RANGE].iter_mut().enumerate() {
                    *slot = lo + j as u32;
                }
                len += count;
            } else {
                let other = self.run(lo as usize, hi as usize);
                self.t.between(own, other, self.sweeps);
            }
        }
        test_listed(&mut self.t, own, (self.boxes, self.ids), &self.near[..len]);
    }

    /// The forward pairs of a run of many spheres (a crowded level): the stretches' spheres
    /// that reach the union of the own boxes are listed first, by one test each and a store
    /// that the test's outcome keeps; only they meet every own sphere. Stretches long enough to
    /// sweep are swept instead.
    #[inline(never)]
    fn near_many(&mut self, own: Run<'_>, stretches: &[[u32; 2]; STRETCHES]) {
        let boxes = self.boxes;
        let union = own.boxes.iter().fold(SimdBox::EMPTY, |u, b| u.union(b));
        let total: u32 = stretches
            .iter()
            .map(|&[lo, hi]| hi.saturating_sub(lo))
            .sum();
        if self.dense.len() < total as usize {
            // To a power of two, at least `DENSE_FLOOR`: a chunk's first crowded runs do not
            // each reach a new peak.
            let room = (total as usize).next_power_of_two().max(DENSE_FLOOR);
            self.dense.resize(room, 0);
        }
        let mut len = 0;
        for &[lo, hi] in stretches {
            let count = hi.saturating_sub(lo) as usize;
            let stretch = &boxes[lo as usize..lo as usize + count];
            if own.len() * count > SHORT_CROSS {
                let other = self.run(lo as usize, lo as usize + count);
                self.t.between(own, other, self.sweeps);
                continue;
            }
            self.t.tests += count as u64;
            for (b, h) in (lo..).zip(stretch) {
                // `len` counts at most the entries before this one: below `total`.
                self.dense[len] = b;
                len += usize::from(h.overlaps(&union));
            }
        }
        test_listed(&mut self.t, own, (boxes, self.ids), &self.dense[..len]);
    }

    /// The cross-level pairs of the spheres `own` of the node at cell `xyz` of `level`: every
    /// sphere placed below `level` in the subtrees of the 27 cells around `xyz`, pruned by the
    /// union of `own`'s ranges. Returns the number of nodes visited.
    #[inline(never)]
    fn descend(&mut self, level: u32, xyz: [u32; 3], own: Run<'_>) -> u32 {
        let (tree, boxes, ids, run_of) = (self.tree, self.boxes, self.ids, self.run_of);
        // The union of the own ranges: quantising is monotone, so the range of the union box
        // is the union of the ranges.
        let union = own
            .boxes
            .iter()
            .fold(SimdBox::EMPTY, |u, b| u.union(b))
            .aabb();
        let (umin, umax) = (
            tree.lattice.quantize(union.min),
            tree.lattice.quantize(union.max),
        );
        let reaches = |c: &Cell| tree.lattice.reaches(c, umin, umax);
        let side = 1i32 << level;
        let mut visited = 0;
        for dz in -1..=1 {
            for dy in -1..=1 {
                for dx in -1..=1 {
                    let cell = [0, 1, 2].map(|a| xyz[a] as i32 + [dx, dy, dz][a]);
                    if cell.iter().any(|&v| v < 0 || v >= side) {
                        continue;
                    }
                    let start = Cell::at(level, cell.map(|v| v as u32));
                    if !reaches(&start) {
                        continue;
                    }
                    tree.nodes.walk(start, &reaches, |c, slot| {
                        if c.level > level {
                            visited += 1;
                            let [a, b] = run_of[slot];
                            if a < b {
                                let other = Run::of(boxes, ids, a as usize, b as usize);
                                self.t.between(own, other, self.sweeps);
                            }
                        }
                    });
                }
            }
        }
        visited
    }
}
