//! The placement rules: which node a sphere lives in (computed in O(1) from integer cell
//! coordinates), the walk key a node sorts by in the pair passes, and the region a node's
//! spheres can reach. [`Lattice`] holds a tree's bounds, depth and integer lattice, and is the only
//! place that tells the two [`Placement`]s apart.

use super::cell::{Cell, code_of, level_of, morton, node_index, unmorton};
use super::{MAX_DEPTH, Placement};
use crate::geom::Aabb;
use glam::{Vec3, Vec3A};

impl Placement {
    /// A sensible octree depth for spheres of about `typical_radius` in `bounds` under this
    /// placement: [`depth_for`] for `Strict`, [`depth_for_loose`] for `Loose`.
    #[doc(hidden)]
    #[must_use]
    pub fn depth_for(self, bounds: &Aabb, typical_radius: f32) -> u32 {
        match self {
            Placement::Strict => depth_for(bounds, typical_radius),
            Placement::Loose => depth_for_loose(bounds, typical_radius),
        }
    }
}

/// Deepest cells of a strict tree span this many sphere diameters at [`depth_for`]: a sphere
/// then straddles a deepest plane with probability about one half per axis, and the spheres of
/// a cell meet few cells' worth of neighbours.
const STRICT_CELL_DIAMETERS: f32 = 2.0;
/// Cells of a loose tree span this many diameters at [`depth_for_loose`]: the deepest level
/// whose half cell still holds the radius, where every sphere of that size is placed.
const LOOSE_CELL_DIAMETERS: f32 = 1.0;

/// A sensible depth for a scene: the deepest level whose cells are still at least two sphere
/// diameters along the bounds' longest axis, clamped to `0..=MAX_DEPTH`. A zero radius gives
/// `MAX_DEPTH`; a negative or non-finite radius, or invalid bounds, give 0.
#[doc(hidden)]
#[must_use]
pub fn depth_for(bounds: &Aabb, typical_radius: f32) -> u32 {
    let cell = STRICT_CELL_DIAMETERS * 2.0 * typical_radius;
    deepest_level_with_cells(bounds.extent().max_element(), cell)
}

/// A sensible depth for a [`Placement::Loose`] tree: the deepest level whose cells are still at
/// least one sphere diameter along the bounds' shortest axis, so spheres of `typical_radius`
/// (or smaller) are placed there, one level deeper than [`depth_for`] usually gives. Clamped to
/// `0..=MAX_DEPTH`; a zero radius gives `MAX_DEPTH`; a negative or non-finite radius, or
/// invalid bounds, give 0.
#[doc(hidden)]
#[must_use]
pub fn depth_for_loose(bounds: &Aabb, typical_radius: f32) -> u32 {
    let cell = LOOSE_CELL_DIAMETERS * 2.0 * typical_radius;
    deepest_level_with_cells(bounds.extent().min_element(), cell)
}

/// The deepest level (at most `MAX_DEPTH`) at which `edge` split in `2^L` cells leaves cells of
/// at least `cell`: `MAX_DEPTH` for `cell == 0`, 0 for a negative or non-finite `cell` or a
/// non-positive or non-finite `edge`.
fn deepest_level_with_cells(edge: f32, cell: f32) -> u32 {
    if !(cell >= 0.0 && cell.is_finite() && edge > 0.0 && edge.is_finite()) {
        return 0;
    }
    let cells = edge / cell;
    if cells < 1.0 {
        0
    } else if cells.is_finite() {
        (cells.log2().floor() as u32).min(MAX_DEPTH)
    } else {
        MAX_DEPTH
    }
}

/// `floor` of each lane of `q`, for lanes in `[0, 2^16)`, as integers, in four vector operations
/// and three lane reads (`as u16` per lane costs a clamp pair and a scalar conversion each).
/// `q + 2^23` rounds to an integer (the spacing of floats in `[2^23, 2^24)` is 1), so
/// `(q + 2^23) − 2^23` is `q` rounded to the nearest integer, exactly; one less where that is
/// above `q` is `floor(q)`; and `floor(q) + 2^23` holds `floor(q)` in its low mantissa bits.
#[inline]
fn floor_to_u16(q: Vec3A) -> [u16; 3] {
    let m = Vec3A::splat(8_388_608.0);
    let r = (q + m) - m;
    let f = r - Vec3A::select(r.cmpgt(q), Vec3A::ONE, Vec3A::ZERO);
    let b = f + m;
    [
        b.x.to_bits() as u16,
        b.y.to_bits() as u16,
        b.z.to_bits() as u16,
    ]
}

/// The bits of a walk key of a tree of depth `depth`, in either layout: `3·depth` for the cell
/// and 4 for the level.
#[inline]
pub(super) fn walk_key_bits(depth: u32) -> u32 {
    3 * depth + StrictKey::LEVEL_BITS
}

/// A strict tree's walk key: depth-first walk order. The node's Morton code at its level `L`,
/// shifted to the deepest level (`<< 3·(depth − L)`, the code of the node's first
/// deepest-level cell), then `L` in the low [`StrictKey::LEVEL_BITS`] bits. A node's subtree
/// shares its shifted prefix range and is deeper, so the node sorts before its subtree and after
/// everything that precedes it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub(super) struct StrictKey(pub(super) u64);

impl StrictKey {
    /// Bits of the level field: levels `0..=MAX_DEPTH` fit.
    const LEVEL_BITS: u32 = 4;

    #[inline]
    fn new(depth: u32, level: u32, code: u32) -> Self {
        let prefix = u64::from(code) << (3 * (depth - level));
        StrictKey(prefix << Self::LEVEL_BITS | u64::from(level))
    }

    /// The node's level.
    #[inline]
    pub(super) fn level(self) -> u32 {
        (self.0 & ((1 << Self::LEVEL_BITS) - 1)) as u32
    }

    /// The Morton code of the node's first deepest-level cell.
    #[inline]
    pub(super) fn prefix(self) -> u32 {
        (self.0 >> Self::LEVEL_BITS) as u32
    }
}

/// A loose tree's walk key: level by level, each level in row-major order. `L << 3·depth`,
/// then the cell `(x, y, z)` as `z·4^L + y·2^L + x`, so a level's nodes come in rows along x,
/// rows in y-then-z order, and the key of the cell `(x + dx, y + dy, z + dz)` is the key plus
/// [`LooseKey::offset`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub(super) struct LooseKey(pub(super) u64);

impl LooseKey {
    #[inline]
    fn new(depth: u32, level: u32, [x, y, z]: [u32; 3]) -> Self {
        let cell = (u64::from(z) << (2 * level)) | (u64::from(y) << level) | u64::from(x);
        LooseKey((u64::from(level) << (3 * depth)) | cell)
    }

    /// The level and cell of the node, in a tree of depth `depth`.
    #[inline]
    pub(super) fn cell(self, depth: u32) -> (u32, [u32; 3]) {
        let level = (self.0 >> (3 * depth)) as u32;
        let mask = (1u32 << level) - 1;
        let cell = self.0 as u32;
        (
            level,
            [
                cell & mask,
                (cell >> level) & mask,
                (cell >> (2 * level)) & mask,
            ],
        )
    }

    /// What to add (wrapping) to the key of a level-`level` cell for the cell `(dx, dy, dz)`
    /// away, where that cell exists.
    #[inline]
    pub(super) fn offset(level: u32, [dx, dy, dz]: [i32; 3]) -> u64 {
        let side = 1i64 << level;
        (i64::from(dx) + i64::from(dy) * side + i64::from(dz) * side * side) as u64
    }
}

/// Where a sphere goes, from [`Lattice::locate`]. 16 bytes: the parallel apply keeps one per
/// slot.
#[derive(Clone, Copy, Debug)]
pub(super) struct Located {
    /// The box's corners as lattice coordinates, clamped to the lattice.
    pub(super) qmin: [u16; 3],
    pub(super) qmax: [u16; 3],
    /// The node the sphere lives in ([`Located::node`]), with [`Located::OUTSIDE`] set if it is
    /// kept in the root for not fitting the tree (counted in `OctreeStats::overflow`): node
    /// indices stay below it (`cell::node_count(MAX_DEPTH) < 2^31`).
    node_outside: u32,
}
const _: () = assert!(core::mem::size_of::<Located>() == 16);

impl Located {
    /// The bit of `node_outside` that says the sphere is outside.
    const OUTSIDE: u32 = 1 << 31;

    pub(super) const fn new(qmin: [u16; 3], qmax: [u16; 3], node: u32, outside: bool) -> Self {
        let flag = if outside { Self::OUTSIDE } else { 0 };
        Located {
            qmin,
            qmax,
            node_outside: (node & !Self::OUTSIDE) | flag,
        }
    }

    /// The node the sphere lives in.
    #[inline]
    pub(super) fn node(&self) -> u32 {
        self.node_outside & !Self::OUTSIDE
    }

    /// True if the sphere is kept in the root for not fitting the tree.
    #[inline]
    pub(super) fn outside(&self) -> bool {
        self.node_outside & Self::OUTSIDE != 0
    }
}

/// The last radius placed through [`Lattice::locate_memo`] and its loose level by radius
/// ([`Lattice::loose_level`]), valid for the lattice it was noted on.
#[derive(Clone, Copy, Debug)]
pub(crate) struct LevelMemo {
    /// The radius's bits; a NaN's (no radius placed) when empty.
    radius_bits: u32,
    level: Option<u32>,
}

impl LevelMemo {
    /// Holds no radius: a NaN is never placed.
    pub(crate) const EMPTY: LevelMemo = LevelMemo {
        radius_bits: f32::NAN.to_bits(),
        level: None,
    };
}

/// A tree's bounds, depth, placement and the integer lattice boxes are mapped to.
#[derive(Clone, Debug)]
pub(super) struct Lattice {
    pub(super) bounds: Aabb,
    pub(super) depth: u32,
    pub(super) placement: Placement,
    /// Bits per axis of the lattice: `depth` (strict), or `depth + 1` (loose: half the deepest
    /// cells, so every level's loose bounds lie on lattice lines).
    pub(super) bits: u32,
    /// Lattice cells per unit length on each axis: `2^bits / extent`.
    scale: Vec3A,
    /// `bounds.min`, and the last lattice cell `2^bits − 1` on every axis, for `quantize`.
    min: Vec3A,
    top: Vec3A,
    /// Loose mode: the largest radius placed at level `L`, half the level's cell size on the
    /// bounds' shortest axis (`min extent / 2^(L+1)`).
    pub(super) half_cell: [f32; MAX_DEPTH as usize + 1],
}

impl Lattice {
    /// The lattice of a tree; `bounds` are finite with volume, `depth <= MAX_DEPTH`.
    pub(super) fn new(bounds: Aabb, depth: u32, placement: Placement) -> Lattice {
        let bits = match placement {
            Placement::Strict => depth,
            Placement::Loose => depth + 1,
        };
        let shortest = bounds.extent().min_element();
        Lattice {
            bounds,
            depth,
            placement,
            bits,
            scale: (Vec3::splat((1u32 << bits) as f32) / bounds.extent()).into(),
            min: bounds.min.into(),
            top: Vec3A::splat(((1u32 << bits) - 1) as f32),
            half_cell: core::array::from_fn(|l| shortest / (2u32 << l) as f32),
        }
    }

    /// Where a sphere goes: its box's lattice range, its node, and whether it is kept in
    /// the root for not fitting.
    #[inline(always)]
    pub(super) fn locate(&self, center: Vec3, radius: f32) -> Located {
        let mut memo = LevelMemo::EMPTY;
        self.locate_memo(center, radius, &mut memo)
    }

    /// [`Lattice::locate`] reading a loose sphere's level by radius from `memo` when it holds
    /// `radius` (and noting it there when not): a world of one sphere size places each sphere
    /// without working its level out again. `memo` belongs to this lattice.
    #[inline(always)]
    pub(super) fn locate_memo(&self, center: Vec3, radius: f32, memo: &mut LevelMemo) -> Located {
        let aabb = Aabb::from_center_radius(center, radius);
        let qmin = self.quantize(aabb.min);
        let qmax = self.quantize(aabb.max);
        let (node, outside) = match self.placement {
            Placement::Strict => self.strict_node(&aabb, qmin, qmax),
            Placement::Loose => {
                if memo.radius_bits != radius.to_bits() {
                    *memo = LevelMemo {
                        radius_bits: radius.to_bits(),
                        level: self.loose_level(radius),
                    };
                }
                self.loose_node(memo.level, center, qmin, qmax)
            }
        };
        Located::new(qmin, qmax, node, outside)
    }

    /// True if a sphere placed in the root is there for not fitting the tree
    /// ([`Located::outside`]), from its stored box and sphere.
    #[inline]
    pub(super) fn is_outside(&self, aabb: &Aabb, center: Vec3, radius: f32) -> bool {
        match self.placement {
            Placement::Strict => !self.bounds.contains(aabb),
            Placement::Loose => self.locate(center, radius).outside(),
        }
    }

    /// Strict placement.
    ///
    /// Derivation. Map a coordinate to its deepest-level cell `q = floor((x − min)·2^d/extent)`,
    /// clamped to `0..2^d`. This map is monotone (float subtraction and multiplication by a
    /// positive constant round monotonically), so boxes that overlap have overlapping integer
    /// ranges — the property the pair walk relies on. A level-`L` cell is the integer range
    /// `[k·2^s, (k+1)·2^s − 1]` with `s = d − L`, so the box `[qmin, qmax]` straddles no
    /// level-`L` plane iff `qmin >> s == qmax >> s` on every axis, i.e. iff all bits of
    /// `x = (xmin^xmax) | (ymin^ymax) | (zmin^zmax)` are below bit `s`. The deepest such level
    /// takes the smallest `s`, which is `bit_length(x)`: `L = d − bit_length(x)`, and the node
    /// within that level is the Morton code of `qmin >> s`. A box leaving the bounds goes to
    /// the root; its clamped range still covers every cell it overlaps.
    #[inline]
    fn strict_node(&self, aabb: &Aabb, qmin: [u16; 3], qmax: [u16; 3]) -> (u32, bool) {
        if !self.bounds.contains(aabb) {
            return (0, true);
        }
        let x = (0..3).fold(0u32, |x, a| x | u32::from(qmin[a] ^ qmax[a]));
        let s = 32 - x.leading_zeros();
        let level = self.depth - s;
        let c = qmin.map(|q| u32::from(q) >> s);
        (node_index(level, morton(c)), false)
    }

    /// Loose placement (looseness 2).
    ///
    /// Derivation. The integer lattice has `2^(d+1)` cells per axis (`bits = d + 1`), half the
    /// deepest cells, so a level-`L` cell `k` spans `S = 2^(d+1−L)` lattice cells `[k·S, k·S+S−1]`
    /// and its loose bounds, grown by `S/2` on each side, are the lattice range
    /// `[k·S − S/2, k·S + S − 1 + S/2]` (exact integers at every level). The float rule is
    /// "radius ≤ half the level's cell size on every axis" (`half_cell`): the deepest such level
    /// is `floor(log2(half_cell[0] / r))`, read from the quotient's exponent and corrected by one
    /// table compare for its rounding. The pair pass relies on the integer version of "the box
    /// is inside the loose bounds": with `qc` the centre's lattice cell and `k = qc >> (bits − L)`,
    /// the box's range `[qmin, qmax]` is inside `k`'s loose range whenever
    /// `h = max(qc − qmin, qmax − qc) ≤ S/2 = 2^(d−L)` (worst cases `qc = k·S` and
    /// `qc = k·S + S − 1`), i.e. for `L ≤ d − ceil_log2(h)`. Both rules agree except where
    /// rounding makes the quantized box a cell wider; the sphere takes the shallower of the two
    /// levels, so both hold. Clamping to the lattice only moves range ends towards the lattice, so a
    /// clamped range stays inside the loose range and overlapping boxes keep overlapping ranges.
    /// Centres outside the bounds and spheres too big for the root's loose bounds go to the
    /// root as overflow.
    #[inline]
    fn loose_node(
        &self,
        by_radius: Option<u32>,
        center: Vec3,
        qmin: [u16; 3],
        qmax: [u16; 3],
    ) -> (u32, bool) {
        let Some(by_radius) = by_radius else {
            return (0, true);
        };
        if !self.bounds.contains_point(center) {
            return (0, true);
        }
        let qc = self.quantize(center);
        let h = (0..3).fold(0u32, |h, a| {
            h.max(u32::from(qc[a].saturating_sub(qmin[a])))
                .max(u32::from(qmax[a].saturating_sub(qc[a])))
        });
        let need = if h <= 1 {
            0
        } else {
            32 - (h - 1).leading_zeros()
        };
        if need > self.depth {
            return (0, true);
        }
        let level = by_radius.min(self.depth - need);
        let s = self.bits - level;
        let c = qc.map(|q| u32::from(q) >> s);
        (node_index(level, morton(c)), false)
    }

    /// The deepest level `L <= depth` with `radius <= half_cell[L]`, or `None` if even the root
    /// is too small. `radius` is finite and `>= 0` (checked on input).
    #[inline]
    pub(super) fn loose_level(&self, radius: f32) -> Option<u32> {
        let h = &self.half_cell;
        if radius > h[0] {
            return None;
        }
        let d = self.depth;
        // `h[0] / radius >= 1`; its exponent is `floor(log2)` of it, off by at most one after
        // the division's rounding (or when `h` is subnormal), which the compares fix.
        let q = h[0] / radius;
        let est = if q.is_finite() {
            (q.to_bits() >> 23) as i32 - 127
        } else {
            d as i32
        };
        let mut l = est.clamp(0, d as i32) as u32;
        while l > 0 && radius > h[l as usize] {
            l -= 1;
        }
        while l < d && radius <= h[l as usize + 1] {
            l += 1;
        }
        Some(l)
    }

    /// The cell size a sphere of `radius` gets: its loose level's cells (the root's if it
    /// fits no level), or a strict tree's deepest cells (where spheres of a typical radius
    /// live when the depth follows them).
    pub(super) fn typical_cell(&self, radius: f32) -> f32 {
        let level = match self.placement {
            Placement::Strict => self.depth,
            Placement::Loose => self.loose_level(radius).unwrap_or(0),
        };
        self.bounds.extent().max_element() / (1u32 << level) as f32
    }

    /// The lattice cell of a point, clamped to the lattice: `floor((p − min)·scale)` clamped to
    /// `[0, top]` (`floor` commutes with the clamp to integer limits).
    #[inline]
    pub(super) fn quantize(&self, p: Vec3) -> [u16; 3] {
        // `Vec3A` so the four operations are one SSE instruction each; same IEEE results.
        let q = ((Vec3A::from(p) - self.min) * self.scale)
            .max(Vec3A::ZERO)
            .min(self.top);
        floor_to_u16(q)
    }

    /// The key the pair pass sorts the spheres of `node` by ([`StrictKey`] or [`LooseKey`]'s
    /// bits); nodes with equal keys are equal.
    pub(super) fn walk_key(&self, node: u32) -> u64 {
        let level = level_of(node);
        let code = code_of(node, level);
        match self.placement {
            Placement::Strict => StrictKey::new(self.depth, level, code).0,
            Placement::Loose => LooseKey::new(self.depth, level, unmorton(code)).0,
        }
    }

    /// The lattice range that holds the ranges of the spheres placed in `cell`: the cell itself
    /// (strict), or its loose bounds, the cell grown by half its size (loose; the low end is
    /// clamped at 0, which no range is below).
    #[inline]
    pub(super) fn reach_range(&self, cell: &Cell) -> ([u32; 3], [u32; 3]) {
        let shift = self.bits - cell.level;
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

    /// The cells of `level` whose reach ([`Lattice::reach_range`]) overlaps the lattice range
    /// `[lo, hi]`, as an inclusive range of cell coordinates per axis (empty if `lo > hi` on
    /// some axis after clamping to the level).
    #[inline]
    pub(super) fn reaching_cells(
        &self,
        level: u32,
        lo: [u16; 3],
        hi: [u16; 3],
    ) -> ([u32; 3], [u32; 3]) {
        let shift = self.bits - level;
        let size = 1i64 << shift;
        let last = (1i64 << level) - 1;
        let (grow_lo, grow_hi) = match self.placement {
            Placement::Strict => (0, 0),
            // A loose cell `k` reaches `[k·S − S/2, k·S + S − 1 + S/2]`.
            Placement::Loose => (size / 2, size / 2),
        };
        let mut a = [0u32; 3];
        let mut b = [0u32; 3];
        for axis in 0..3 {
            // Cells with `k·S − grow_lo <= hi` and `k·S + S − 1 + grow_hi >= lo`: `k` from
            // `ceil((lo − grow_hi − S + 1) / S) = floor((lo − grow_hi) / S)` to
            // `floor((hi + grow_lo) / S)`; `S = 2^shift`, so each floor is an arithmetic shift.
            let first = ((i64::from(lo[axis]) - grow_hi) >> shift).max(0);
            let end = ((i64::from(hi[axis]) + grow_lo) >> shift).min(last);
            if end < first {
                return ([1; 3], [0; 3]);
            }
            (a[axis], b[axis]) = (first as u32, end as u32);
        }
        (a, b)
    }

    /// True if the lattice range of `cell`'s spheres ([`Lattice::reach_range`]) overlaps the lattice
    /// range `[lo, hi]`: the node may hold a sphere whose box overlaps a box with that range.
    #[inline]
    pub(super) fn reaches(&self, cell: &Cell, lo: [u16; 3], hi: [u16; 3]) -> bool {
        let (rlo, rhi) = self.reach_range(cell);
        (0..3).all(|a| rlo[a] <= u32::from(hi[a]) && u32::from(lo[a]) <= rhi[a])
    }

    /// The box that holds the spheres placed in `cell`: its cell (strict) or its loose bounds
    /// (loose); rounded, so a sphere placed in it may poke out by [`Lattice::rounding`].
    pub(super) fn reach_box(&self, cell: &Cell) -> Aabb {
        let size = self.bounds.extent() / (1u32 << cell.level) as f32;
        let min = self.bounds.min
            + Vec3::new(cell.xyz[0] as f32, cell.xyz[1] as f32, cell.xyz[2] as f32) * size;
        let b = Aabb::new(min, min + size);
        match self.placement {
            Placement::Strict => b,
            Placement::Loose => Aabb::new(b.min - size * 0.5, b.max + size * 0.5),
        }
    }

    /// The lattice's rounding tolerance: how far a sphere placed in a cell may poke out of
    /// [`Lattice::reach_box`]: the cell map and
    /// the box corners each round by a few ulps of the coordinates involved, which this covers
    /// with a relative margin of the coordinates' magnitude (`1e-5`) and of the extent (`1e-6`),
    /// both far above `f32`'s `6e-8`.
    pub(super) fn rounding(&self) -> f32 {
        let mag = self
            .bounds
            .min
            .abs()
            .max(self.bounds.max.abs())
            .max_element();
        mag * 1e-5 + self.bounds.extent().max_element() * 1e-6
    }
}

impl Lattice {
    /// Panics unless sphere `id` (centre `c`, radius `r`, located as `at`) may live in `node`
    /// by the placement rule, checked from the rule's definition rather than by re-running the
    /// O(1) placement (for `Octree::validate`).
    pub(super) fn check_rule(&self, id: usize, c: Vec3, r: f32, at: &Located, node: u32) {
        let level = level_of(node);
        let cell = unmorton(code_of(node, level));
        match self.placement {
            Placement::Strict => {
                let aabb = Aabb::from_center_radius(c, r);
                self.check_strict(id, &aabb, at, node, level, cell);
            }
            Placement::Loose => self.check_loose(id, c, r, at, node, level, cell),
        }
    }

    /// Strict: an overflow sphere's box leaves the bounds and it is in the root; any other
    /// box's lattice range lies in the node's cell and straddles a mid plane of it, unless the
    /// node is deepest.
    fn check_strict(
        &self,
        id: usize,
        aabb: &Aabb,
        at: &Located,
        node: u32,
        level: u32,
        cell: [u32; 3],
    ) {
        let wrong = "is not in the node placement gives";
        if at.outside() {
            let left = !self.bounds.contains(aabb);
            assert!(node == 0 && left, "id {id} {wrong}: it overflows the root");
            return;
        }
        let s = self.bits - level;
        let (lo, hi) = (at.qmin.map(u32::from), at.qmax.map(u32::from));
        let inside = (0..3).all(|a| lo[a] >> s == cell[a] && hi[a] >> s == cell[a]);
        assert!(inside, "id {id} {wrong}: its box leaves node {node}'s cell");
        let straddles = s == 0 || (0..3).any(|a| lo[a] >> (s - 1) != hi[a] >> (s - 1));
        assert!(
            straddles,
            "id {id} {wrong}: a child of node {node} holds its box"
        );
    }

    /// Loose: the centre lies in the node's cell, the radius within half the cell size, the
    /// box's lattice range inside the node's loose bounds, and no deeper level would take it; an
    /// overflow sphere is in the root and fits no level.
    #[allow(clippy::too_many_arguments, reason = "the parts of one placed sphere")]
    fn check_loose(
        &self,
        id: usize,
        c: Vec3,
        r: f32,
        at: &Located,
        node: u32,
        level: u32,
        cell: [u32; 3],
    ) {
        let fits = |l: u32| r <= self.half_cell[l as usize];
        let qc = self.quantize(c);
        // How far the box's lattice range reaches from the centre's lattice cell: the range fits the
        // loose bounds of any level-`L` cell holding the centre iff this is `<= 2^(depth − L)`.
        let reach = (0..3)
            .map(|a| {
                u32::from(qc[a] - at.qmin[a].min(qc[a]))
                    .max(u32::from(at.qmax[a].max(qc[a]) - qc[a]))
            })
            .max()
            .unwrap_or(0);
        let reach_fits = |l: u32| reach <= 1 << (self.depth - l);
        if at.outside() {
            assert_eq!(node, 0, "overflow sphere {id} is not in the root");
            assert!(
                !fits(0) || !self.bounds.contains_point(c) || !reach_fits(0),
                "sphere {id} fits the root but is counted as overflow"
            );
            return;
        }
        assert!(
            self.bounds.contains_point(c),
            "sphere {id} has its centre outside the bounds but is not overflow"
        );
        assert!(fits(level), "sphere {id} is too big for level {level}");
        let s = self.bits - level;
        let size = 1i64 << s;
        for a in 0..3 {
            assert_eq!(
                u32::from(qc[a]) >> s,
                cell[a],
                "sphere {id}'s centre is not in its node's cell"
            );
            let lo = i64::from(cell[a]) * size - size / 2;
            let hi = i64::from(cell[a]) * size + size - 1 + size / 2;
            assert!(
                lo <= i64::from(at.qmin[a]) && i64::from(at.qmax[a]) <= hi,
                "sphere {id}'s box leaves its node's loose bounds"
            );
        }
        assert!(
            level == self.depth || !fits(level + 1) || !reach_fits(level + 1),
            "sphere {id} would fit a deeper level than {level}"
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn floor_to_u16_is_floor() {
        let mut vals = vec![0.0f32, 0.25, 0.5, 0.75, 1.0, 1.5, 2.5, 3.5, 2047.0, 65535.0];
        for k in 0..2048u32 {
            let x = k as f32;
            vals.extend([x, x.next_up(), x.next_down().max(0.0), x + 0.5]);
        }
        let mut seed = 7u32;
        for _ in 0..100_000 {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            vals.push((seed >> 8) as f32 / (1 << 24) as f32 * 65535.0);
        }
        for chunk in vals.chunks(3) {
            let v = [chunk[0], chunk[chunk.len() / 2], chunk[chunk.len() - 1]];
            assert_eq!(
                floor_to_u16(Vec3A::from_array(v)),
                v.map(|x| x.floor() as u16),
                "{v:?}"
            );
        }
    }

    #[test]
    fn depth_for_gives_cells_of_two_diameters() {
        let b = Aabb::new(Vec3::ZERO, Vec3::splat(64.0));
        assert_eq!(depth_for(&b, 0.5), 5);
        assert_eq!(depth_for(&b, 100.0), 0);
        assert_eq!(depth_for(&b, 0.0), MAX_DEPTH);
        assert_eq!(depth_for(&b, -1.0), 0);
        assert_eq!(depth_for(&b, f32::NAN), 0);
    }

    #[test]
    fn cell_of_reads_the_row_major_key() {
        let d = 6;
        let key = LooseKey((4u64 << (3 * d)) | (3 << 8) | (9 << 4) | 5);
        assert_eq!(key.cell(d), (4, [5, 9, 3]));
        assert_eq!(LooseKey(0).cell(d), (0, [0, 0, 0]));
        // Depth 10, deepest level: 30 cell bits below the level.
        let key = LooseKey((10u64 << 30) | (1023 << 20) | 1023);
        assert_eq!(key.cell(10), (10, [1023, 0, 1023]));
    }

    #[test]
    fn walk_keys_decode_what_they_encode() {
        let d = 7;
        for (level, xyz) in [(0, [0, 0, 0]), (4, [5, 0, 7]), (7, [127, 64, 3])] {
            let loose = LooseKey::new(d, level, xyz);
            assert_eq!(loose.cell(d), (level, xyz));
            if level > 0 && xyz.iter().all(|&v| v + 1 < 1 << level) {
                let next = LooseKey::new(d, level, xyz.map(|v| v + 1));
                assert_eq!(
                    loose.0.wrapping_add(LooseKey::offset(level, [1; 3])),
                    next.0
                );
            }
            let strict = StrictKey::new(d, level, morton(xyz));
            assert_eq!(strict.level(), level);
            assert_eq!(strict.prefix() >> (3 * (d - level)), morton(xyz));
            assert!(walk_key_bits(d) >= 64 - strict.0.leading_zeros());
            assert!(walk_key_bits(d) >= 64 - loose.0.leading_zeros());
        }
    }
}
