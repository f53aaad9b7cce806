//! Box, sphere and nearest queries, the box-based candidate traversal the `BroadPhase`
//! re-tests exactly, and the occupied-cell iterator (the casts are in `ray`). They follow the
//! node lists through occupied subtrees ([`Nodes::walk`](super::nodes::Nodes::walk)), entering
//! a node only if the region its spheres can reach meets the query; none allocates but
//! [`Octree::nearest`], for its result. The `_with` queries stop as soon as their visitor
//! returns [`ControlFlow::Break`], and say whether it did.
use super::cell::Cell;
use super::{NONE, Octree};
use crate::geom::{self, Aabb, SimdBox};
use crate::pair::ProxyKey;
use crate::search::{every, nearest_expanding, nearest_start_in_cells};
use core::ops::ControlFlow;
use glam::Vec3;

/// Queries whose reaching cells over the occupied levels are at most this many read those
/// cells' lists directly; larger ones walk the occupied subtrees.
const DIRECT_CELLS: u64 = 256;

/// A direct query reads the cells of a level through their parents' child masks when it
/// reaches more than this many of them (see `Octree::masked_cells`).
const MASKED_CELLS: u64 = 32;

/// A direct query reads the rows of at most this many cells without a branch per cell (see
/// `Octree::candidates`).
const ROW: u32 = 4;

/// Room for the list heads a direct query gathers: one per reaching cell and the root's,
/// and the reads past a short row's end, which are written but not kept.
const HEADS: usize = DIRECT_CELLS as usize + 1 + ROW as usize;

/// The per-sphere reads of the queries, in one place: what they need of a sphere's record
/// and of its node's list, whatever the layout of those.
impl Octree {
    /// The box of sphere `id` (`center ± radius`, recomputed: the record stores the sphere).
    #[inline(always)]
    pub(super) fn box_of(&self, id: u32) -> Aabb {
        self.objs[id as usize].aabb()
    }

    /// The centre and radius of sphere `id`, exactly as given.
    #[inline(always)]
    pub(super) fn sphere_of(&self, id: u32) -> (Vec3, f32) {
        let o = &self.objs[id as usize];
        (o.center, o.radius)
    }

    /// True if sphere `id` lives in the root.
    #[inline(always)]
    pub(super) fn in_root(&self, id: u32) -> bool {
        self.objs[id as usize].node == 0
    }

    /// Reads the first record of each of the lists `heads` (all non-empty): independent
    /// loads, which the core overlaps, where a walk's each wait for the visit before. The
    /// gathered walks (box queries, ray pieces) call it before walking the lists.
    #[inline(always)]
    pub(super) fn touch_first(&self, heads: &[u32]) {
        let touched = heads.iter().fold(0u32, |t, &h| {
            t ^ self.links[h as usize].next ^ self.objs[h as usize].radius.to_bits()
        });
        core::hint::black_box(touched);
    }

    /// The sphere after `i` in its node's list, `NONE` at the end.
    #[inline(always)]
    pub(super) fn next_in_list(&self, i: u32) -> u32 {
        self.links[i as usize].next
    }
}

impl Octree {
    /// Depth-first over occupied nodes from the root: `enter(cell)` decides whether to visit a
    /// node's spheres (`visit(id)`) and children; the root is always entered. The first
    /// `Break` of `visit` ends the walk (no node is entered after it) and is returned.
    pub(super) fn traverse(
        &self,
        mut enter: impl FnMut(&Cell) -> bool,
        mut visit: impl FnMut(u32) -> ControlFlow<()>,
    ) -> ControlFlow<()> {
        if self.is_empty() {
            return ControlFlow::Continue(());
        }
        let stopped = core::cell::Cell::new(false);
        self.nodes.walk(
            Cell::ROOT,
            |cell| !stopped.get() && enter(cell),
            |_, slot| {
                let mut i = self.nodes.head_at(slot);
                while i != NONE && !stopped.get() {
                    stopped.set(visit(i).is_break());
                    i = self.next_in_list(i);
                }
            },
        );
        if stopped.get() {
            ControlFlow::Break(())
        } else {
            ControlFlow::Continue(())
        }
    }

    /// Visits the ids of every sphere whose integer range overlaps `aabb`'s (a superset of
    /// the spheres overlapping `aabb`).
    ///
    /// A small query reads the lists of the cells that reach it directly, level by occupied
    /// level: no walk down from the root, whose upper levels cost a visit each while holding
    /// few spheres. A large one walks the occupied subtrees instead, whose masks skip empty
    /// regions.
    fn candidates(
        &self,
        aabb: &Aabb,
        mut visit: impl FnMut(u32) -> ControlFlow<()>,
    ) -> ControlFlow<()> {
        let (qlo, qhi) = (
            self.lattice.quantize(aabb.min),
            self.lattice.quantize(aabb.max),
        );
        let mut cells = 0u64;
        for level in 1..=self.lattice.depth {
            if self.per_level[level as usize] > 0 {
                let (a, b) = self.lattice.reaching_cells(level, qlo, qhi);
                cells += (0..3)
                    .map(|i| u64::from((b[i] + 1).saturating_sub(a[i])))
                    .product::<u64>();
            }
        }
        if cells > DIRECT_CELLS {
            return self.traverse(|cell| self.lattice.reaches(cell, qlo, qhi), visit);
        }
        // The heads of the reaching cells' lists are gathered first and their first spheres'
        // records read together (independent loads, which the core overlaps), then the lists
        // are walked in the same order: a walk's loads depend on each other, and the records
        // of a large world's neighbouring cells are rarely in the cache.
        let mut heads = [NONE; HEADS];
        let mut n = 0;
        let mut keep = |head: u32| {
            heads[n] = head;
            n += usize::from(head != NONE);
        };
        if self.per_level[0] > 0 {
            keep(self.nodes.head(0));
        }
        for level in 1..=self.lattice.depth {
            if self.per_level[level as usize] == 0 {
                continue;
            }
            let (a, b) = self.lattice.reaching_cells(level, qlo, qhi);
            let len = (b[0] + 1).saturating_sub(a[0]);
            let cells = (0..3)
                .map(|i| u64::from((b[i] + 1).saturating_sub(a[i])))
                .product::<u64>();
            if cells > MASKED_CELLS {
                self.masked_cells(level, a, b, &mut keep);
                continue;
            }
            for z in a[2]..=b[2] {
                for y in a[1]..=b[1] {
                    if len > ROW {
                        for x in a[0]..=b[0] {
                            keep(self.nodes.head(Cell::at(level, [x, y, z]).node()));
                        }
                        continue;
                    }
                    // A short row is read with no branch on its length or on which cells
                    // hold spheres (a coin toss each): each of its `ROW` reads is kept only
                    // if it is a cell of the row with a list.
                    for k in 0..ROW {
                        let x = a[0] + k.min(len - 1);
                        let head = self.nodes.head(Cell::at(level, [x, y, z]).node());
                        keep(if k < len { head } else { NONE });
                    }
                }
            }
        }
        let heads = &heads[..n];
        self.touch_first(heads);
        for &head in heads {
            let mut i = head;
            while i != NONE {
                visit(i)?;
                i = self.next_in_list(i);
            }
        }
        ControlFlow::Continue(())
    }

    /// Gives `keep` the list heads of the cells `a ..= b` of `level` (at least 1) that hold a
    /// sphere, found through their parents' child masks: one mask per parent cell instead of
    /// one list head per cell, most of which are empty in a sparse level. A mask bit says the
    /// child's subtree holds a sphere, which its own list may not: such a child's empty head
    /// is read too.
    fn masked_cells(&self, level: u32, a: [u32; 3], b: [u32; 3], keep: &mut impl FnMut(u32)) {
        // The octants of a parent at `p` (on one axis) whose child lies in `a ..= b`: `low`
        // are the octants of the lower child on that axis, `high` those of the upper one.
        let side = |p: u32, a: u32, b: u32, low: u8, high: u8| {
            let inside = |c: u32| a <= c && c <= b;
            (if inside(2 * p) { low } else { 0 }) | (if inside(2 * p + 1) { high } else { 0 })
        };
        for pz in a[2] / 2..=b[2] / 2 {
            let zm = side(pz, a[2], b[2], 0x0F, 0xF0);
            for py in a[1] / 2..=b[1] / 2 {
                let yzm = zm & side(py, a[1], b[1], 0x33, 0xCC);
                for px in a[0] / 2..=b[0] / 2 {
                    let inside = yzm & side(px, a[0], b[0], 0x55, 0xAA);
                    let parent = Cell::at(level - 1, [px, py, pz]);
                    let mut bits = u32::from(self.nodes.mask(parent.node()) & inside);
                    while bits != 0 {
                        let child = parent.child(bits.trailing_zeros());
                        bits &= bits - 1;
                        keep(self.nodes.head(child.node()));
                    }
                }
            }
        }
    }

    /// Calls `f` with the key of every sphere whose AABB overlaps `aabb` (closed), once each,
    /// in no particular order. A non-finite or inverted `aabb` finds nothing.
    pub fn query_aabb(&self, aabb: &Aabb, f: impl FnMut(ProxyKey)) {
        let _ = self.query_aabb_with(aabb, every(f));
    }

    /// [`Octree::query_aabb`] with a visitor that can stop: the first
    /// [`ControlFlow::Break`] ends the query and is returned; `Continue` if every match was
    /// visited.
    pub fn query_aabb_with(
        &self,
        aabb: &Aabb,
        f: impl FnMut(ProxyKey) -> ControlFlow<()>,
    ) -> ControlFlow<()> {
        if geom::check_aabb(aabb).is_err() {
            return ControlFlow::Continue(());
        }
        self.query_aabb_with_unchecked(aabb, f)
    }

    /// [`Octree::query_aabb`] without the input check, for boxes the crate made itself: a
    /// sphere or body near `f32::MAX` has a box that overflows to ±∞ from finite input, and it
    /// must still find what it overlaps.
    pub(crate) fn query_aabb_unchecked(&self, aabb: &Aabb, f: impl FnMut(ProxyKey)) {
        let _ = self.query_aabb_with_unchecked(aabb, every(f));
    }

    /// [`Octree::query_aabb_with`] without the input check.
    pub(crate) fn query_aabb_with_unchecked(
        &self,
        aabb: &Aabb,
        mut f: impl FnMut(ProxyKey) -> ControlFlow<()>,
    ) -> ControlFlow<()> {
        self.candidates(aabb, |id| {
            if self.box_of(id).overlaps(aabb) {
                f(self.key_of(id))
            } else {
                ControlFlow::Continue(())
            }
        })
    }

    /// Calls `f` with the key of every sphere that overlaps the query sphere (centre distance
    /// `<= r1 + r2`, so touching spheres count), once each, in no particular order. A
    /// non-finite centre or radius, or a negative radius, finds nothing.
    pub fn query_sphere(&self, center: Vec3, radius: f32, f: impl FnMut(ProxyKey)) {
        let _ = self.query_sphere_with(center, radius, every(f));
    }

    /// [`Octree::query_sphere`] with a visitor that can stop: the first
    /// [`ControlFlow::Break`] ends the query and is returned; `Continue` if every match was
    /// visited.
    pub fn query_sphere_with(
        &self,
        center: Vec3,
        radius: f32,
        mut f: impl FnMut(ProxyKey) -> ControlFlow<()>,
    ) -> ControlFlow<()> {
        if geom::check_sphere(center, radius).is_err() {
            return ControlFlow::Continue(());
        }
        self.candidates(&Aabb::from_center_radius(center, radius), |id| {
            let (c, r) = self.sphere_of(id);
            if geom::spheres_touch(c, r, center, radius) {
                f(self.key_of(id))
            } else {
                ControlFlow::Continue(())
            }
        })
    }

    /// Calls `visit(id)` for every sphere of every node whose reach box, grown by the rounding tolerance, is
    /// within `radius` of `p` (`point_aabb_distance`): a superset of the spheres whose
    /// box is within `radius`, since that box lies in the grown reach box and the distance
    /// does not decrease as a box shrinks.
    fn near_ids(
        &self,
        p: Vec3,
        radius: f32,
        visit: impl FnMut(u32) -> ControlFlow<()>,
    ) -> ControlFlow<()> {
        // A box within `radius` of `p` overlaps the cube `p ± radius`.
        self.candidates(&Aabb::from_center_radius(p, radius), visit)
    }

    /// Calls `f(key)` for every sphere whose pruning box (`sphere_prune_box`)
    /// overlaps the cube `p ± radius`, once
    /// each: a superset of those within `radius` of `p`, for callers that measure exact
    /// distances themselves. Nothing for a non-finite `p` or a NaN or negative `radius`. The
    /// first `Break` of `f` ends it and is returned.
    pub(crate) fn near(
        &self,
        p: Vec3,
        radius: f32,
        mut f: impl FnMut(ProxyKey) -> ControlFlow<()>,
    ) -> ControlFlow<()> {
        if !p.is_finite() || radius.is_nan() || radius < 0.0 {
            return ControlFlow::Continue(());
        }
        let cube = Aabb::from_center_radius(p, radius);
        let simd_cube = SimdBox::new(&cube);
        self.near_ids(p, radius, |id| {
            let (c, r) = self.sphere_of(id);
            if geom::sphere_prune_box(c, r, 0.0).overlaps(&simd_cube) {
                f(self.key_of(id))
            } else {
                ControlFlow::Continue(())
            }
        })
    }

    /// The `k` spheres nearest `point` by `point_sphere_distance` (0 inside a sphere),
    /// with their distances, sorted by `(distance, key)`: the first `k` of all spheres in that
    /// order (all of them if there are fewer). Empty for `k == 0` or a non-finite `point`.
    ///
    /// An expanding search: starting from the distance to the bounds plus a part of the
    /// edge of `k` cells of the most populated level, each round computes the exact
    /// distance of every sphere of the nodes within the radius (plus a relative pad, as the
    /// node test rounds differently from the `f32` box corners) and doubles the radius until
    /// `k` spheres are within it or every sphere was seen. A sphere not seen is farther than
    /// the radius, so the first `k` seen in `(distance, key)` order are the answer.
    #[must_use]
    pub fn nearest(&self, point: Vec3, k: usize) -> Vec<(ProxyKey, f32)> {
        let n = self.live;
        if k == 0 || n == 0 || !point.is_finite() {
            return Vec::new();
        }
        let start = self.nearest_start(point, k);
        let mut out = Vec::new();
        nearest_expanding(k, n, start, &mut out, |radius, out| {
            let reach = radius + geom::distance_pad(point, radius);
            let _ = self.near_ids(point, reach, |id| {
                let (c, r) = self.sphere_of(id);
                let d = geom::point_sphere_distance(point, c, r);
                out.push((self.key_of(id), d));
                ControlFlow::Continue(())
            });
            out.len()
        });
        out
    }

    /// Where a search for the `k` spheres nearest `point` starts
    /// ([`nearest_start_in_cells`]): from the cells of the level holding the most spheres
    /// below the root (the root's cell if none does), not from the region's size, which a
    /// growing tree keeps well above its spheres' span. `+∞` for an empty tree.
    pub(crate) fn nearest_start(&self, point: Vec3, k: usize) -> f32 {
        if self.live == 0 {
            return f32::INFINITY;
        }
        let level = (1..=self.lattice.depth)
            .max_by_key(|&l| (self.per_level[l as usize], core::cmp::Reverse(l)))
            .filter(|&l| self.per_level[l as usize] > 0)
            .unwrap_or(0);
        let cell = self.lattice.bounds.extent().max_element() / (1u32 << level) as f32;
        nearest_start_in_cells(point, &self.lattice.bounds, k, cell)
    }

    /// Calls `f(level, cell)` for every node that holds at least one sphere, parents before
    /// their children: the cell itself in strict mode, its loose bounds (the cell grown by half
    /// its size) in loose mode. Overflow spheres live in the root.
    pub fn for_each_occupied_cell(&self, mut f: impl FnMut(u32, Aabb)) {
        if self.is_empty() {
            return;
        }
        self.nodes.walk(
            Cell::ROOT,
            |_| true,
            |cell, slot| {
                if self.nodes.head_at(slot) != NONE {
                    f(cell.level, self.lattice.reach_box(cell));
                }
            },
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Placement;
    use crate::rng::Rng;
    use crate::test_geom::segment_in_box;
    use std::collections::BTreeMap;

    /// The distance from `p` to the box `lo..=hi`, in `f64`: `p` minus its clamp to the box.
    fn box_distance(p: Vec3, lo: Vec3, hi: Vec3) -> f64 {
        (0..3)
            .map(|a| {
                let x = f64::from(p[a]);
                let q = x.clamp(f64::from(lo[a]), f64::from(hi[a]));
                (x - q) * (x - q)
            })
            .sum::<f64>()
            .sqrt()
    }

    /// A tree with spheres inside and outside its bounds (some of radius 0, some large,
    /// some coincident), with its own list of `(key, centre, radius)`.
    fn world(seed: u64, placement: Placement) -> (Octree, Vec<(ProxyKey, Vec3, f32)>) {
        let mut rng = Rng::new(seed);
        let bounds = Aabb::new(Vec3::splat(-20.0), Vec3::splat(20.0));
        let mut tree = Octree::with_placement(bounds, 4, placement).unwrap();
        let mut shapes = Vec::new();
        for i in 0..300 {
            let c = rng.vec3_in(Vec3::splat(-24.0), Vec3::splat(24.0));
            let r = match i % 10 {
                0 => 0.0,
                1 => rng.range(4.0, 12.0),
                _ => rng.range(0.05, 2.0),
            };
            let (c, r) = match shapes.last() {
                Some(&(_, c, r)) if i % 50 == 7 => (c, r),
                _ => (c, r),
            };
            shapes.push((tree.insert(c, r).unwrap(), c, r));
        }
        // Removals move other spheres to new dense slots; the list keeps what is live.
        for _ in 0..30 {
            let i = rng.below(shapes.len() as u32) as usize;
            tree.remove(shapes.swap_remove(i).0).unwrap();
        }
        (tree, shapes)
    }

    /// A sphere's box as the queries prune it: the radius grown by `2⁻²⁰` of itself and by
    /// `inflate`.
    fn own_box(c: Vec3, r: f32, inflate: f32) -> (Vec3, Vec3) {
        let r = r * (1.0 + 2f32.powi(-20)) + inflate;
        (
            Vec3::new(c.x - r, c.y - r, c.z - r),
            Vec3::new(c.x + r, c.y + r, c.z + r),
        )
    }

    /// Box queries over a deep sparse tree, sized to reach more than [`MASKED_CELLS`] cells of
    /// its deepest level (read through the parents' masks) and, for some, more than
    /// [`DIRECT_CELLS`] in all (the walk from the root), equal a scan of the spheres.
    #[test]
    fn box_queries_through_the_masks_find_every_overlapping_sphere() {
        for (seed, placement) in [(3, Placement::Strict), (4, Placement::Loose)] {
            let mut rng = Rng::new(seed);
            let bounds = Aabb::new(Vec3::splat(-64.0), Vec3::splat(64.0));
            let mut tree = Octree::with_placement(bounds, 7, placement).unwrap();
            let shapes: Vec<(ProxyKey, Vec3, f32)> = (0..3000)
                .map(|_| {
                    let c = rng.vec3_in(Vec3::splat(-66.0), Vec3::splat(66.0));
                    let r = rng.range(0.05, 0.6);
                    (tree.insert(c, r).unwrap(), c, r)
                })
                .collect();
            let deepest = (1..=tree.lattice.depth)
                .rev()
                .find(|&l| tree.per_level[l as usize] > 0)
                .unwrap();
            let (mut masked, mut walked) = (0, 0);
            for q in 0..600 {
                let lo = rng.vec3_in(Vec3::splat(-70.0), Vec3::splat(70.0));
                let side = if q % 5 == 0 { 12.0 } else { 4.0 };
                let aabb = Aabb::new(lo, lo + rng.vec3_in(Vec3::ZERO, Vec3::splat(side)));
                let (qlo, qhi) = (
                    tree.lattice.quantize(aabb.min),
                    tree.lattice.quantize(aabb.max),
                );
                let (a, b) = tree.lattice.reaching_cells(deepest, qlo, qhi);
                let cells: u64 = (0..3)
                    .map(|i| u64::from((b[i] + 1).saturating_sub(a[i])))
                    .product();
                masked += usize::from(cells > MASKED_CELLS && cells <= DIRECT_CELLS);
                walked += usize::from(cells > DIRECT_CELLS);
                let mut got = Vec::new();
                tree.query_aabb(&aabb, |k| got.push(k));
                got.sort_unstable();
                let mut want: Vec<ProxyKey> = shapes
                    .iter()
                    .filter(|&&(_, c, r)| Aabb::new(c - r, c + r).overlaps(&aabb))
                    .map(|&(k, _, _)| k)
                    .collect();
                want.sort_unstable();
                assert_eq!(got, want, "{placement:?} query {q} {aabb:?}");
            }
            assert!(
                masked > 100 && walked > 20,
                "masked {masked}, walked {walked}"
            );
        }
    }

    #[test]
    fn ray_candidates_visit_every_hit_box_exactly_once() {
        for (seed, placement) in [(1, Placement::Strict), (2, Placement::Loose)] {
            let (tree, shapes) = world(seed, placement);
            let mut rng = Rng::new(seed + 100);
            for q in 0..300 {
                let o = rng.vec3_in(Vec3::splat(-30.0), Vec3::splat(30.0));
                let d = match q % 7 {
                    0 => Vec3::ZERO,
                    1 => Vec3::X * rng.range(-2.0, 2.0),
                    _ => rng.vec3_in(Vec3::splat(-2.0), Vec3::splat(2.0)),
                };
                let max_t = rng.range(0.0, 40.0);
                let inflate = if q % 3 == 0 { 0.0 } else { rng.range(0.0, 3.0) };
                let mut seen = BTreeMap::new();
                tree.ray_candidates(o, d, max_t, inflate, |key, aabb| {
                    assert_eq!(Some(*aabb), tree.aabb(key));
                    *seen.entry(key).or_insert(0) += 1;
                    max_t
                });
                assert!(seen.values().all(|&n| n == 1), "a sphere visited twice");
                let inv = geom::inverse_dir(d);
                for &(key, c, r) in &shapes {
                    let (lo, hi) = own_box(c, r, inflate);
                    // The contract, box by box.
                    let hit = Aabb::new(lo, hi).ray_entry(o, inv, max_t).is_some();
                    assert_eq!(seen.contains_key(&key), hit, "query {q} key {key:?}");
                    // The test's own slab loop agrees wherever it is clear-cut.
                    let inside = segment_in_box(o, d, max_t, lo, hi);
                    if inside.is_some_and(|(t0, t1)| t1 - t0 > 1e-3) {
                        assert!(hit, "query {q}: a box the segment crosses was skipped");
                    }
                    let near = segment_in_box(o, d, max_t, lo - 1e-3, hi + 1e-3);
                    if near.is_none() {
                        assert!(!hit, "query {q}: a box the segment misses was visited");
                    }
                }
            }
        }
    }

    #[test]
    fn ray_candidates_shrink_to_the_returned_value_and_keep_ties() {
        let (mut tree, mut shapes) = world(3, Placement::Strict);
        // Two coincident spheres: one entry t, two keys, both must be seen.
        for _ in 0..2 {
            let c = Vec3::new(5.0, 1.0, -2.0);
            shapes.push((tree.insert(c, 0.5).unwrap(), c, 0.5));
        }
        let mut rng = Rng::new(33);
        for q in 0..300 {
            let o = if q == 0 {
                Vec3::new(-30.0, 1.0, -2.0)
            } else {
                rng.vec3_in(Vec3::splat(-30.0), Vec3::splat(30.0))
            };
            let d = if q == 0 {
                Vec3::X
            } else {
                rng.vec3_in(Vec3::splat(-1.0), Vec3::splat(1.0))
            };
            let (max_t, inflate) = (60.0, 0.25);
            let inv = geom::inverse_dir(d);
            let entry = |c: Vec3, r: f32| {
                let (lo, hi) = own_box(c, r, inflate);
                Aabb::new(lo, hi).ray_entry(o, inv, max_t)
            };
            let mut seen = Vec::new();
            let mut last = f32::INFINITY;
            tree.ray_candidates(o, d, max_t, inflate, |key, aabb| {
                seen.push(key);
                let (c, r) = tree.sphere(key).unwrap();
                assert_eq!(*aabb, Aabb::from_center_radius(c, r));
                let t = entry(c, r).unwrap_or(f32::NAN);
                assert!(
                    t <= last,
                    "query {q}: visited a box entered behind the best"
                );
                last = last.min(t);
                t
            });
            let best = shapes
                .iter()
                .filter_map(|s| entry(s.1, s.2))
                .reduce(f32::min);
            let Some(best) = best else {
                assert!(seen.is_empty());
                continue;
            };
            for &(key, c, r) in &shapes {
                if entry(c, r) == Some(best) {
                    assert!(
                        seen.contains(&key),
                        "query {q}: a tie at the best t was skipped"
                    );
                }
            }
            if q == 0 {
                let ties = shapes
                    .iter()
                    .filter(|s| entry(s.1, s.2) == Some(best))
                    .count();
                assert!(ties >= 2);
            }
        }
    }

    #[test]
    fn near_visits_every_near_box_once_and_only_boxes_meeting_the_cube() {
        for (seed, placement) in [(4, Placement::Strict), (5, Placement::Loose)] {
            let (tree, shapes) = world(seed, placement);
            let mut rng = Rng::new(seed + 100);
            for q in 0..300 {
                let p = rng.vec3_in(Vec3::splat(-30.0), Vec3::splat(30.0));
                let radius = match q % 5 {
                    0 => 0.0,
                    1 => rng.range(10.0, 40.0),
                    _ => rng.range(0.0, 5.0),
                };
                let mut seen = BTreeMap::new();
                let _ = tree.near(p, radius, |key| {
                    *seen.entry(key).or_insert(0) += 1;
                    ControlFlow::Continue(())
                });
                assert!(seen.values().all(|&n| n == 1), "a sphere visited twice");
                for &(key, c, r) in &shapes {
                    let (lo, hi) = own_box(c, r, 0.0);
                    // The test's own distance: every box within the radius is visited.
                    if box_distance(p, lo, hi) <= f64::from(radius) - 1e-4 {
                        assert!(seen.contains_key(&key), "query {q}: a near box skipped");
                    }
                    // Only boxes that meet the cube `p ± radius`, by the test's own compare.
                    let meets = (0..3).all(|a| lo[a] <= p[a] + radius && p[a] - radius <= hi[a]);
                    if seen.contains_key(&key) {
                        assert!(meets, "query {q}: a box off the cube visited");
                    }
                }
            }
        }
    }

    #[test]
    fn candidate_traversals_refuse_bad_arguments() {
        let (tree, _) = world(6, Placement::Strict);
        let mut n = 0;
        let nan = f32::NAN;
        for (o, d, max_t, inflate) in [
            (Vec3::new(nan, 0.0, 0.0), Vec3::X, 10.0, 0.0),
            (Vec3::ZERO, Vec3::new(0.0, f32::INFINITY, 0.0), 10.0, 0.0),
            (Vec3::ZERO, Vec3::X, nan, 0.0),
            (Vec3::ZERO, Vec3::X, -1.0, 0.0),
            (Vec3::ZERO, Vec3::X, 10.0, -1.0),
            (Vec3::ZERO, Vec3::X, 10.0, nan),
        ] {
            tree.ray_candidates(o, d, max_t, inflate, |_, _| {
                n += 1;
                0.0
            });
        }
        for (p, radius) in [
            (Vec3::new(nan, 0.0, 0.0), 100.0),
            (Vec3::splat(f32::INFINITY), 100.0),
            (Vec3::ZERO, -1.0),
            (Vec3::ZERO, nan),
        ] {
            let _ = tree.near(p, radius, |_| {
                n += 1;
                ControlFlow::Continue(())
            });
        }
        assert_eq!(n, 0);
    }
}
