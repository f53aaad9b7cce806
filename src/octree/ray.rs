//! Ray and sphere casts: the closest hit, every hit, and the box-based ray candidates the
//! `BroadPhase` re-tests exactly. A ray is read in pieces along its length, nearer cells
//! first, or by walking the occupied subtrees when pieces would not pay ([`Octree::ray_plan`]).

use super::cell::{morton, node_index};
use super::{NONE, Octree, Placement};
use crate::geom::{self, Aabb};
use crate::pair::ProxyKey;
use crate::search::{FirstHit, Slab};
use core::ops::ControlFlow;
use glam::Vec3;

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

impl Octree {
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
        // A piece's list heads are gathered (see [`Gathered`]) and walked before the next
        // piece, whose start is checked against the best hit so far.
        let mut gathered = Gathered::default();
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
                        let head = self.nodes.head(first + (yz | morton([x, 0, 0])));
                        if gathered.keep(head) {
                            best = gathered.walk(self, best, &mut visit);
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
            best = gathered.walk(self, best, &mut visit);
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
}

/// Room for the list heads a ray piece gathers before it walks them (a full gather is walked
/// at once, so a piece may read any number of cells).
const RAY_HEADS: usize = 64;

/// The non-empty list heads a ray piece has read and not yet walked, in the order read.
struct Gathered {
    heads: [u32; RAY_HEADS],
    len: usize,
}

impl Default for Gathered {
    fn default() -> Self {
        Gathered {
            heads: [NONE; RAY_HEADS],
            len: 0,
        }
    }
}

impl Gathered {
    /// Keeps `head` if its list is not empty (with no branch on it); true once full.
    #[inline]
    fn keep(&mut self, head: u32) -> bool {
        self.heads[self.len] = head;
        self.len += usize::from(head != NONE);
        self.len == RAY_HEADS
    }

    /// Walks the kept lists in order, their first records read first (see
    /// [`Octree::touch_first`]), and empties the gather; returns `best` shrunk to what
    /// `visit` returns.
    #[inline]
    fn walk(
        &mut self,
        tree: &Octree,
        mut best: f32,
        visit: &mut impl FnMut(u32, f32) -> f32,
    ) -> f32 {
        let heads = &self.heads[..core::mem::take(&mut self.len)];
        tree.touch_first(heads);
        for &head in heads {
            let mut i = head;
            while i != NONE {
                best = best.min(visit(i, best));
                i = tree.next_in_list(i);
            }
        }
        best
    }
}
