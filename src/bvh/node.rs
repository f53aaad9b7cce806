//! The 32-byte node of the depth-first array, and the inline stack of the `&self` traversals.

use crate::geom::{Aabb, SimdBox};
use glam::{Vec3, Vec3A, Vec4};

/// One node of the depth-first array (pbrt's `LinearBVHNode`): a leaf holds the primitive
/// range `first..first + count` (`count > 0`); an interior node has `count == 0`, its first
/// child at the next index and its second child at `first`.
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(C)]
pub(crate) struct Node {
    /// Box corner with the smallest coordinates. 12 bytes.
    pub(crate) min: Vec3,
    /// Leaf: first primitive index; interior: index of the second child. 4 bytes.
    pub(crate) first: u32,
    /// Box corner with the largest coordinates. 12 bytes.
    pub(crate) max: Vec3,
    /// Leaf: number of primitives (> 0); interior: 0. 4 bytes.
    pub(crate) count: u32,
}

const _: () = assert!(core::mem::size_of::<Node>() == 32);

impl Node {
    /// A leaf over the primitives `first..first + count`.
    #[inline]
    pub(crate) fn leaf(aabb: &Aabb, first: u32, count: u32) -> Self {
        debug_assert!(count > 0);
        Node {
            min: aabb.min,
            first,
            max: aabb.max,
            count,
        }
    }

    /// An interior node whose second child is not placed yet.
    #[inline]
    pub(crate) fn interior(aabb: &Aabb) -> Self {
        Node {
            min: aabb.min,
            first: super::NONE,
            max: aabb.max,
            count: 0,
        }
    }

    #[inline]
    pub(crate) fn is_leaf(&self) -> bool {
        self.count > 0
    }

    #[inline]
    pub(crate) fn aabb(&self) -> Aabb {
        Aabb::new(self.min, self.max)
    }

    #[inline]
    pub(crate) fn set_aabb(&mut self, aabb: &Aabb) {
        self.min = aabb.min;
        self.max = aabb.max;
    }

    #[inline]
    pub(crate) fn set_box(&mut self, b: &SimdBox) {
        self.min = b.min.into();
        self.max = b.max.into();
    }

    /// The leaf's primitive range, as `usize` bounds.
    #[inline]
    pub(crate) fn range(&self) -> core::ops::Range<usize> {
        self.first as usize..(self.first + self.count) as usize
    }

    /// The two children of an interior node.
    #[inline]
    pub(crate) fn children(&self, index: u32) -> (u32, u32) {
        debug_assert!(!self.is_leaf());
        (index + 1, self.first)
    }

    /// The node's box in SIMD lanes, for the overlap tests of the traversals. Each corner is
    /// read with its neighbouring `u32` as the fourth lane (which `Vec3A` ignores), so that
    /// the four consecutive fields load as one 16-byte vector.
    #[inline]
    pub(crate) fn bounds(&self) -> SimdBox {
        let (min, max) = (self.min, self.max);
        SimdBox {
            min: Vec3A::from_vec4(Vec4::new(min.x, min.y, min.z, f32::from_bits(self.first))),
            max: Vec3A::from_vec4(Vec4::new(max.x, max.y, max.z, f32::from_bits(self.count))),
        }
    }
}

/// Entries a traversal keeps inline before it spills to the heap. A tree of 2⁶⁰ leaves built
/// balanced needs about one entry per level, so only degenerate deep trees spill.
pub(crate) const INLINE_STACK: usize = 64;

/// A LIFO stack with `N` entries inline and a heap `Vec` for the rest: traversals of `&self`
/// do not allocate unless the tree is deeper than `N`.
pub(crate) struct SmallStack<T: Copy, const N: usize> {
    buf: [T; N],
    len: usize,
    /// Entries pushed while `buf` was full; always newer than all of `buf`.
    spill: Vec<T>,
}

impl<T: Copy, const N: usize> SmallStack<T, N> {
    /// An empty stack; `fill` only initialises the inline slots.
    pub(crate) fn new(fill: T) -> Self {
        Self {
            buf: [fill; N],
            len: 0,
            spill: Vec::new(),
        }
    }

    #[inline]
    pub(crate) fn push(&mut self, x: T) {
        if self.len < N {
            self.buf[self.len] = x;
            self.len += 1;
        } else {
            self.spill.push(x);
        }
    }

    #[inline]
    pub(crate) fn pop(&mut self) -> Option<T> {
        if let Some(x) = self.spill.pop() {
            return Some(x);
        }
        if self.len == 0 {
            return None;
        }
        self.len -= 1;
        Some(self.buf[self.len])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn small_stack_is_lifo_across_the_spill() {
        let mut s = SmallStack::<u32, 4>::new(0);
        for i in 0..10 {
            s.push(i);
        }
        assert_eq!(s.pop(), Some(9));
        s.push(42);
        let rest: Vec<u32> = core::iter::from_fn(|| s.pop()).collect();
        assert_eq!(rest, [42, 8, 7, 6, 5, 4, 3, 2, 1, 0]);
    }

    #[test]
    fn node_encoding() {
        let b = Aabb::new(Vec3::ZERO, Vec3::ONE);
        let leaf = Node::leaf(&b, 3, 2);
        assert!(leaf.is_leaf());
        assert_eq!(leaf.range(), 3..5);
        assert_eq!(leaf.aabb(), b);
        let mut inner = Node::interior(&b);
        inner.first = 7;
        assert!(!inner.is_leaf());
        assert_eq!(inner.children(4), (5, 7));
    }
}
