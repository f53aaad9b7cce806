//! All overlapping pairs of a [`Placement::Loose`](super::Placement::Loose) tree: same-level
//! neighbours, then cross-level pairs through the neighbours' occupied subtrees.
//!
//! Why neighbours suffice. On the integer lattice (see `Lattice::loose_node`) a sphere's range
//! lies inside its node's loose range `[k·S − S/2, k·S + S − 1 + S/2]` (cell `k`, `S` lattice
//! cells per level-`L` cell), and a node's loose range lies inside its parent's. Overlapping
//! boxes have overlapping ranges, so if `a` at level `L` overlaps `b` at level `L' >= L`, the
//! loose range of `a`'s cell overlaps that of `b`'s level-`L` ancestor cell `k'`. Two level-`L`
//! loose ranges overlap iff `|k − k'|·S <= 2S − 1`, i.e. iff `|k − k'| <= 1` on every axis: `b`'s
//! node is in the subtree of one of the 27 cells around `a`'s (its own included).
//!
//! The pass. The spheres are radix-sorted by their node's [`LooseKey`] (level, then the cell in
//! row-major order), so each occupied node is a run of the sorted array and a level's nodes
//! come in rows along x. Then, per occupied node:
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
//!   loop, which has one loop end to mispredict where a loop per stretch has five. A run of
//!   many spheres (a crowded level, such as a settled pile) lists only the stretches' spheres
//!   that reach the union of its own boxes, one test each, and tests its spheres against those;
//! - if some sphere lives deeper, the pairs with every sphere deeper than the node in the
//!   subtrees of the 27 cells around it, found by descending the occupied subtrees (child
//!   masks) and pruning every node whose loose range misses the union of the run's ranges
//!   (which holds every range the run overlaps). A cross-level pair is found only from its
//!   shallower sphere's node, through the one neighbour cell that is its deeper sphere's
//!   ancestor, so once. Only then are the runs recorded in a per-node slot of the paged node
//!   storage (and cleared after the pass), for the descent to find them.
//!
//! Overflow spheres sit in the root, whose 27-cell neighbourhood is the root itself: each is
//! tested against the whole tree pruned by its own clamped range, which overlaps the range of
//! everything its box overlaps (outside the region, a face of the lattice: few nodes), and the
//! root's spheres are paired among themselves by the strict pass's subdivision of a long own
//! list over the root cell (`strict::Parts`), so overflow spheres bunched on one face of the
//! region do not meet each other in one sweep.

use super::cell::Cell;
use super::loose_node::Pass;
use super::placement::{LooseKey, walk_key_bits};
use super::strict::Parts;
use super::walk::{self, Keys, Sweeps, Tester, Walk, runs};
use super::{MAX_DEPTH, Octree, PassCost};
use crate::geom::SimdBox;
use crate::pair::ProxyKey;
use crate::radix::room_for;

/// A node's key in the lists of a pass's runs: `u32` while every walk key fits in 32 bits
/// (every depth below [`MAX_DEPTH`]), which halves the list the neighbour seeks scan, else
/// `u64`.
pub(super) trait RunKey: Copy + Ord + Send + Sync + 'static {
    /// The sentinel that ends the list: above every key, and every key a seek looks for.
    const END: Self;
    fn from_key(key: u64) -> Self;
    fn get(self) -> u64;
    /// The scratch's list of this width.
    fn list(s: &mut Scratch) -> &mut Vec<Self>;
}

impl RunKey for u32 {
    const END: u32 = u32::MAX;
    #[inline]
    fn from_key(key: u64) -> u32 {
        debug_assert!(key < u64::from(u32::MAX));
        key as u32
    }
    #[inline]
    fn get(self) -> u64 {
        u64::from(self)
    }
    fn list(s: &mut Scratch) -> &mut Vec<u32> {
        &mut s.run_key32
    }
}

impl RunKey for u64 {
    const END: u64 = u64::MAX;
    #[inline]
    fn from_key(key: u64) -> u64 {
        key
    }
    #[inline]
    fn get(self) -> u64 {
        self
    }
    fn list(s: &mut Scratch) -> &mut Vec<u64> {
        &mut s.run_key64
    }
}

/// Buffers of the loose pair pass, reused by every pass; they never shrink.
#[derive(Clone, Debug, Default)]
pub(super) struct Scratch {
    /// The occupied nodes of a pass, in key order: node `k` has key `run_key[k]` (in
    /// `run_key32` or `run_key64`, see [`RunKey`]) and the sorted spheres
    /// `run_start[k]..run_start[k + 1]`; a sentinel ends both (key [`RunKey::END`], start the
    /// sphere count). `run_slot[k]` is its slot in the node storage, filled only when some
    /// level below it is occupied.
    run_key32: Vec<u32>,
    run_key64: Vec<u64>,
    run_start: Vec<u32>,
    run_slot: Vec<u32>,
    /// By node slot ([`super::nodes::Nodes::slot`]): the node's run `[start, end)` during a
    /// pass, `[0, 0]` otherwise. Grows with the node pages.
    run_of: Vec<[u32; 2]>,
    /// The neighbours of a crowded run that reach its union box, as positions in the
    /// sorted spheres.
    dense: Vec<u32>,
    /// The subdivision of the root's own list.
    parts: Parts,
    /// Per task of a chunked pass: its own scratch.
    #[cfg(feature = "parallel")]
    chunks: Vec<Chunk>,
    /// The first run of each chunk of a chunked pass, and the run count last.
    #[cfg(feature = "parallel")]
    chunk_runs: Vec<u32>,
}

/// The scratch of one task of a chunked pass ([`Octree::loose_pairs_chunked`]).
#[cfg(feature = "parallel")]
#[derive(Clone, Debug, Default)]
struct Chunk {
    sweeps: Sweeps,
    dense: Vec<u32>,
    parts: Parts,
}

impl Octree {
    /// Calls `emit(a, b)` for every overlapping pair of a loose tree, once.
    pub(super) fn loose_pairs(
        &self,
        ws: &mut walk::Scratch,
        s: &mut Scratch,
        emit: impl FnMut(ProxyKey, ProxyKey),
    ) -> PassCost {
        let Some(Walk {
            keys,
            ids,
            boxes,
            t,
            sweeps,
            ..
        }) = self.begin_pass(ws, emit)
        else {
            return PassCost::default();
        };
        let deeper = self.occupied_below();
        // Only a pass with cross-level pairs needs the runs by node slot.
        let d = self.lattice.depth as usize;
        let cross = (0..=d).any(|l| deeper[l] && self.per_level[l] > 0);
        let (tests, visited) = if walk_key_bits(self.lattice.depth) <= 32 {
            self.loose_runs::<u32, _>(s, keys, (boxes, ids), t, sweeps, cross, &deeper)
        } else {
            self.loose_runs::<u64, _>(s, keys, (boxes, ids), t, sweeps, cross, &deeper)
        };
        s.clear_runs(cross);
        PassCost {
            tests,
            nodes_visited: visited,
        }
    }

    /// The serial pass over the runs of `keys`, their keys listed as `K`: the tests and nodes
    /// visited.
    #[allow(clippy::too_many_arguments)]
    fn loose_runs<K: RunKey, F: FnMut(ProxyKey, ProxyKey)>(
        &self,
        s: &mut Scratch,
        keys: Keys<'_>,
        (boxes, ids): (&[SimdBox], &[u64]),
        t: Tester<'_, F>,
        sweeps: &mut Sweeps,
        cross: bool,
        deeper: &[bool; MAX_DEPTH as usize + 1],
    ) -> (u64, u32) {
        s.index_runs::<K>(self, keys, cross);
        let mut run_key = core::mem::take(K::list(s));
        let Scratch {
            run_start,
            run_of,
            dense,
            parts,
            ..
        } = s;
        let runs = run_key.len() - 1;
        let runs_of = (&run_key[..], &run_start[..], &run_of[..]);
        let mut pass = Pass::new(self, (boxes, ids), runs_of, t, (sweeps, dense, parts));
        let mut visited = runs as u32;
        for r in 0..runs {
            visited += pass.node(r, deeper);
        }
        let tests = pass.t.tests;
        drop(pass);
        core::mem::swap(K::list(s), &mut run_key);
        (tests, visited)
    }

    /// [`Octree::loose_pairs`] split over rayon's current pool: the walk-order sort in up to
    /// `out.len()` parts, then the runs in `out.len()` chunks of about equal sphere counts,
    /// each passed by its own task with its own pass state and scratch. Chunk `c` calls
    /// `emit(&mut out[c], a, b)` for each pair it finds. Every pair is found from one run, as
    /// in the serial pass, so once; the tests and nodes counted are the serial pass's.
    #[cfg(feature = "parallel")]
    pub(super) fn loose_pairs_chunked<S, E>(
        &self,
        ws: &mut walk::Scratch,
        s: &mut Scratch,
        out: &mut [S],
        emit: &E,
    ) -> PassCost
    where
        S: Send,
        E: Fn(&mut S, ProxyKey, ProxyKey) + Sync,
    {
        let k = out.len();
        if k == 0 {
            ws.ready = false;
            return PassCost::default();
        }
        if !self.ensure_walk(ws, k) {
            return PassCost::default();
        }
        let ws = &*ws;
        let (boxes, ids) = (&ws.boxes[..], &ws.items[..]);
        let deeper = self.occupied_below();
        let d = self.lattice.depth as usize;
        let cross = (0..=d).any(|l| deeper[l] && self.per_level[l] > 0);
        if s.chunks.len() < k {
            s.chunks.resize_with(k, Chunk::default);
        }
        let cost = if walk_key_bits(self.lattice.depth) <= 32 {
            self.loose_chunks::<u32, S, E>(s, ws.keys(), (boxes, ids), out, emit, cross, &deeper)
        } else {
            self.loose_chunks::<u64, S, E>(s, ws.keys(), (boxes, ids), out, emit, cross, &deeper)
        };
        s.clear_runs(cross);
        cost
    }

    /// The chunks of [`Octree::loose_pairs_chunked`] over the runs of `keys`, their keys
    /// listed as `K`.
    #[cfg(feature = "parallel")]
    #[allow(clippy::too_many_arguments)]
    fn loose_chunks<K: RunKey, S, E>(
        &self,
        s: &mut Scratch,
        keys: Keys<'_>,
        (boxes, ids): (&[SimdBox], &[u64]),
        out: &mut [S],
        emit: &E,
        cross: bool,
        deeper: &[bool; MAX_DEPTH as usize + 1],
    ) -> PassCost
    where
        S: Send,
        E: Fn(&mut S, ProxyKey, ProxyKey) + Sync,
    {
        use rayon::prelude::*;
        let k = out.len();
        s.index_runs_par::<K>(self, keys, cross, k);
        let run_key = core::mem::take(K::list(s));
        let Scratch {
            run_start,
            run_of,
            chunks,
            chunk_runs,
            ..
        } = &mut *s;
        let (run_start, run_of) = (&run_start[..], &run_of[..]);
        let first_run = |c: usize| chunk_runs[c] as usize;
        let cost = chunks[..k]
            .par_iter_mut()
            .zip(out.par_iter_mut())
            .enumerate()
            .map(|(c, (chunk, out))| {
                let (lo, hi) = (first_run(c), first_run(c + 1));
                let Chunk {
                    sweeps,
                    dense,
                    parts,
                } = chunk;
                let t = Tester {
                    versions: &self.versions,
                    tests: 0,
                    emit: |a, b| emit(out, a, b),
                };
                let runs_of = (&run_key[..], run_start, run_of);
                let mut pass = Pass::new(self, (boxes, ids), runs_of, t, (sweeps, dense, parts));
                if lo < hi {
                    pass.start_at(lo);
                }
                let mut visited = (hi - lo) as u32;
                for r in lo..hi {
                    visited += pass.node(r, deeper);
                }
                PassCost {
                    tests: pass.t.tests,
                    nodes_visited: visited,
                }
            })
            .reduce(PassCost::default, |a, b| PassCost {
                tests: a.tests + b.tests,
                nodes_visited: a.nodes_visited + b.nodes_visited,
            });
        *K::list(s) = run_key;
        cost
    }

    /// `deeper[L]`: some sphere lives below level `L`.
    fn occupied_below(&self) -> [bool; MAX_DEPTH as usize + 1] {
        let mut deeper = [false; MAX_DEPTH as usize + 1];
        let mut below = 0;
        for l in (0..=self.lattice.depth as usize).rev() {
            deeper[l] = below > 0;
            below += self.per_level[l];
        }
        deeper
    }
}

impl Scratch {
    /// Heap bytes held (capacities).
    pub(super) fn heap_bytes(&self) -> usize {
        self.run_key64.capacity() * 8
            + (self.run_key32.capacity()
                + self.run_start.capacity()
                + self.run_slot.capacity()
                + self.dense.capacity())
                * 4
            + self.run_of.capacity() * 8
            + self.parts.heap_bytes()
    }

    /// Lists the runs of `keys` (and, for a pass with cross-level pairs, records each in
    /// `run_of` by its node's slot), with the sentinel.
    fn index_runs<K: RunKey>(&mut self, tree: &Octree, keys: Keys<'_>, cross: bool) {
        let heads = tree.nodes.head_len();
        if cross && self.run_of.len() < heads {
            self.run_of.resize(heads, [0, 0]);
        }
        // Sized before they fill (`room_for`), not grown by doubling as they fill.
        let count = (1..keys.len())
            .filter(|&i| keys.get(i) != keys.get(i - 1))
            .count()
            + 1;
        let mut run_key = core::mem::take(K::list(self));
        room_for(&mut run_key, count + 1);
        room_for(&mut self.run_start, count + 1);
        if cross {
            room_for(&mut self.run_slot, count);
        }
        run_key.clear();
        self.run_start.clear();
        self.run_slot.clear();
        for (key, i, j) in runs(keys) {
            if cross {
                let (level, xyz) = LooseKey(key).cell(tree.lattice.depth);
                let slot = tree
                    .nodes
                    .slot(Cell::at(level, xyz).node())
                    .expect("an occupied node's page exists");
                self.run_of[slot] = [i as u32, j as u32];
                self.run_slot.push(slot as u32);
            }
            run_key.push(K::from_key(key));
            self.run_start.push(i as u32);
        }
        run_key.push(K::END);
        self.run_start.push(keys.len() as u32);
        *K::list(self) = run_key;
    }

    /// [`Scratch::index_runs`] over rayon's current pool: chunk `c` of `k` lists the runs that
    /// start in `[n·c/k, n·(c+1)/k)` of the `n` sorted spheres into its own stretch of the
    /// lists, after a first pass counted them; `chunk_runs` gets each chunk's first run and
    /// the run count last.
    #[cfg(feature = "parallel")]
    fn index_runs_par<K: RunKey>(&mut self, tree: &Octree, keys: Keys<'_>, cross: bool, k: usize) {
        use rayon::prelude::*;
        let heads = tree.nodes.head_len();
        if cross && self.run_of.len() < heads {
            self.run_of.resize(heads, [0, 0]);
        }
        let job = Runs {
            tree,
            keys,
            k,
            cross,
        };
        (0..k)
            .into_par_iter()
            .map(|c| job.count(c))
            .collect_into_vec(&mut self.chunk_runs);
        let mut sum = 0;
        for r in &mut self.chunk_runs {
            (*r, sum) = (sum, sum + *r);
        }
        self.chunk_runs.push(sum);
        let runs = sum as usize;
        let mut run_key = core::mem::take(K::list(self));
        room_for(&mut run_key, runs + 1);
        room_for(&mut self.run_start, runs + 1);
        if cross {
            room_for(&mut self.run_slot, runs);
        }
        run_key.resize(runs + 1, K::END);
        self.run_start.resize(runs + 1, 0);
        self.run_slot.resize(if cross { runs } else { 0 }, 0);
        job.fill(
            0..k,
            &self.chunk_runs,
            &mut run_key[..runs],
            &mut self.run_start[..runs],
            &mut self.run_slot,
        );
        run_key[runs] = K::END;
        *K::list(self) = run_key;
        self.run_start[runs] = keys.len() as u32;
        if cross {
            for (r, &slot) in self.run_slot.iter().enumerate() {
                self.run_of[slot as usize] = [self.run_start[r], self.run_start[r + 1]];
            }
        }
    }

    /// Resets the `run_of` entries [`Scratch::index_runs`] set.
    fn clear_runs(&mut self, cross: bool) {
        if cross {
            for &slot in &self.run_slot {
                self.run_of[slot as usize] = [0, 0];
            }
        }
    }
}

/// What every chunk of [`Scratch::index_runs_par`] reads.
#[cfg(feature = "parallel")]
struct Runs<'a> {
    tree: &'a Octree,
    keys: Keys<'a>,
    k: usize,
    cross: bool,
}

#[cfg(feature = "parallel")]
impl Runs<'_> {
    /// The sphere positions of chunk `c`.
    fn positions(&self, c: usize) -> core::ops::Range<usize> {
        let n = self.keys.len();
        n * c / self.k..n * (c + 1) / self.k
    }

    /// True if a run starts at position `i`.
    #[inline]
    fn starts(&self, i: usize) -> bool {
        i == 0 || self.keys.get(i) != self.keys.get(i - 1)
    }

    /// The runs that start in chunk `c`.
    fn count(&self, c: usize) -> u32 {
        self.positions(c).filter(|&i| self.starts(i)).count() as u32
    }

    /// Lists the runs of chunks `chunks` (whose first runs `first` gives, relative to the
    /// lists' stretches passed), halving the chunks between two tasks until one is left.
    fn fill<K: RunKey>(
        &self,
        chunks: core::ops::Range<usize>,
        first: &[u32],
        run_key: &mut [K],
        run_start: &mut [u32],
        run_slot: &mut [u32],
    ) {
        if chunks.len() > 1 {
            let mid = chunks.start + chunks.len() / 2;
            let at = (first[mid] - first[chunks.start]) as usize;
            let (ka, kb) = run_key.split_at_mut(at);
            let (sa, sb) = run_start.split_at_mut(at);
            let (la, lb) = run_slot.split_at_mut(if self.cross { at } else { 0 });
            rayon::join(
                || self.fill(chunks.start..mid, first, ka, sa, la),
                || self.fill(mid..chunks.end, first, kb, sb, lb),
            );
            return;
        }
        let mut r = 0;
        for i in chunks.clone().flat_map(|c| self.positions(c)) {
            if !self.starts(i) {
                continue;
            }
            let key = self.keys.get(i);
            run_key[r] = K::from_key(key);
            run_start[r] = i as u32;
            if self.cross {
                let (level, xyz) = LooseKey(key).cell(self.tree.lattice.depth);
                run_slot[r] = self
                    .tree
                    .nodes
                    .slot(Cell::at(level, xyz).node())
                    .expect("an occupied node's page exists") as u32;
            }
            r += 1;
        }
    }
}

#[cfg(all(test, feature = "parallel"))]
mod tests {
    use super::super::Placement;
    use super::*;
    use crate::geom::Aabb;
    use crate::rng::Rng;
    use glam::Vec3;

    /// The chunked pass finds the serial pass's pairs, each once, with the same test and node
    /// counts, for any number of chunks (more chunks than runs, too) and threads, in a tree
    /// with several occupied levels, crowded nodes and spheres outside the bounds.
    #[test]
    fn chunked_pass_finds_the_serial_pairs_once() {
        let bounds = Aabb::new(Vec3::splat(-40.0), Vec3::splat(40.0));
        let mut rng = Rng::new(7);
        for (n, depth) in [(1, 3), (40, 2), (3000, 5), (20_000, 6)] {
            let mut t = Octree::with_placement(bounds, depth, Placement::Loose).unwrap();
            for i in 0..n {
                let c = Vec3::new(
                    rng.range(-45.0, 45.0),
                    rng.range(-45.0, 45.0),
                    rng.range(-45.0, 45.0),
                );
                // A crowd in one corner, a few big spheres, the rest small.
                let c = if i % 9 == 0 {
                    c * 0.05 + Vec3::splat(20.0)
                } else {
                    c
                };
                let r = if i % 50 == 0 {
                    rng.range(2.0, 9.0)
                } else {
                    rng.range(0.1, 1.0)
                };
                t.insert(c, r).unwrap();
            }
            let pack = |a: ProxyKey, b: ProxyKey| {
                let (a, b) = (crate::pair::slot(a), crate::pair::slot(b));
                (u64::from(a.min(b)) << 32) | u64::from(a.max(b))
            };
            let mut want = Vec::new();
            t.for_each_pair(|a, b| want.push(pack(a, b)));
            want.sort_unstable();
            let serial = t.stats();
            for threads in [1, 3] {
                let pool = rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .build()
                    .unwrap();
                for chunks in [1, 2, 5, 64] {
                    let mut out = vec![Vec::new(); chunks];
                    let emit = |o: &mut Vec<u64>, a, b| o.push(pack(a, b));
                    pool.install(|| t.for_each_pair_chunked(&mut out, &emit, |_| ()));
                    let mut got: Vec<u64> = out.concat();
                    got.sort_unstable();
                    assert_eq!(got, want, "n {n} threads {threads} chunks {chunks}");
                    let st = t.stats();
                    assert_eq!(
                        (st.aabb_tests, st.nodes_visited),
                        (serial.aabb_tests, serial.nodes_visited),
                        "n {n} chunks {chunks}"
                    );
                }
            }
            t.validate();
        }
    }
}
