//! Implicit node indexing: level `L` starts at node `(8^L − 1)/7`, and a node's index within
//! its level is the Morton code of its cell. [`Cell`] is a node named by level, Morton code and
//! cell coordinates together, as the traversals carry it.

use super::MAX_DEPTH;

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

/// The level of node `node`: level `L` holds the nodes with `8^L <= 7·node + 1 < 8^(L+1)`.
/// (`MAX_DEPTH + 1` for nodes past the deepest level, `NONE` among them.)
#[inline]
pub(super) fn level_of(node: u32) -> u32 {
    (u64::from(node) * 7 + 1).ilog2() / 3
}

/// The Morton code of `node` within its level `level`.
#[inline]
pub(super) fn code_of(node: u32, level: u32) -> u32 {
    node - LEVEL_START[level as usize]
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

/// The cell `(x, y, z)` of a Morton code: the inverse of [`morton`].
#[inline]
pub(super) fn unmorton(code: u32) -> [u32; 3] {
    [compact3(code), compact3(code >> 1), compact3(code >> 2)]
}

/// The indices of `points` in the order of the Morton curve through them: each point's cell
/// of the 1024³ lattice over their bounding box, ties in index order. Points near each other
/// mostly come near each other in this order. The points are finite; at most `u32::MAX`.
pub(crate) fn curve_order(points: impl Iterator<Item = glam::Vec3> + Clone) -> Vec<u32> {
    let (lo, hi) = points.clone().fold(
        (glam::DVec3::INFINITY, glam::DVec3::NEG_INFINITY),
        |(lo, hi), p| (lo.min(p.as_dvec3()), hi.max(p.as_dvec3())),
    );
    // In `f64`, so that no extent of finite `f32` points overflows; a flat axis maps to 0.
    let extent = hi - lo;
    let scale = glam::DVec3::select(
        extent.cmpgt(glam::DVec3::ZERO),
        1023.0 / extent,
        glam::DVec3::ZERO,
    );
    let mut keyed: Vec<u64> = points
        .enumerate()
        .map(|(i, p)| {
            // Each coordinate is 0..=1023 up to rounding; `morton` reads its low 10 bits.
            let c = ((p.as_dvec3() - lo) * scale).to_array().map(|x| x as u32);
            (u64::from(morton(c)) << 32) | i as u64
        })
        .collect();
    keyed.sort_unstable();
    keyed.into_iter().map(|k| k as u32).collect()
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

/// A node as the traversals carry it: level, Morton code and cell coordinates. 20 bytes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(super) struct Cell {
    pub(super) code: u32,
    pub(super) level: u32,
    pub(super) xyz: [u32; 3],
}

impl Cell {
    /// The root.
    pub(super) const ROOT: Cell = Cell {
        code: 0,
        level: 0,
        xyz: [0; 3],
    };

    /// The cell `xyz` of `level`.
    #[inline]
    pub(super) fn at(level: u32, xyz: [u32; 3]) -> Cell {
        Cell {
            code: morton(xyz),
            level,
            xyz,
        }
    }

    /// Child octant `c` (`x | y<<1 | z<<2`, each bit the upper half on that axis).
    #[inline]
    pub(super) fn child(&self, c: u32) -> Cell {
        Cell {
            code: self.code * 8 + c,
            level: self.level + 1,
            xyz: [0, 1, 2].map(|a| self.xyz[a] * 2 + ((c >> a) & 1)),
        }
    }

    /// The node index.
    #[inline]
    pub(super) fn node(&self) -> u32 {
        node_index(self.level, self.code)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn level_starts_and_levels() {
        assert_eq!(&LEVEL_START[..4], &[0, 1, 9, 73]);
        assert_eq!(node_count(10), 1_227_133_513);
        assert_eq!(level_of(0), 0);
        assert_eq!(level_of(1), 1);
        assert_eq!(level_of(8), 1);
        assert_eq!(level_of(9), 2);
        assert_eq!(level_of(72), 2);
        assert_eq!(level_of(73), 3);
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
    fn level_of_agrees_with_the_level_starts() {
        let by_table = |node: u32| LEVEL_START[1..].iter().take_while(|&&s| s <= node).count();
        for &start in &LEVEL_START {
            for node in [start.saturating_sub(1), start, start.saturating_add(1)] {
                assert_eq!(level_of(node) as usize, by_table(node), "node {node}");
            }
        }
        for node in [u32::MAX - 1, u32::MAX, 1 << 31, 12_345_678] {
            assert_eq!(level_of(node) as usize, by_table(node), "node {node}");
        }
    }

    #[test]
    fn compact3_inverts_spread3() {
        for c in [[0, 0, 0], [1, 2, 3], [1023, 0, 511], [1023, 1023, 1023]] {
            let m = morton(c);
            assert_eq!([compact3(m), compact3(m >> 1), compact3(m >> 2)], c);
            assert_eq!(unmorton(m), c);
        }
    }

    #[test]
    fn children_are_the_next_level_cells() {
        let c = Cell::at(2, [3, 1, 2]);
        for k in 0..8 {
            let child = c.child(k);
            assert_eq!(child, Cell::at(3, child.xyz));
            assert_eq!(child.xyz.map(|v| v / 2), c.xyz);
        }
    }
}
