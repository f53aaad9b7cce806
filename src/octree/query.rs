//! Box, sphere and ray queries, and the occupied-cell iterator. None of them allocates: they
//! walk occupied subtrees with a fixed inline stack (depth-first, at most 7 pending siblings
//! per level plus the current node).

use super::place::node_index;
use super::{MAX_DEPTH, NONE, Octree, Placement};
use crate::{Aabb, ProxyKey, Vec3, geom};

/// Capacity of the inline traversal stack: one node, then at most 7 pending siblings per level.
const STACK: usize = 1 + 7 * MAX_DEPTH as usize + 8;

/// A node on the traversal stack.
#[derive(Clone, Copy, Debug, Default)]
struct Cell {
    code: u32,
    level: u32,
    xyz: [u32; 3],
}

impl Cell {
    fn child(&self, c: u32) -> Cell {
        Cell {
            code: self.code * 8 + c,
            level: self.level + 1,
            xyz: [0, 1, 2].map(|a| self.xyz[a] * 2 + ((c >> a) & 1)),
        }
    }
}

impl Octree {
    /// Depth-first over occupied nodes: `enter(cell)` decides whether to visit a node's
    /// spheres (`visit(id)`) and children; the root is always entered.
    fn traverse(&self, mut enter: impl FnMut(&Cell) -> bool, mut visit: impl FnMut(u32)) {
        if self.objs.is_empty() {
            return;
        }
        let mut stack = [Cell::default(); STACK];
        let mut len = 1;
        while len > 0 {
            len -= 1;
            let cell = stack[len];
            let node = node_index(cell.level, cell.code);
            let mut i = self.nodes.head(node);
            while i != NONE {
                visit(i);
                i = self.objs[i as usize].next;
            }
            let mask = self.nodes.mask(node);
            for c in (0..8).rev().filter(|c| mask & (1 << c) != 0) {
                let child = cell.child(c);
                if enter(&child) {
                    stack[len] = child;
                    len += 1;
                }
            }
        }
    }

    /// The grid range that holds the ranges of the spheres placed in a node: its cell
    /// (strict), or its loose bounds, the cell grown by half its size (loose; the low end is
    /// clamped at 0, which no range is below).
    fn cell_range(&self, cell: &Cell) -> ([u32; 3], [u32; 3]) {
        let shift = self.grid - cell.level;
        let lo = cell.xyz.map(|c| c << shift);
        let hi = lo.map(|l| l + (1 << shift) - 1);
        match self.placement {
            Placement::Strict => (lo, hi),
            Placement::Loose => {
                let half = (1 << shift) >> 1;
                (lo.map(|l| l.saturating_sub(half)), hi.map(|h| h + half))
            }
        }
    }

    /// The box that holds the spheres placed in a node: its cell (strict) or its loose bounds
    /// (loose); rounded, so a sphere placed in it may poke out by an ulp.
    fn cell_box(&self, cell: &Cell) -> Aabb {
        let size = self.bounds.extent() / (1u32 << cell.level) as f32;
        let min = self.bounds.min
            + Vec3::new(cell.xyz[0] as f32, cell.xyz[1] as f32, cell.xyz[2] as f32) * size;
        let b = Aabb::new(min, min + size);
        match self.placement {
            Placement::Strict => b,
            Placement::Loose => Aabb::new(b.min - size * 0.5, b.max + size * 0.5),
        }
    }

    /// Visits the ids of every sphere whose integer range overlaps `aabb`'s (a superset of
    /// the spheres overlapping `aabb`).
    fn candidates(&self, aabb: &Aabb, visit: impl FnMut(u32)) {
        let (qlo, qhi) = (self.quantize(aabb.min), self.quantize(aabb.max));
        self.traverse(
            |cell| {
                let (lo, hi) = self.cell_range(cell);
                (0..3).all(|a| u32::from(qlo[a]) <= hi[a] && u32::from(qhi[a]) >= lo[a])
            },
            visit,
        );
    }

    /// Calls `f` with the key of every sphere whose AABB overlaps `aabb` (closed), once each,
    /// in no particular order. A non-finite or inverted `aabb` finds nothing.
    pub fn query_aabb(&self, aabb: &Aabb, f: impl FnMut(ProxyKey)) {
        if geom::check_aabb(aabb).is_ok() {
            self.query_aabb_unchecked(aabb, f);
        }
    }

    /// [`Octree::query_aabb`] without the input check, for boxes the crate made itself: a
    /// sphere or body near `f32::MAX` has a box that overflows to ±∞ from finite input, and it
    /// must still find what it overlaps.
    pub(crate) fn query_aabb_unchecked(&self, aabb: &Aabb, mut f: impl FnMut(ProxyKey)) {
        self.candidates(aabb, |id| {
            if self.objs[id as usize].aabb.overlaps(aabb) {
                f(self.keys[id as usize]);
            }
        });
    }

    /// Calls `f` with the key of every sphere that overlaps the query sphere (centre distance
    /// `<= r1 + r2`, so touching spheres count), once each, in no particular order. A
    /// non-finite centre or radius, or a negative radius, finds nothing.
    pub fn query_sphere(&self, center: Vec3, radius: f32, mut f: impl FnMut(ProxyKey)) {
        if geom::check_sphere(center, radius).is_err() {
            return;
        }
        self.candidates(&Aabb::from_center_radius(center, radius), |id| {
            let (c, r) = self.spheres[id as usize];
            if (c - center).length_squared() <= (r + radius) * (r + radius) {
                f(self.keys[id as usize]);
            }
        });
    }

    /// The closest sphere hit by the segment `origin + t·dir`, `t ∈ [0, max_t]` (`t` in units
    /// of `dir`; an origin inside a sphere hits at 0), per [`geom::ray_sphere`]; ties go to
    /// the smaller key. A non-finite origin or direction, or a NaN or negative `max_t`, hits
    /// nothing.
    #[must_use]
    pub fn cast_ray(&self, origin: Vec3, dir: Vec3, max_t: f32) -> Option<(ProxyKey, f32)> {
        if !geom::ray_is_valid(origin, dir, max_t) {
            return None;
        }
        let inv = geom::inverse_dir(dir);
        let slack = self.cell_slack();
        let best = core::cell::Cell::new(None::<(ProxyKey, f32)>);
        let limit = || best.get().map_or(max_t, |(_, t)| t);
        self.traverse(
            |cell| {
                self.cell_box(cell)
                    .grown(slack)
                    .ray_entry(origin, inv, limit())
                    .is_some()
            },
            |id| {
                let (c, r) = self.spheres[id as usize];
                if let Some(t) = geom::ray_sphere(origin, dir, c, r, limit()) {
                    let key = self.keys[id as usize];
                    let better = best
                        .get()
                        .is_none_or(|(bk, bt)| t < bt || (t == bt && key < bk));
                    if better {
                        best.set(Some((key, t)));
                    }
                }
            },
        );
        best.get()
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
    fn cast_ray_all_with(
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
        let slack = self.cell_slack();
        self.traverse(
            |cell| {
                self.cell_box(cell)
                    .grown(slack)
                    .ray_entry(origin, inv, max_t)
                    .is_some()
            },
            |id| {
                let (c, r) = self.spheres[id as usize];
                if let Some(t) = hit(c, r) {
                    f(self.keys[id as usize], t);
                }
            },
        );
    }

    /// Calls `f(level, cell)` for every node that holds at least one sphere, parents before
    /// their children: the cell itself in strict mode, its loose bounds (the cell grown by half
    /// its size) in loose mode. Overflow spheres live in the root.
    pub fn for_each_occupied_cell(&self, mut f: impl FnMut(u32, Aabb)) {
        let mut stack = [Cell::default(); STACK];
        let mut len = usize::from(!self.objs.is_empty());
        while len > 0 {
            len -= 1;
            let cell = stack[len];
            let node = node_index(cell.level, cell.code);
            if self.nodes.head(node) != NONE {
                f(cell.level, self.cell_box(&cell));
            }
            let mask = self.nodes.mask(node);
            for c in (0..8).rev().filter(|c| mask & (1 << c) != 0) {
                stack[len] = cell.child(c);
                len += 1;
            }
        }
    }

    /// How far a sphere placed in a cell may poke out of the cell's float box: the cell map
    /// and the box corners each round by a few ulps of the coordinates involved.
    fn cell_slack(&self) -> f32 {
        let mag = self
            .bounds
            .min
            .abs()
            .max(self.bounds.max.abs())
            .max_element();
        mag * 1e-5 + self.bounds.extent().max_element() * 1e-6
    }
}
