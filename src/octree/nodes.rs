//! The paged per-node arrays (list heads and child-occupancy masks) and the one walk over
//! occupied subtrees that queries, rays, the loose pass and `validate` share.

use super::cell::{Cell, code_of, level_of, node_index};
use super::{MAX_DEPTH, NONE};

/// Nodes per page of the paged node arrays, as a power of two: 4096 nodes (16 KB of heads and
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
    /// Heap bytes held (capacities).
    pub(super) fn heap_bytes(&self) -> usize {
        (self.table.capacity() + self.head.capacity()) * 4 + self.mask.capacity()
    }

    pub(super) fn new(count: u32) -> Self {
        Nodes {
            table: vec![0; (count as usize).div_ceil(PAGE)],
            head: Vec::new(),
            mask: Vec::new(),
        }
    }

    /// Empties the arrays for a tree of `count` nodes, keeping their capacity (a re-root).
    pub(super) fn reset(&mut self, count: u32) {
        self.table.clear();
        self.table.resize((count as usize).div_ceil(PAGE), 0);
        self.head.clear();
        self.mask.clear();
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

    /// Marks the path from `node` to the root as occupied; call after `node` became non-empty.
    /// Stops at the first ancestor that was already non-empty (its own ancestors are marked).
    pub(super) fn mark_occupied(&mut self, node: u32) {
        for (parent, octant) in ancestors(node) {
            let s = self.slot_mut(parent);
            let was_empty = self.head[s] == NONE && self.mask[s] == 0;
            self.mask[s] |= 1 << octant;
            if !was_empty {
                return;
            }
        }
    }

    /// Clears occupancy bits up from `node`; call after `node` became empty.
    pub(super) fn mark_empty(&mut self, node: u32) {
        for (parent, octant) in ancestors(node) {
            let s = self.slot_mut(parent);
            self.mask[s] &= !(1 << octant);
            if self.head[s] != NONE || self.mask[s] != 0 {
                return;
            }
        }
    }

    /// Depth-first over the occupied subtree of `start`, allocation-free: calls
    /// `visit(cell, slot)` for each node entered whose page exists (`start` is always entered),
    /// and enters an occupied child (per the child masks) only if `enter(child)`.
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
            let Some(slot) = self.slot(cell.node()) else {
                continue;
            };
            visit(&cell, slot);
            let mut m = self.mask[slot];
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
