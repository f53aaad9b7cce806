//! Box, sphere and ray queries, and the occupied-cell iterator. None of them allocates: they
//! follow the node lists through occupied subtrees ([`Nodes::walk`](super::nodes::Nodes::walk)),
//! entering a node only if the region its spheres can reach meets the query.

use super::cell::Cell;
use super::{NONE, Octree};
use crate::geom::{self, Aabb};
use crate::pair::ProxyKey;
use glam::Vec3;

/// Queries whose reaching cells over the occupied levels are at most this many read those
/// cells' lists directly; larger ones walk the occupied subtrees.
const DIRECT_CELLS: u64 = 96;

impl Octree {
    /// Depth-first over occupied nodes from the root: `enter(cell)` decides whether to visit a
    /// node's spheres (`visit(id)`) and children; the root is always entered.
    fn traverse(&self, enter: impl FnMut(&Cell) -> bool, mut visit: impl FnMut(u32)) {
        if self.objs.is_empty() {
            return;
        }
        self.nodes.walk(Cell::ROOT, enter, |_, slot| {
            let mut i = self.nodes.head_at(slot);
            while i != NONE {
                visit(i);
                i = self.objs[i as usize].next;
            }
        });
    }

    /// Visits the ids of every sphere whose integer range overlaps `aabb`'s (a superset of
    /// the spheres overlapping `aabb`).
    ///
    /// A small query reads the lists of the cells that reach it directly, level by occupied
    /// level: no walk down from the root, whose upper levels cost a visit each while holding
    /// few spheres. A large one walks the occupied subtrees instead, whose masks skip empty
    /// regions.
    fn candidates(&self, aabb: &Aabb, mut visit: impl FnMut(u32)) {
        let (qlo, qhi) = (self.grid.quantize(aabb.min), self.grid.quantize(aabb.max));
        let mut cells = 0u64;
        for level in 1..=self.grid.depth {
            if self.per_level[level as usize] > 0 {
                let (a, b) = self.grid.reaching_cells(level, qlo, qhi);
                cells += (0..3)
                    .map(|i| u64::from((b[i] + 1).saturating_sub(a[i])))
                    .product::<u64>();
            }
        }
        if cells > DIRECT_CELLS {
            self.traverse(|cell| self.grid.reaches(cell, qlo, qhi), visit);
            return;
        }
        let mut list = |node: u32| {
            let mut i = self.nodes.head(node);
            while i != NONE {
                visit(i);
                i = self.objs[i as usize].next;
            }
        };
        if self.per_level[0] > 0 {
            list(0);
        }
        for level in 1..=self.grid.depth {
            if self.per_level[level as usize] == 0 {
                continue;
            }
            let (a, b) = self.grid.reaching_cells(level, qlo, qhi);
            for z in a[2]..=b[2] {
                for y in a[1]..=b[1] {
                    for x in a[0]..=b[0] {
                        list(Cell::at(level, [x, y, z]).node());
                    }
                }
            }
        }
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
        let slack = self.grid.slack();
        let best = core::cell::Cell::new(None::<(ProxyKey, f32)>);
        let limit = || best.get().map_or(max_t, |(_, t)| t);
        self.traverse(
            |cell| {
                self.grid
                    .reach_box(cell)
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
        let slack = self.grid.slack();
        self.traverse(
            |cell| {
                self.grid
                    .reach_box(cell)
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
        if self.objs.is_empty() {
            return;
        }
        self.nodes.walk(
            Cell::ROOT,
            |_| true,
            |cell, slot| {
                if self.nodes.head_at(slot) != NONE {
                    f(cell.level, self.grid.reach_box(cell));
                }
            },
        );
    }
}
