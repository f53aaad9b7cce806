//! The tree primitives' boxes laid out for the leaf kernels of the pair passes: in blocks of
//! four consecutive primitives (tree order), each block holding one 4-lane vector per face
//! (`min.x`, `min.y`, `min.z`, `max.x`, `max.y`, `max.z`), so that a block is tested against
//! one box in six compares from six aligned loads. Kept beside `Bvh::boxes`, which everything
//! else reads.

use crate::geom::SimdBox;
use glam::{Vec3A, Vec4};

/// Boxes per block: the lanes of one vector.
pub(super) const GROUP: usize = 4;

/// The tree primitives' boxes by blocks: primitive `i` is lane `i % 4` of block `i / 4`; the
/// lanes past the last primitive hold empty boxes.
#[derive(Clone, Debug, Default)]
pub(super) struct Lanes {
    blocks: Vec<Group>,
    /// Tree primitives covered.
    len: usize,
}

/// Four boxes, one per lane. 96 bytes.
#[derive(Clone, Copy, Debug)]
pub(super) struct Group {
    /// `min.x`, `min.y`, `min.z` of the four boxes. 48 bytes.
    min: [Vec4; 3],
    /// `max.x`, `max.y`, `max.z` of the four boxes. 48 bytes.
    max: [Vec4; 3],
}

const _: () = assert!(core::mem::size_of::<Group>() == 96);

impl Group {
    pub(super) const EMPTY: Group = Group {
        min: [Vec4::INFINITY; 3],
        max: [Vec4::NEG_INFINITY; 3],
    };

    /// Writes `b` to lane `k` (`< 4`).
    #[inline(always)]
    pub(super) fn set(&mut self, k: usize, b: &SimdBox) {
        let k = k % GROUP;
        fn lane(v: &mut Vec4, k: usize) -> &mut f32 {
            &mut AsMut::<[f32; 4]>::as_mut(v)[k]
        }
        let ([x0, y0, z0], [x1, y1, z1]) = (&mut self.min, &mut self.max);
        *lane(x0, k) = b.min.x;
        *lane(y0, k) = b.min.y;
        *lane(z0, k) = b.min.z;
        *lane(x1, k) = b.max.x;
        *lane(y1, k) = b.max.y;
        *lane(z1, k) = b.max.z;
    }

    /// The four boxes' faces: `min.x`, `min.y`, `min.z` and `max.x`, `max.y`, `max.z`, one
    /// lane per box (for the ray kernel of the queries).
    #[inline(always)]
    pub(super) fn faces(&self) -> (&[Vec4; 3], &[Vec4; 3]) {
        (&self.min, &self.max)
    }

    /// Bit `k` set iff box `k` of the block overlaps the splatted box (closed, as
    /// [`SimdBox::overlaps`]).
    #[inline(always)]
    pub(super) fn overlaps(&self, q: &Splat) -> u32 {
        let x = self.min[0].cmple(q.max[0]) & q.min[0].cmple(self.max[0]);
        let y = self.min[1].cmple(q.max[1]) & q.min[1].cmple(self.max[1]);
        let z = self.min[2].cmple(q.max[2]) & q.min[2].cmple(self.max[2]);
        (x & y & z).bitmask()
    }
}

/// One box with each face in all four lanes, to test against a [`Group`].
#[derive(Clone, Copy)]
pub(super) struct Splat {
    min: [Vec4; 3],
    max: [Vec4; 3],
}

impl Splat {
    #[inline(always)]
    pub(super) fn of(b: &SimdBox) -> Splat {
        let (lo, hi) = (b.min, b.max);
        Splat {
            min: [Vec4::splat(lo.x), Vec4::splat(lo.y), Vec4::splat(lo.z)],
            max: [Vec4::splat(hi.x), Vec4::splat(hi.y), Vec4::splat(hi.z)],
        }
    }
}

/// The blocks that hold a leaf's primitives `first..first + len`: its primitive `j` is bit
/// `off + j` of the masks over `blocks` ([`Leaf::mask`]).
#[derive(Clone, Copy)]
pub(super) struct Leaf<'a> {
    pub(super) blocks: &'a [Group],
    pub(super) off: usize,
    /// Bits `off..off + len`.
    pub(super) valid: u64,
}

impl Leaf<'_> {
    /// Bit `k` set iff lane `k` of the blocks from `from` on overlaps `q` (bits of earlier
    /// blocks clear; lanes outside the leaf are not masked here).
    #[inline(always)]
    pub(super) fn mask_from(&self, from: usize, q: &Splat) -> u64 {
        let mut m = 0;
        for (j, b) in self.blocks.iter().enumerate().skip(from) {
            m |= u64::from(b.overlaps(q)) << (GROUP * j);
        }
        m
    }

    /// Bit `off + j` set iff the leaf's primitive `j` overlaps `q`.
    #[inline(always)]
    pub(super) fn mask(&self, q: &Splat) -> u64 {
        self.mask_from(0, q) & self.valid
    }
}

impl Lanes {
    /// Heap bytes held (capacities).
    pub(super) fn heap_bytes(&self) -> usize {
        self.blocks.capacity() * core::mem::size_of::<Group>()
    }

    /// Rewrites every block from `boxes` (the tree's primitives in tree order).
    pub(super) fn fill(&mut self, boxes: &[SimdBox]) {
        self.blocks.clear();
        self.blocks
            .resize(boxes.len().div_ceil(GROUP), Group::EMPTY);
        self.len = boxes.len();
        for (i, b) in boxes.iter().enumerate() {
            self.set(i, b);
        }
    }

    /// Writes the box of tree primitive `i`.
    #[inline]
    pub(super) fn set(&mut self, i: usize, b: &SimdBox) {
        self.blocks[i / GROUP].set(i % GROUP, b);
    }

    /// The box of tree primitive `i`, as written.
    pub(super) fn get(&self, i: usize) -> SimdBox {
        let (g, k) = (&self.blocks[i / GROUP], i % GROUP);
        SimdBox {
            min: Vec3A::new(g.min[0][k], g.min[1][k], g.min[2][k]),
            max: Vec3A::new(g.max[0][k], g.max[1][k], g.max[2][k]),
        }
    }

    /// Tree primitives covered.
    pub(super) fn len(&self) -> usize {
        self.len
    }

    /// The blocks of primitives `first..first + len`, or `None` if their masks would not fit
    /// 64 bits (`first % 4 + len > 64`: leaves of more than 61 boxes).
    #[inline]
    pub(super) fn leaf(&self, first: usize, len: usize) -> Option<Leaf<'_>> {
        let off = first % GROUP;
        if off + len > 64 || len == 0 {
            return None;
        }
        Some(Leaf {
            blocks: &self.blocks[first / GROUP..(first + len).div_ceil(GROUP)],
            off,
            valid: low_bits(len) << off,
        })
    }
}

/// The most rows one leaf kernel records: one per box of a leaf.
const FOUND_ROWS: usize = 64;

/// The overlap masks of a leaf kernel's rows (one box's tests against a leaf's blocks), kept
/// only if not empty without a branch on that: each row is stored unconditionally and the
/// length advances by whether its mask has a bit set. The pairs are then handed on by one
/// loop over all the set bits of all the rows ([`Found::drain`]) instead of one set-bit loop
/// per row, whose exits the branch predictor cannot guess.
pub(super) struct Found {
    /// `(row, mask)`; one spare entry takes the last unconditional store.
    rows: [(usize, u64); FOUND_ROWS + 1],
    len: usize,
}

impl Found {
    pub(super) fn new() -> Found {
        Found {
            rows: [(0, 0); FOUND_ROWS + 1],
            len: 0,
        }
    }

    /// Records the pairs `(row, k)` for each set bit `k` of `mask`. At most [`FOUND_ROWS`]
    /// rows between two [`Found::drain`]s.
    #[inline(always)]
    pub(super) fn push(&mut self, row: usize, mask: u64) {
        debug_assert!(self.len < FOUND_ROWS);
        let at = self.len.min(FOUND_ROWS);
        self.rows[at] = (row, mask);
        self.len = at + usize::from(mask != 0);
    }

    /// Calls `f(row, k)` for each recorded pair, rows in the order recorded and each row's
    /// bits lowest first, and forgets them. One loop over the pairs: each turn clears the bit
    /// it hands on in the row's stored mask and moves to the next row when none is left, by
    /// arithmetic, not a branch.
    #[inline(always)]
    pub(super) fn drain(&mut self, mut f: impl FnMut(usize, usize)) {
        let rows = &mut self.rows[..self.len];
        self.len = 0;
        let mut r = 0;
        while let Some(&mut (row, ref mut mask)) = rows.get_mut(r) {
            f(row, mask.trailing_zeros() as usize);
            *mask &= *mask - 1;
            r += usize::from(*mask == 0);
        }
    }
}

/// The positions of the set bits of `m`, lowest first.
#[inline]
pub(super) fn bits(mut m: u64) -> impl Iterator<Item = usize> {
    core::iter::from_fn(move || {
        (m != 0).then(|| {
            let k = m.trailing_zeros() as usize;
            m &= m - 1;
            k
        })
    })
}

/// The lowest `len` bits set (`len <= 64`).
#[inline]
pub(super) fn low_bits(len: usize) -> u64 {
    if len == 0 { 0 } else { u64::MAX >> (64 - len) }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geom::Aabb;
    use crate::rng::Rng;
    use glam::Vec3;

    /// The group test and the masks agree with `SimdBox::overlaps` box by box, touching
    /// faces and the padding included.
    #[test]
    fn masks_match_the_box_test() {
        let mut rng = Rng::new(5);
        let boxes: Vec<SimdBox> = (0..70)
            .map(|i| {
                if i % 9 == 0 {
                    return SimdBox::EMPTY;
                }
                let c = rng.vec3_in(Vec3::splat(-3.0), Vec3::splat(3.0));
                // Integer corners: many boxes touch exactly.
                SimdBox::new(&Aabb::new(c.floor(), c.floor() + Vec3::ONE))
            })
            .collect();
        let mut lanes = Lanes::default();
        lanes.fill(&boxes);
        assert_eq!(lanes.len(), boxes.len());
        for q in &boxes {
            let s = Splat::of(q);
            for first in [0, 1, 5, 6] {
                for len in [1, 3, 4, 5, 33, 60, 64] {
                    let Some(leaf) = lanes.leaf(first, len) else {
                        assert!(first % 4 + len > 64);
                        continue;
                    };
                    let want = (0..len).fold(0u64, |m, k| {
                        m | u64::from(boxes[first + k].overlaps(q)) << (k + leaf.off)
                    });
                    assert_eq!(leaf.mask(&s), want, "{first} {len}");
                }
            }
        }
        lanes.set(3, &boxes[7]);
        assert_eq!(lanes.get(3), boxes[7]);
    }

    /// `Found` hands on every set bit of every pushed row once, in push order and lowest bit
    /// first, as the set-bit loops did, skipping empty rows, and is empty after a drain.
    #[test]
    fn found_hands_on_each_set_bit_once() {
        let mut rng = Rng::new(7);
        let mut found = Found::new();
        let word = |rng: &mut Rng| u64::from(rng.next_u32()) << 32 | u64::from(rng.next_u32());
        for round in 0..200 {
            let masks: Vec<u64> = (0..rng.below(65) as usize)
                .map(|_| match rng.below(4) {
                    0 => 0,
                    1 => 1 << rng.below(64),
                    2 => u64::MAX,
                    _ => word(&mut rng) & word(&mut rng),
                })
                .collect();
            let mut want = Vec::new();
            for (row, &m) in masks.iter().enumerate() {
                found.push(row, m);
                want.extend(bits(m).map(|k| (row, k)));
            }
            let mut got = Vec::new();
            found.drain(|row, k| got.push((row, k)));
            assert_eq!(got, want, "round {round}");
            found.drain(|_, _| panic!("drained twice"));
        }
    }
}
