//! Box, sphere, ray, sphere-cast and nearest queries, the box-based candidate traversals the
//! `BroadPhase` re-tests exactly, and the occupied-cell iterator. They follow the node lists
//! through occupied subtrees ([`Nodes::walk`](super::nodes::Nodes::walk)), entering a node only
//! if the region its spheres can reach meets the query; none allocates but
//! [`Octree::nearest`], for its result. The `_with` queries stop as soon as their visitor
//! returns [`ControlFlow::Break`], and say whether it did.

use super::cell::{Cell, morton, node_index};
use super::{NONE, Octree, Placement};
use crate::geom::{self, Aabb, SimdBox};
use crate::pair::ProxyKey;
use crate::search::{FirstHit, Slab, every, nearest_expanding, nearest_start_in_cells};
use core::ops::ControlFlow;
use glam::Vec3;

/// Queries whose reaching cells over the occupied levels are at most this many read those
/// cells' lists directly; larger ones walk the occupied subtrees.
const DIRECT_CELLS: u64 = 256;

/// A direct query reads the rows of at most this many cells without a branch per cell (see
/// `Octree::candidates`).
const ROW: u32 = 4;

/// A ray is cut into pieces no longer than the deepest occupied level's cells; one longer than
/// this many pieces walks the occupied subtrees instead.
const MAX_RAY_PIECES: f32 = 65_536.0;

/// How a ray reads the spheres below the root ([`Octree::ray_plan`]).
enum RayPlan {
    /// The segment misses the region they lie in (or there are none).
    Miss,
    /// By walking the occupied subtrees.
    Walk,
    /// By pieces in order of `t`, each reading the cells the previous one did not.
    Pieces(RayPieces),
}

/// A ray cut into pieces: `t0..t1` (within the region) in steps of `dt` (about a deepest
/// occupied cell), each piece's box grown by `slack`.
#[derive(Clone, Copy)]
struct RayPieces {
    t0: f32,
    t1: f32,
    dt: f32,
    slack: f32,
}

/// Relative widening of a ray piece's box against the rounding of its end points.
const RAY_PIECE_SLACK: f32 = 1e-5;

/// A ray whose pieces, grown by the cast's radius and the slack, would be wider than this many
/// deepest cells walks the occupied subtrees instead: such pieces overlap each other so much
/// that each would read most of what its neighbours read (a huge sphere cast would read every
/// cell once per piece).
const MAX_PIECE_CELLS: f32 = 8.0;

/// The per-sphere reads of the queries, in one place: what they need of a sphere's record
/// and of its node's list, whatever the layout of those.
impl Octree {
    /// The box of sphere `id` (`center ± radius`, recomputed: the record stores the sphere).
    #[inline(always)]
    fn box_of(&self, id: u32) -> Aabb {
        self.objs[id as usize].aabb()
    }

    /// The centre and radius of sphere `id`, exactly as given.
    #[inline(always)]
    fn sphere_of(&self, id: u32) -> (Vec3, f32) {
        let o = &self.objs[id as usize];
        (o.center, o.radius)
    }

    /// True if sphere `id` lives in the root.
    #[inline(always)]
    fn in_root(&self, id: u32) -> bool {
        self.objs[id as usize].node == 0
    }

    /// The sphere after `i` in its node's list, `NONE` at the end.
    #[inline(always)]
    fn next_in_list(&self, i: u32) -> u32 {
        self.links[i as usize].next
    }
}

impl Octree {
    /// Depth-first over occupied nodes from the root: `enter(cell)` decides whether to visit a
    /// node's spheres (`visit(id)`) and children; the root is always entered. The first
    /// `Break` of `visit` ends the walk (no node is entered after it) and is returned.
    fn traverse(
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
        let mut list = |head: u32| {
            let mut i = head;
            while i != NONE {
                visit(i)?;
                i = self.next_in_list(i);
            }
            ControlFlow::Continue(())
        };
        if self.per_level[0] > 0 {
            list(self.nodes.head(0))?;
        }
        for level in 1..=self.lattice.depth {
            if self.per_level[level as usize] == 0 {
                continue;
            }
            let (a, b) = self.lattice.reaching_cells(level, qlo, qhi);
            let len = (b[0] + 1).saturating_sub(a[0]);
            for z in a[2]..=b[2] {
                for y in a[1]..=b[1] {
                    if len > ROW {
                        for x in a[0]..=b[0] {
                            list(self.nodes.head(Cell::at(level, [x, y, z]).node()))?;
                        }
                        continue;
                    }
                    // A short row is read with no branch on its length or on which cells
                    // hold spheres (a coin toss each): the heads of its cells are kept,
                    // passing over the empty ones, then their lists are read.
                    let mut heads = [NONE; ROW as usize];
                    let mut n = 0;
                    for k in 0..ROW {
                        let x = a[0] + k.min(len - 1);
                        let head = self.nodes.head(Cell::at(level, [x, y, z]).node());
                        heads[n] = head;
                        n += usize::from(k < len && head != NONE);
                    }
                    for &head in &heads[..n] {
                        list(head)?;
                    }
                }
            }
        }
        ControlFlow::Continue(())
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

    /// The closest sphere hit by the segment `origin + t·dir`, `t ∈ [0, max_t]` (`t` in units
    /// of `dir`; an origin inside a sphere hits at 0), per `ray_sphere`; ties go to
    /// the smaller key. A non-finite origin or direction, or a NaN or negative `max_t`, hits
    /// nothing.
    #[must_use]
    pub fn cast_ray(&self, origin: Vec3, dir: Vec3, max_t: f32) -> Option<(ProxyKey, f32)> {
        if !geom::ray_is_valid(origin, dir, max_t) {
            return None;
        }
        let mut hit = FirstHit::new(max_t);
        // The `f64` sphere test may hit where the `f32` node tests round the other way.
        let pad = geom::cast_pad(origin, 0.0, dir, max_t);
        self.ray_ids(origin, dir, max_t, pad, |id, limit| {
            let (c, r) = self.sphere_of(id);
            let t = geom::ray_sphere(origin, dir, c, r, limit);
            hit.offer(self.key_of(id), t)
        });
        hit.best()
    }

    /// Calls `f(key, t)` for every sphere hit by the segment (same rules as
    /// [`Octree::cast_ray`]), once each, in no particular order.
    pub fn cast_ray_all(
        &self,
        origin: Vec3,
        dir: Vec3,
        max_t: f32,
        mut f: impl FnMut(ProxyKey, f32),
    ) {
        self.cast_ray_all_with(
            origin,
            dir,
            max_t,
            |c, r| geom::ray_sphere(origin, dir, c, r, max_t),
            &mut f,
        );
    }

    /// Calls `f(key, t)` for every sphere `(c, r)` of a cell the segment enters for which
    /// `hit(c, r)` gives a `t`.
    pub(crate) fn cast_ray_all_with(
        &self,
        origin: Vec3,
        dir: Vec3,
        max_t: f32,
        hit: impl Fn(Vec3, f32) -> Option<f32>,
        f: &mut impl FnMut(ProxyKey, f32),
    ) {
        if !geom::ray_is_valid(origin, dir, max_t) {
            return;
        }
        let inv = geom::inverse_dir(dir);
        let pad = self.lattice.rounding() + geom::cast_pad(origin, 0.0, dir, max_t);
        let _ = self.traverse(
            |cell| {
                self.lattice
                    .reach_box(cell)
                    .grown(pad)
                    .ray_entry(origin, inv, max_t)
                    .is_some()
            },
            |id| {
                let (c, r) = self.sphere_of(id);
                if let Some(t) = hit(c, r) {
                    f(self.key_of(id), t);
                }
                ControlFlow::Continue(())
            },
        );
    }

    /// Calls `visit(id, best)`, once each, for the spheres of the root and of every node whose
    /// reach the segment `origin + t·dir`, `t ∈ [0, best]` may meet (grown by the rounding tolerance and by
    /// `inflate`; nearer nodes first, a few beside the segment too), where `best` starts at
    /// `max_t` and becomes `min(best, returned value)` after each visit (a NaN return leaves
    /// it). Every sphere whose box grown by `inflate` the segment enters is among them: below
    /// the root a sphere's box lies in its node's reach box grown by the rounding tolerance.
    fn ray_ids(
        &self,
        origin: Vec3,
        dir: Vec3,
        max_t: f32,
        inflate: f32,
        mut visit: impl FnMut(u32, f32) -> f32,
    ) {
        let mut best = max_t;
        // The root's spheres (overflow, and strict straddlers of its planes) once, up front.
        let mut i = self.nodes.head(0);
        while i != NONE {
            best = best.min(visit(i, best));
            i = self.next_in_list(i);
        }
        match self.ray_plan(origin, dir, best, inflate) {
            RayPlan::Miss => {}
            RayPlan::Walk => self.ray_ids_walk(origin, dir, best, inflate, |id, b| {
                if self.in_root(id) { b } else { visit(id, b) }
            }),
            RayPlan::Pieces(p) => self.ray_ids_pieces(origin, dir, &p, best, visit),
        }
    }

    /// How [`Octree::ray_ids`] reads the spheres below the root along the segment
    /// `t ∈ [0, best]`: not at all if it misses the region they lie in, by pieces of about a
    /// deepest occupied cell, or by walking the tree where pieces would not pay.
    fn ray_plan(&self, origin: Vec3, dir: Vec3, best: f32, inflate: f32) -> RayPlan {
        let Some(deepest) = (1..=self.lattice.depth)
            .rev()
            .find(|&l| self.per_level[l as usize] > 0)
        else {
            return RayPlan::Miss;
        };
        // Spheres below the root lie in their cells' reach boxes grown by the rounding tolerance: within
        // the bounds (strict), or within them grown by half a cell of the shallowest occupied
        // level (loose); twice it covers the rounding of the region's own corners.
        let extent = self.lattice.bounds.extent();
        let reach = match self.lattice.placement {
            Placement::Strict => 0.0,
            Placement::Loose => {
                let shallowest = (1..=deepest)
                    .find(|&l| self.per_level[l as usize] > 0)
                    .unwrap_or(deepest);
                extent.max_element() / (2u32 << shallowest) as f32
            }
        };
        let region = self
            .lattice
            .bounds
            .grown(reach + 2.0 * self.lattice.rounding() + inflate);
        let inv = geom::inverse_dir(dir);
        let Some(t0) = region.ray_entry(origin, inv, best) else {
            return RayPlan::Miss;
        };
        let t1 = region.ray_exit(origin, inv, best);
        let cell = extent.min_element() / (1u32 << deepest) as f32;
        let dt = cell / dir.abs().max_element();
        let pieces = (t1 - t0) / dt;
        let (a, b) = (origin + dir * t0, origin + dir * t1);
        let slack = RAY_PIECE_SLACK * a.abs().max(b.abs()).max_element().max(1.0) + inflate;
        let piece_cells = (slack + slack + cell) / cell;
        // A zero direction has no pieces (`dt = ∞` would make the first one NaN, a box over
        // every cell): it, a ray of too many pieces and one of too wide pieces walk the tree.
        if !(dt > 0.0
            && dt.is_finite()
            && pieces.is_finite()
            && pieces <= MAX_RAY_PIECES
            && piece_cells <= MAX_PIECE_CELLS)
        {
            return RayPlan::Walk;
        }
        RayPlan::Pieces(RayPieces { t0, t1, dt, slack })
    }

    /// The spheres below the root along the ray, piece by piece (see [`RayPlan::Pieces`]),
    /// `best` shrinking to what `visit` returns.
    fn ray_ids_pieces(
        &self,
        origin: Vec3,
        dir: Vec3,
        p: &RayPieces,
        mut best: f32,
        mut visit: impl FnMut(u32, f32) -> f32,
    ) {
        let RayPieces { t0, t1, dt, slack } = *p;
        // Pieces in order of `t`, each a box around its stretch of the segment grown by
        // `inflate` and a slack fixed for the whole ray. Each axis' piece intervals only move
        // forward, and so do the cell ranges that reach them at every level: the pieces a
        // cell reaches are consecutive, so reading at each piece only the cells the previous
        // piece did not reach reads every cell once, in the first piece it reaches, and every
        // sphere with it (its exact test decides; one read early costs nothing but the test).
        let q = |t_lo: f32, t_hi: f32| {
            let (p, r) = (origin + dir * t_lo, origin + dir * t_hi);
            Aabb::new(p.min(r) - Vec3::splat(slack), p.max(r) + Vec3::splat(slack))
        };
        // The occupied levels below the root, each with the cell range its last piece read.
        let mut levels = [(0u32, [1u32; 3], [0u32; 3]); super::MAX_DEPTH as usize];
        let mut occupied = 0;
        for level in 1..=self.lattice.depth {
            if self.per_level[level as usize] > 0 {
                levels[occupied].0 = level;
                occupied += 1;
            }
        }
        let mut k = 0u32;
        loop {
            let ta = t0 + dt * k as f32;
            if ta > t1.min(best) {
                break;
            }
            let tb = (t0 + dt * (k + 1) as f32).min(t1);
            let piece = q(ta, tb);
            let (qlo, qhi) = (
                self.lattice.quantize(piece.min),
                self.lattice.quantize(piece.max),
            );
            for (level, pa, pb) in &mut levels[..occupied] {
                let (a, b) = self.lattice.reaching_cells(*level, qlo, qhi);
                let (pa, pb) = (core::mem::replace(pa, a), core::mem::replace(pb, b));
                // A cell's node is its level's first plus its Morton code, whose bits of `x`,
                // `y` and `z` are or-ed: a row computes those of `y` and `z` once.
                let first = node_index(*level, 0);
                let mut row = |y: u32, z: u32, x0: u32, x1: u32| {
                    let yz = morton([0, y, z]);
                    for x in x0..x1 + 1 {
                        let mut i = self.nodes.head(first + (yz | morton([x, 0, 0])));
                        while i != NONE {
                            best = best.min(visit(i, best));
                            i = self.next_in_list(i);
                        }
                    }
                };
                for z in a[2]..b[2] + 1 {
                    let z_read = pa[2] <= z && z <= pb[2];
                    for y in a[1]..b[1] + 1 {
                        let read = z_read && pa[1] <= y && y <= pb[1];
                        if !read || pa[0] > pb[0] {
                            row(y, z, a[0], b[0]);
                            continue;
                        }
                        // A row the last piece read in part: only its cells outside
                        // `pa.x..=pb.x`, on either side.
                        if a[0] < pa[0] {
                            row(y, z, a[0], b[0].min(pa[0] - 1));
                        }
                        if pb[0] < b[0] {
                            row(y, z, a[0].max(pb[0] + 1), b[0]);
                        }
                    }
                }
            }
            if tb >= t1 {
                break;
            }
            k += 1;
        }
    }

    /// [`Octree::ray_ids`] by a walk over the occupied subtrees, for rays too long for pieces.
    fn ray_ids_walk(
        &self,
        origin: Vec3,
        dir: Vec3,
        max_t: f32,
        inflate: f32,
        mut visit: impl FnMut(u32, f32) -> f32,
    ) {
        let inv = geom::inverse_dir(dir);
        let rounding = self.lattice.rounding();
        let best = core::cell::Cell::new(max_t);
        let _ = self.traverse(
            |cell| {
                self.lattice
                    .reach_box(cell)
                    .grown(rounding)
                    .grown(inflate)
                    .ray_entry(origin, inv, best.get())
                    .is_some()
            },
            |id| {
                best.set(best.get().min(visit(id, best.get())));
                ControlFlow::Continue(())
            },
        );
    }

    /// Calls `visit(key, aabb)`, `aabb` its stored box `center ± radius`, for every sphere
    /// whose pruning box with `inflate` added to its radius, `center ± (radius·(1 + 2⁻²⁰) +
    /// inflate)` (`sphere_prune_box`, for the `f64` re-tests), the segment
    /// `origin + t·dir`, `t ∈ [0, best]` enters ([`Aabb::ray_entry`], touching counts), once each; `best` starts at `max_t` and becomes
    /// `min(best, returned value)` after each visit (a NaN return leaves it), so a sphere
    /// entered exactly at `best` is still visited. Nodes come in walk order, not by distance.
    /// Nothing for a non-finite origin or direction, a NaN or negative `max_t`, or a NaN or
    /// negative `inflate`; no allocation.
    pub(crate) fn ray_candidates(
        &self,
        origin: Vec3,
        dir: Vec3,
        max_t: f32,
        inflate: f32,
        mut visit: impl FnMut(ProxyKey, &Aabb) -> f32,
    ) {
        if !geom::ray_is_valid(origin, dir, max_t) || inflate.is_nan() || inflate < 0.0 {
            return;
        }
        let slab = Slab::new(origin, dir, inflate);
        self.ray_ids(origin, dir, max_t, inflate, |id, best| {
            let (c, r) = self.sphere_of(id);
            match slab.sphere_entry(c, r, best) {
                Some(_) => visit(self.key_of(id), &self.box_of(id)),
                None => best,
            }
        });
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

    /// The first sphere touched by the sphere `center + t·dir`, `radius`, `t ∈ [0, max_t]`,
    /// with its `t` in units of `dir` (0 if it touches at the start), per
    /// `sphere_cast_sphere`; ties go to the smaller key. `None` if nothing is touched,
    /// or for a non-finite argument, a negative `radius` or a negative `max_t`.
    ///
    /// Nodes are pruned by their reach box grown by `radius` plus a relative pad (the exact
    /// test works in `f64`, the node test in `f32`), and every sphere of an entered node is
    /// tested exactly.
    #[must_use]
    pub fn cast_sphere(
        &self,
        center: Vec3,
        radius: f32,
        dir: Vec3,
        max_t: f32,
    ) -> Option<(ProxyKey, f32)> {
        let (mut hit, inflate) = FirstHit::sphere_cast(center, radius, dir, max_t)?;
        self.ray_ids(center, dir, max_t, inflate, |id, limit| {
            let (c, r) = self.sphere_of(id);
            let t = geom::sphere_cast_sphere(center, radius, dir, limit, c, r);
            hit.offer(self.key_of(id), t)
        });
        hit.best()
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
