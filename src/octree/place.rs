//! Placement: which node a sphere lives in, computed in O(1), and the paged node arrays with
//! their per-node list heads and child-occupancy masks.

use super::{MAX_DEPTH, NONE, Obj, Octree, Placement};
use crate::{Aabb, Vec3};
use glam::Vec3A;

/// First node index of each level: level `L` starts at `(8^L − 1)/7`; entry `MAX_DEPTH + 1` is
/// the node count of a depth-`MAX_DEPTH` tree (1 227 133 513, fits in `u32`).
const LEVEL_START: [u32; MAX_DEPTH as usize + 2] = {
    let mut s = [0u32; MAX_DEPTH as usize + 2];
    let mut l = 1;
    while l < s.len() {
        s[l] = s[l - 1] * 8 + 1;
        l += 1;
    }
    s
};

/// Number of nodes of a tree with levels `0..=depth`.
pub(super) fn node_count(depth: u32) -> u32 {
    LEVEL_START[depth as usize + 1]
}

/// Index of the node with Morton code `code` at `level`.
#[inline]
pub(super) fn node_index(level: u32, code: u32) -> u32 {
    LEVEL_START[level as usize] + code
}

/// Spreads the low 10 bits of `v` to every third bit (bit i → bit 3i).
#[inline]
const fn spread3(v: u32) -> u32 {
    let mut x = v & 0x3ff;
    x = (x | (x << 16)) & 0x0300_00ff;
    x = (x | (x << 8)) & 0x0300_f00f;
    x = (x | (x << 4)) & 0x030c_30c3;
    (x | (x << 2)) & 0x0924_9249
}

/// Compacts every third bit of `x` (bit 3i → bit i); the inverse of `spread3`.
#[inline]
pub(super) fn compact3(x: u32) -> u32 {
    let mut x = x & 0x0924_9249;
    x = (x | (x >> 2)) & 0x030c_30c3;
    x = (x | (x >> 4)) & 0x0300_f00f;
    x = (x | (x >> 8)) & 0x0300_00ff;
    (x | (x >> 16)) & 0x3ff
}

/// The Morton code of cell `(x, y, z)`: x in bit 0 of each triple, y in bit 1, z in bit 2, so
/// child octant `c` of a node with code `m` has code `8m + c` with `c = bx | by<<1 | bz<<2`.
#[inline]
pub(super) fn morton(c: [u32; 3]) -> u32 {
    let s = |v: u32| SPREAD3[(v & 0x3ff) as usize];
    s(c[0]) | (s(c[1]) << 1) | (s(c[2]) << 2)
}

/// `spread3` of every 10-bit value: a placement does three lookups instead of three bit
/// spreads. 4 KB.
static SPREAD3: [u32; 1024] = {
    let mut t = [0u32; 1024];
    let mut v = 0;
    while v < 1024 {
        t[v] = spread3(v as u32);
        v += 1;
    }
    t
};

/// A sensible depth for a scene: the deepest level whose cells are still at least two sphere
/// diameters along the bounds' longest axis, clamped to `0..=MAX_DEPTH`. A zero radius gives
/// `MAX_DEPTH`; a negative or non-finite radius, or invalid bounds, give 0.
#[must_use]
pub fn depth_for(bounds: &Aabb, typical_radius: f32) -> u32 {
    deepest_level_with_cells(bounds.extent().max_element(), 4.0 * typical_radius)
}

/// A sensible depth for a [`Placement::Loose`] tree: the deepest level whose cells are still at
/// least one sphere diameter along the bounds' shortest axis, so spheres of `typical_radius`
/// (or smaller) are placed there, one level deeper than [`depth_for`] usually gives. Clamped to
/// `0..=MAX_DEPTH`; a zero radius gives `MAX_DEPTH`; a negative or non-finite radius, or
/// invalid bounds, give 0.
#[must_use]
pub fn depth_for_loose(bounds: &Aabb, typical_radius: f32) -> u32 {
    deepest_level_with_cells(bounds.extent().min_element(), 2.0 * typical_radius)
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

/// `floor` of each lane of `q`, for lanes in `[0, 2^16)`, as integers; four SSE operations
/// and three lane reads, where `as u16` on each lane costs a clamp pair and a scalar conversion
/// per lane (a tenth of a loose `locate`, callgrind). `q + 2^23` rounds to an integer (the
/// spacing of floats in `[2^23, 2^24)` is 1), so `(q + 2^23) − 2^23` is `q` rounded to the
/// nearest integer, exactly; one less where that is above `q` is `floor(q)`; and `floor(q) +
/// 2^23` holds `floor(q)` in its low mantissa bits.
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

/// Nodes per page of the paged node arrays.
const PAGE_BITS: u32 = 12;
const PAGE: usize = 1 << PAGE_BITS;

/// Per-node list heads and child-occupancy masks, paged: `table[node >> PAGE_BITS]` is the
/// page's position in `head`/`mask` plus one, or 0 while no node of the page was ever
/// occupied (reads then see an empty node). Pages are never freed.
#[derive(Clone, Debug)]
pub(super) struct Nodes {
    table: Vec<u32>,
    /// First object of each node's list, `NONE` if empty. 4 bytes per node.
    head: Vec<u32>,
    /// Bit `c` set iff child octant `c`'s subtree holds a sphere. 1 byte per node.
    mask: Vec<u8>,
}

impl Nodes {
    pub(super) fn new(count: u32) -> Self {
        Nodes {
            table: vec![0; (count as usize).div_ceil(PAGE)],
            head: Vec::new(),
            mask: Vec::new(),
        }
    }

    /// Position of `node` in `head`/`mask`, if its page exists.
    #[inline]
    pub(super) fn slot(&self, node: u32) -> Option<usize> {
        let p = self.table[(node >> PAGE_BITS) as usize];
        (p != 0).then(|| (((p - 1) as usize) << PAGE_BITS) | (node as usize & (PAGE - 1)))
    }

    /// Position of `node`, allocating its page first if needed.
    fn slot_mut(&mut self, node: u32) -> usize {
        let t = (node >> PAGE_BITS) as usize;
        if self.table[t] == 0 {
            let pages = self.head.len() / PAGE;
            self.head.resize(self.head.len() + PAGE, NONE);
            self.mask.resize(self.mask.len() + PAGE, 0);
            self.table[t] = pages as u32 + 1;
        }
        (((self.table[t] - 1) as usize) << PAGE_BITS) | (node as usize & (PAGE - 1))
    }

    /// Nodes allocated in pages so far: every [`Nodes::slot`] is below this.
    pub(super) fn head_len(&self) -> usize {
        self.head.len()
    }

    /// The child mask of the node at position `slot`.
    #[inline]
    pub(super) fn mask_at(&self, slot: usize) -> u8 {
        self.mask[slot]
    }

    #[inline]
    pub(super) fn head(&self, node: u32) -> u32 {
        self.slot(node).map_or(NONE, |s| self.head[s])
    }

    #[inline]
    pub(super) fn mask(&self, node: u32) -> u8 {
        self.slot(node).map_or(0, |s| self.mask[s])
    }

    pub(super) fn set_head(&mut self, node: u32, id: u32) {
        let s = self.slot_mut(node);
        self.head[s] = id;
    }

    /// True if neither the node nor any descendant holds a sphere.
    pub(super) fn is_empty(&self, node: u32) -> bool {
        self.slot(node)
            .is_none_or(|s| self.head[s] == NONE && self.mask[s] == 0)
    }

    /// The level of `node`.
    pub(super) fn level_of(&self, node: u32) -> u32 {
        LEVEL_START[1..].iter().take_while(|&&s| s <= node).count() as u32
    }

    /// Marks the path from `node` to the root as occupied; call after `node` became non-empty.
    /// Stops at the first ancestor that was already non-empty (its own ancestors are marked).
    fn mark_occupied(&mut self, node: u32) {
        let mut level = self.level_of(node);
        let mut code = node - LEVEL_START[level as usize];
        while level > 0 {
            let parent = node_index(level - 1, code >> 3);
            let was_empty = self.is_empty(parent);
            let s = self.slot_mut(parent);
            self.mask[s] |= 1 << (code & 7);
            if !was_empty {
                return;
            }
            level -= 1;
            code >>= 3;
        }
    }

    /// Clears occupancy bits up from `node`; call after `node` became empty.
    fn mark_empty(&mut self, node: u32) {
        let mut level = self.level_of(node);
        let mut code = node - LEVEL_START[level as usize];
        while level > 0 {
            let parent = node_index(level - 1, code >> 3);
            let s = self.slot_mut(parent);
            self.mask[s] &= !(1 << (code & 7));
            if !self.is_empty(parent) {
                return;
            }
            level -= 1;
            code >>= 3;
        }
    }
}

impl Octree {
    /// Where a sphere goes: its AABB, the AABB's corners as clamped grid coordinates, its
    /// node, and whether it is kept in the root for not fitting (counted in `overflow`).
    #[inline]
    pub(super) fn locate(
        &self,
        center: Vec3,
        radius: f32,
    ) -> (Aabb, [u16; 3], [u16; 3], u32, bool) {
        let aabb = Aabb::from_center_radius(center, radius);
        let qmin = self.quantize(aabb.min);
        let qmax = self.quantize(aabb.max);
        let (node, outside) = match self.placement {
            Placement::Strict => self.strict_node(&aabb, qmin, qmax),
            Placement::Loose => self.loose_node(center, radius, qmin, qmax),
        };
        (aabb, qmin, qmax, node, outside)
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
    /// Derivation. The integer grid has `2^(d+1)` cells per axis (`grid = d + 1`), half the
    /// deepest cells, so a level-`L` cell `k` spans `S = 2^(d+1−L)` grid cells `[k·S, k·S+S−1]`
    /// and its loose bounds, grown by `S/2` on each side, are the grid range
    /// `[k·S − S/2, k·S + S − 1 + S/2]` (exact integers at every level). The float rule is
    /// "radius ≤ half the level's cell size on every axis" (`half_cell`): the deepest such level
    /// is `floor(log2(half_cell[0] / r))`, read from the quotient's exponent and corrected by one
    /// table compare for its rounding. The pair pass relies on the integer version of "the box
    /// is inside the loose bounds": with `qc` the centre's grid cell and `k = qc >> (grid − L)`,
    /// the box's range `[qmin, qmax]` is inside `k`'s loose range whenever
    /// `h = max(qc − qmin, qmax − qc) ≤ S/2 = 2^(d−L)` (worst cases `qc = k·S` and
    /// `qc = k·S + S − 1`), i.e. for `L ≤ d − ceil_log2(h)`. Both rules agree except where
    /// rounding makes the quantized box a cell wider; the sphere takes the shallower of the two
    /// levels, so both hold. Clamping to the grid only moves range ends towards the grid, so a
    /// clamped range stays inside the loose range and overlapping boxes keep overlapping ranges.
    /// Centres outside the bounds and spheres too big for the root's loose bounds go to the
    /// root as overflow.
    #[inline]
    fn loose_node(&self, center: Vec3, radius: f32, qmin: [u16; 3], qmax: [u16; 3]) -> (u32, bool) {
        let Some(by_radius) = self.loose_level(radius) else {
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
        let s = self.grid - level;
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

    /// The grid cell of a point, clamped to the grid: `floor((p − min)·scale)` clamped to
    /// `[0, top]` (`floor` commutes with the clamp to integer limits).
    #[inline]
    pub(super) fn quantize(&self, p: Vec3) -> [u16; 3] {
        // `Vec3A` so the four operations are one SSE instruction each; same IEEE results.
        let q = ((Vec3A::from(p) - self.grid_min) * self.scale)
            .max(Vec3A::ZERO)
            .min(self.grid_top);
        floor_to_u16(q)
    }

    /// The key the pair pass sorts the spheres by; nodes with equal keys are equal.
    ///
    /// Strict trees: depth-first walk order. The node's Morton code at its level `L`, shifted
    /// to the deepest level (`<< 3·(depth − L)`, the code of the node's first deepest-level
    /// cell), then `L` in the low 4 bits. A node's subtree shares its shifted prefix range and
    /// is deeper, so the node sorts before its subtree and after everything that precedes it.
    ///
    /// Loose trees: level by level, each level in row-major order. `L << 3·depth`, then the
    /// cell `(x, y, z)` as `z·4^L + y·2^L + x`, so a level's nodes come in rows along x, rows
    /// in y-then-z order, which the loose pass walks with one pointer per neighbour row.
    ///
    /// Either way `3·depth + 4` bits.
    pub(super) fn walk_key(&self, node: u32) -> u64 {
        let level = self.nodes.level_of(node);
        let code = node - LEVEL_START[level as usize];
        match self.placement {
            Placement::Strict => {
                ((u64::from(code) << (3 * (self.depth - level))) << 4) | u64::from(level)
            }
            Placement::Loose => {
                let [x, y, z] = [compact3(code), compact3(code >> 1), compact3(code >> 2)];
                let cell = (u64::from(z) << (2 * level)) | (u64::from(y) << level) | u64::from(x);
                (u64::from(level) << (3 * self.depth)) | cell
            }
        }
    }

    /// Pushes object `id` at the front of `node`'s list.
    pub(super) fn link(&mut self, id: u32, node: u32) {
        let walk_key = self.walk_key(node);
        let became_occupied = self.nodes.is_empty(node);
        let head = self.nodes.head(node);
        let o = &mut self.objs[id as usize];
        o.node = node;
        o.walk_key = walk_key;
        o.prev = NONE;
        o.next = head;
        if head != NONE {
            self.objs[head as usize].prev = id;
        }
        self.nodes.set_head(node, id);
        if became_occupied {
            self.nodes.mark_occupied(node);
        }
    }

    /// Takes object `id` out of its node's list (its `node` field is left as it was).
    pub(super) fn unlink(&mut self, id: u32) {
        let Obj {
            node, next, prev, ..
        } = self.objs[id as usize];
        if prev == NONE {
            self.nodes.set_head(node, next);
        } else {
            self.objs[prev as usize].next = next;
        }
        if next != NONE {
            self.objs[next as usize].prev = prev;
        }
        if self.nodes.is_empty(node) {
            self.nodes.mark_empty(node);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn level_starts_and_levels() {
        assert_eq!(&LEVEL_START[..4], &[0, 1, 9, 73]);
        assert_eq!(node_count(10), 1_227_133_513);
        let n = Nodes::new(node_count(3));
        assert_eq!(n.level_of(0), 0);
        assert_eq!(n.level_of(1), 1);
        assert_eq!(n.level_of(8), 1);
        assert_eq!(n.level_of(9), 2);
        assert_eq!(n.level_of(72), 2);
        assert_eq!(n.level_of(73), 3);
    }

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
    fn morton_interleaves_x_first() {
        assert_eq!(morton([1, 0, 0]), 1);
        assert_eq!(morton([0, 1, 0]), 2);
        assert_eq!(morton([0, 0, 1]), 4);
        assert_eq!(morton([2, 0, 0]), 8);
        assert_eq!(morton([1023, 1023, 1023]), (1 << 30) - 1);
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
}
