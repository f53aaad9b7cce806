//! The paged per-node arrays (list heads and child-occupancy masks) and the one walk over
//! occupied subtrees that queries, rays, the loose pass and `validate` share.

use super::cell::{Cell, code_of, level_of, node_index};
use super::{MAX_DEPTH, NONE};

/// Nodes per page of the paged node arrays, as a power of two: 4096 nodes (16 KB of heads or
/// 4 KB of masks), small enough that a sparse deep tree touches little memory and large enough
/// that a dense level is a handful of pages.
const PAGE_BITS: u32 = 12;
const PAGE: usize = 1 << PAGE_BITS;

/// Capacity of the walk's inline stack: a node's children are pushed when it is popped, so it
/// holds at most 7 pending siblings per level below the start plus the 8 children of the node
/// popped last.
const STACK: usize = 1 + 7 * MAX_DEPTH as usize + 8;

/// The ancestors of `node`, parent first, each with the octant of its child on the path.
fn ancestors(node: u32) -> impl Iterator<Item = (u32, u32)> {
    let mut level = level_of(node);
    let mut code = code_of(node, level);
    core::iter::from_fn(move || {
        (level > 0).then(|| {
            let octant = code & 7;
            (level, code) = (level - 1, code >> 3);
            (node_index(level, code), octant)
        })
    })
}

/// Per-node list heads and child-occupancy masks, paged apart: `table[node >> PAGE_BITS]` is
/// the page's position in `head` plus one and the page's position in `mask` plus one, each 0
/// while no node of the page was given one (reads then see an empty node). A level that holds
/// no sphere keeps no head pages, and the deepest level, which has no children, no mask pages.
/// Pages are never freed.
#[derive(Clone, Debug)]
pub(super) struct Nodes {
    table: Vec<[u32; 2]>,
    /// First object of each node's list, `NONE` if empty. 4 bytes per node.
    head: Vec<u32>,
    /// Bit `c` set iff child octant `c`'s subtree holds a sphere. 1 byte per node.
    mask: Vec<u8>,
}

/// Which of a page's two positions `Nodes::table` holds.
const HEAD: usize = 0;
const MASK: usize = 1;

/// Position of `node` in the pages whose page positions (plus one) are `at`.
#[inline]
fn position(at: u32, node: u32) -> usize {
    (((at - 1) as usize) << PAGE_BITS) | (node as usize & (PAGE - 1))
}

impl Nodes {
    /// Heap bytes held (capacities).
    pub(super) fn heap_bytes(&self) -> usize {
        self.table.capacity() * 8 + self.head.capacity() * 4 + self.mask.capacity()
    }

    pub(super) fn new(count: u32) -> Self {
        Nodes {
            table: vec![[0; 2]; (count as usize).div_ceil(PAGE)],
            head: Vec::new(),
            mask: Vec::new(),
        }
    }

    /// Empties the arrays for a tree of `count` nodes, keeping their capacity (a re-root).
    pub(super) fn reset(&mut self, count: u32) {
        self.table.clear();
        self.table.resize((count as usize).div_ceil(PAGE), [0; 2]);
        self.head.clear();
        self.mask.clear();
    }

    /// Position of `node` in `head`, if its head page exists.
    #[inline]
    pub(super) fn slot(&self, node: u32) -> Option<usize> {
        let p = self.table[(node >> PAGE_BITS) as usize][HEAD];
        (p != 0).then(|| position(p, node))
    }

    /// Position of `node` in `mask`, if its mask page exists.
    #[inline]
    fn mask_slot(&self, node: u32) -> Option<usize> {
        let p = self.table[(node >> PAGE_BITS) as usize][MASK];
        (p != 0).then(|| position(p, node))
    }

    /// Position of `node` in `head`, allocating its head page first if needed.
    fn slot_mut(&mut self, node: u32) -> usize {
        let t = (node >> PAGE_BITS) as usize;
        if self.table[t][HEAD] == 0 {
            let pages = self.head.len() / PAGE;
            self.head.resize(self.head.len() + PAGE, NONE);
            self.table[t][HEAD] = pages as u32 + 1;
        }
        position(self.table[t][HEAD], node)
    }

    /// Position of `node` in `mask`, allocating its mask page first if needed.
    fn mask_slot_mut(&mut self, node: u32) -> usize {
        let t = (node >> PAGE_BITS) as usize;
        if self.table[t][MASK] == 0 {
            let pages = self.mask.len() / PAGE;
            self.mask.resize(self.mask.len() + PAGE, 0);
            self.table[t][MASK] = pages as u32 + 1;
        }
        position(self.table[t][MASK], node)
    }

    /// Nodes allocated in pages so far: every [`Nodes::slot`] is below this.
    pub(super) fn head_len(&self) -> usize {
        self.head.len()
    }

    /// The list head of the node at position `slot`.
    #[inline]
    pub(super) fn head_at(&self, slot: usize) -> u32 {
        self.head[slot]
    }

    #[inline]
    pub(super) fn head(&self, node: u32) -> u32 {
        self.slot(node).map_or(NONE, |s| self.head[s])
    }

    #[inline]
    pub(super) fn mask(&self, node: u32) -> u8 {
        self.mask_slot(node).map_or(0, |s| self.mask[s])
    }

    pub(super) fn set_head(&mut self, node: u32, id: u32) {
        let s = self.slot_mut(node);
        self.head[s] = id;
    }

    /// True if neither the node nor any descendant holds a sphere.
    pub(super) fn is_empty(&self, node: u32) -> bool {
        self.head(node) == NONE && self.mask(node) == 0
    }

    /// Marks the path from `node` to the root as occupied; call after `node` became non-empty.
    /// Stops at the first ancestor that was already non-empty (its own ancestors are marked).
    pub(super) fn mark_occupied(&mut self, node: u32) {
        for (parent, octant) in ancestors(node) {
            let was_empty = self.is_empty(parent);
            let s = self.mask_slot_mut(parent);
            self.mask[s] |= 1 << octant;
            if !was_empty {
                return;
            }
        }
    }

    /// Clears occupancy bits up from `node`; call after `node` became empty.
    pub(super) fn mark_empty(&mut self, node: u32) {
        for (parent, octant) in ancestors(node) {
            let s = self.mask_slot_mut(parent);
            self.mask[s] &= !(1 << octant);
            if !self.is_empty(parent) {
                return;
            }
        }
    }

    /// Depth-first over the occupied subtree of `start`, allocation-free: calls
    /// `visit(cell, slot)` for each node entered whose head page exists (`slot` its position
    /// in it; `start` is always entered), and enters an occupied child (per the child masks)
    /// only if `enter(child)`.
    #[inline]
    pub(super) fn walk(
        &self,
        start: Cell,
        mut enter: impl FnMut(&Cell) -> bool,
        mut visit: impl FnMut(&Cell, usize),
    ) {
        let mut stack = [Cell::ROOT; STACK];
        stack[0] = start;
        let mut len = 1;
        while len > 0 {
            len -= 1;
            let cell = stack[len];
            let node = cell.node();
            if let Some(slot) = self.slot(node) {
                visit(&cell, slot);
            }
            let mut m = self.mask(node);
            while m != 0 {
                let child = cell.child(m.trailing_zeros());
                m &= m - 1;
                if enter(&child) {
                    stack[len] = child;
                    len += 1;
                }
            }
        }
    }
}
