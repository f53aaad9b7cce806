//! All overlapping pairs of a [`Placement::Strict`](super::Placement::Strict) tree: one
//! streaming walk over the node runs of the walk order with a filtered ancestor stack (RTCD
//! 7.3's `TestAllCollisions`), and a virtual subdivision of long own lists.
//!
//! Order. A strict walk key ([`StrictKey`]) is the node's Morton prefix shifted to the deepest
//! level, then the level as a tie-break, so a node sorts right after its ancestors and before
//! its subtree, and every subtree is one contiguous key range: the walk order is depth-first.
//!
//! The walk. A sphere placed in node `n` has its integer range inside `n`'s cell, so it can
//! only overlap spheres placed in `n`, in `n`'s ancestors, or in `n`'s subtree; testing each
//! node's spheres against each other and against its ancestors' spheres finds every pair
//! exactly once (at the deeper of the two nodes). The naive walk hands every ancestor sphere to
//! every descendant, which is quadratic in the root's straddlers. Here the path from the root
//! to the current node is a stack of levels, and level `l` holds **copies** of the ancestor
//! spheres whose integer range overlaps the level-`l` cell: the parent level's copies plus the
//! parent node's own spheres, filtered by that cell. Each of those ranges meets the parent's
//! cell, so the filter is one bit of its octant mask at the parent's mid cell, computed once
//! per parent when its first child is entered. A sphere `a` that overlaps a sphere `b`
//! placed in the cell's subtree has a range overlapping `b`'s (the cell map is monotone), and
//! `b`'s range lies inside the cell, so `a` is never filtered out wrongly. Ranges are clamped
//! to the lattice, so overflow spheres in the root are filtered the same way. Levels between the
//! current node and its nearest occupied ancestor are filtered too (with no own spheres), so a
//! long list is narrowed step by step and shared by all the nodes under a level.
//!
//! Long own lists. A node's own spheres straddle its mid planes, so they lie on up to three
//! planes, a 2-D distribution that a 1-D sweep handles badly (every sphere of a plane overlaps
//! every other along the plane's normal). A long own list is therefore split further over the
//! node's cell, virtually: each part of the cell hands each of its eight octants copies of the
//! spheres whose range reaches it, until a part is short or reaches the deepest level (then it
//! is swept along x). A pair can meet in several parts; it is reported only in the part that
//! contains the integer point `p = max(qmin_a, qmin_b)` (per axis), which lies in both ranges,
//! hence in exactly one part of every subdivision level, and both spheres reach that part.
//! Spheres that reach all eight octants of a part are tested there against the whole part and
//! not handed down, so a big sphere is never copied into many small parts.
//!
//! Ancestors × own. Ancestor planes are never inside a node's cell, so an ancestor sphere that
//! reaches the cell lies on a face of it. Each sphere gets a group, the first axis whose mid
//! plane of its own node it straddles (2 if none): an ancestor sphere of group `g` is thin along
//! `g`, and a long ancestors × own list is swept, for each `g`, along axis `g` between the
//! ancestors of group `g` and all own spheres; each pair is tested once, on its ancestor's axis.

use super::cell::unmorton;
use super::placement::StrictKey;
use super::walk::{self, Hot, Keys, SHORT_SELF, Sweeps, Tester, Walk, is_short_cross, runs};
use super::{Octree, PassCost};
use crate::pair::ProxyKey;
use crate::radix::room_for;
use crate::sweep;

/// One level of the path from the root to the current node.
#[derive(Clone, Copy, Debug)]
struct Level {
    /// Morton code of the path's node at this level.
    code: u32,
    /// The node's own spheres in walk order (empty for a node only passed through).
    own: (u32, u32),
    /// Copies of the ancestor spheres that reach this level's cell, in `Scratch::anc`.
    cands: (u32, u32),
    /// True once `Scratch::anc_oct` (for `cands`) and `Scratch::hot_oct` (for `own`) hold
    /// the octants of this level's cell that each sphere reaches; computed when the first
    /// child level is entered, so each child filters by one bit test.
    octs: bool,
}

impl Level {
    const ROOT: Level = Level {
        code: 0,
        own: (0, 0),
        cands: (0, 0),
        octs: false,
    };
}

/// A part of a node's cell in the subdivision of a long own list: its integer corner, its
/// size `2^shift`, and its spheres `Parts::buf[start..end]`.
#[derive(Clone, Copy, Debug)]
struct Part {
    lo: [u32; 3],
    shift: u32,
    start: u32,
    end: u32,
}

/// Buffers of the subdivision of long own lists (also the loose pass's, for its root).
#[derive(Clone, Debug, Default)]
pub(super) struct Parts {
    stack: Vec<Part>,
    buf: Vec<Hot>,
    octs: Vec<u8>,
}

/// Buffers of the strict pass, reused by every pass; they never shrink.
#[derive(Clone, Debug, Default)]
pub(super) struct Scratch {
    /// By sphere id: the sphere's sweep group (see the module docs).
    group: Vec<u8>,
    path: Vec<Level>,
    /// The ancestor copies of every level of the path; `anc[..path.last().cands.1]` is live,
    /// the rest is room that only grows, so copies store into it without growing the vector.
    anc: Vec<Hot>,
    /// Octant masks of the copies in `anc` and of the spheres in `hot`, relative to the cell
    /// of the level they are read at (see `Level::octs`).
    anc_oct: Vec<u8>,
    hot_oct: Vec<u8>,
    parts: Parts,
}

impl Scratch {
    /// Heap bytes held (capacities).
    pub(super) fn heap_bytes(&self) -> usize {
        use core::mem::size_of;
        self.group.capacity()
            + self.path.capacity() * size_of::<Level>()
            + self.anc.capacity() * size_of::<Hot>()
            + self.anc_oct.capacity()
            + self.hot_oct.capacity()
            + self.parts.heap_bytes()
    }
}

impl Parts {
    /// Heap bytes held (capacities).
    pub(super) fn heap_bytes(&self) -> usize {
        use core::mem::size_of;
        self.buf.capacity() * size_of::<Hot>()
            + self.stack.capacity() * size_of::<Part>()
            + self.octs.capacity()
    }
}

/// Octants of a cell with mid cell `mid` that the range of `h` reaches (bit `x | y<<1 | z<<2`).
#[inline]
fn octants(h: &Hot, mid: [u32; 3]) -> u8 {
    const HIGH: [u8; 3] = [0xAA, 0xCC, 0xF0];
    let mut m = 0xFF;
    for a in 0..3 {
        if u32::from(h.qmin[a]) >= mid[a] {
            m &= HIGH[a];
        }
        if u32::from(h.qmax[a]) < mid[a] {
            m &= !HIGH[a];
        }
    }
    m
}

/// True if the pair's point `max(qmin_a, qmin_b)` lies in the part with corner `lo` (it lies
/// in every part both spheres reach that has a corner at most it).
#[inline]
fn meets_in(a: &Hot, b: &Hot, lo: [u32; 3]) -> bool {
    (0..3).all(|k| u32::from(a.qmin[k].max(b.qmin[k])) >= lo[k])
}

impl Octree {
    /// Calls `emit(a, b)` for every overlapping pair of a strict tree, once.
    pub(super) fn strict_pairs(
        &self,
        ws: &mut walk::Scratch,
        s: &mut Scratch,
        emit: impl FnMut(ProxyKey, ProxyKey),
    ) -> PassCost {
        let Some(Walk {
            keys,
            hot,
            mut t,
            sweeps,
            ..
        }) = self.begin_pass(ws, emit)
        else {
            return PassCost::default();
        };
        let d = self.lattice.depth;
        s.start(hot, keys, d, self.objs.len());
        let mut visited = 0;
        for (key, i, j) in runs(keys) {
            let key = StrictKey(key);
            visited += s.enter(key, d, hot);
            let level = key.level();
            let here = &mut s.path[level as usize];
            here.own = (i as u32, j as u32);
            here.octs = false;
            let cands = here.cands;
            let own = &hot[i..j];
            let shift = d - level;
            let lo = unmorton(key.prefix()).map(|c| c >> shift << shift);
            s.parts.own_pairs(&mut t, own, lo, shift, sweeps);
            let cands = &s.anc[cands.0 as usize..cands.1 as usize];
            if !cands.is_empty() {
                cross_pairs(&mut t, cands, own, &s.group, sweeps);
            }
        }
        PassCost {
            tests: t.tests,
            nodes_visited: visited,
        }
    }
}

impl Scratch {
    /// Readies the buffers for a pass over `hot`: the sweep groups, the octant buffer and a
    /// path holding only the root.
    fn start(&mut self, hot: &[Hot], keys: Keys<'_>, depth: u32, ids: usize) {
        room_for(&mut self.group, ids);
        room_for(&mut self.hot_oct, hot.len());
        self.group.resize(ids, 0);
        // Without a branch per axis: bit `a` of `straddles` is set if the sphere straddles
        // the axis-`a` mid plane of its node (`(q ^ q') >> (shift − 1) != 0`, written as
        // `(q ^ q') << 1 >> shift`, and masked off at the deepest level, `shift == 0`, where
        // there is no mid plane), and the group is the lowest set bit, 2 if none.
        for (i, h) in hot.iter().enumerate() {
            let key = keys.get(i);
            let shift = depth - StrictKey(key).level();
            let deeper = u32::from(shift != 0);
            let straddles = (0..3).fold(0u32, |m, a| {
                let x = u32::from(h.qmin[a] ^ h.qmax[a]);
                m | ((u32::from((x << 1) >> shift != 0) & deeper) << a)
            });
            self.group[h.id as usize] = (straddles | 4).trailing_zeros() as u8;
        }
        self.hot_oct.resize(hot.len(), 0);
        self.path.clear();
        self.path.push(Level::ROOT);
    }

    /// Makes the path end at the node of `key`: keeps its deepest level that is the node or an
    /// ancestor of it (the root always is), then pushes the levels below that down to the
    /// node. Returns the number of nodes entered (the root counts when it is the node).
    fn enter(&mut self, key: StrictKey, depth: u32, hot: &[Hot]) -> u32 {
        let level = key.level() as usize;
        let prefix = key.prefix();
        let mut m = (self.path.len() - 1).min(level);
        while m > 0 && self.path[m].code != prefix >> (3 * (depth - m as u32)) {
            m -= 1;
        }
        self.path.truncate(m + 1);
        let corner = unmorton(prefix);
        let mut anc_len = self.path[m].cands.1 as usize;
        for l in m + 1..=level {
            anc_len = self.push_level(l, prefix, corner, depth, anc_len, hot);
        }
        (level - m) as u32 + u32::from(level == 0)
    }

    /// Pushes level `l` of the path to the node with Morton prefix `prefix` (whose first
    /// deepest cell is `corner`): the copies of the parent level's candidates and the parent's
    /// own spheres that reach the level-`l` cell, stored from `anc_len` on. Returns the new end.
    fn push_level(
        &mut self,
        l: usize,
        prefix: u32,
        corner: [u32; 3],
        depth: u32,
        anc_len: usize,
        hot: &[Hot],
    ) -> usize {
        let parent = self.path[l - 1];
        let shift = depth - l as u32;
        let (c0, c1) = (parent.cands.0 as usize, parent.cands.1 as usize);
        let (o0, o1) = (parent.own.0 as usize, parent.own.1 as usize);
        if !parent.octs {
            // Every sphere here has its range in or across the parent's cell, so the child
            // octants it reaches are `octants` of the parent's mid cell.
            let mid = corner.map(|c| (c >> (shift + 1) << (shift + 1)) + (1 << shift));
            self.anc_oct.resize(c1, 0);
            for (o, h) in self.anc_oct[c0..c1].iter_mut().zip(&self.anc[c0..c1]) {
                *o = octants(h, mid);
            }
            for (o, h) in self.hot_oct[o0..o1].iter_mut().zip(&hot[o0..o1]) {
                *o = octants(h, mid);
            }
            self.path[l - 1].octs = true;
        }
        let code = prefix >> (3 * shift);
        let bit = 1u8 << (code & 7);
        // The candidates whose octants hold the child, copied without a branch on which do:
        // each is stored at the end, and the end advances if it counts.
        let room = anc_len + (c1 - c0) + (o1 - o0);
        if self.anc.len() < room {
            self.anc.resize(room, Hot::EMPTY);
        }
        let mut end = anc_len;
        for k in c0..c1 {
            self.anc[end] = self.anc[k];
            end += usize::from(self.anc_oct[k] & bit != 0);
        }
        for (h, &o) in hot[o0..o1].iter().zip(&self.hot_oct[o0..o1]) {
            self.anc[end] = *h;
            end += usize::from(o & bit != 0);
        }
        self.path.push(Level {
            code,
            own: (0, 0),
            cands: (anc_len as u32, end as u32),
            octs: false,
        });
        end
    }
}

/// Every pair across the ancestor copies `cands` and the node's own spheres `own`. Ancestor
/// spheres lie on the faces of the node's cell (ancestor planes are never inside it); one of
/// group `g` lies on a face normal to axis `g`, so it is swept along `g`, where it is thin,
/// against all own spheres.
fn cross_pairs<F: FnMut(ProxyKey, ProxyKey)>(
    t: &mut Tester<'_, F>,
    cands: &[Hot],
    own: &[Hot],
    group: &[u8],
    sweeps: &mut Sweeps,
) {
    if is_short_cross(cands.len(), own.len()) {
        t.tests += sweep::all_cross(cands, own, |_, a, _, b| t.emit(a, b));
        return;
    }
    for axis in 0..3 {
        let of_axis = |h: &Hot| usize::from(group[h.id as usize]) == axis;
        sweep::sort_entries_where(&mut sweeps.a, cands, axis, of_axis);
        if !sweeps.a.is_empty() {
            t.sweep_sorted(cands, own, axis, sweeps);
        }
    }
}

impl Parts {
    /// Every pair within `list`, whose cell ranges lie in the cell at `lo` of size `2^shift`,
    /// by the virtual subdivision of the module docs.
    pub(super) fn own_pairs<F: FnMut(ProxyKey, ProxyKey)>(
        &mut self,
        t: &mut Tester<'_, F>,
        list: &[Hot],
        lo: [u32; 3],
        shift: u32,
        sweeps: &mut Sweeps,
    ) {
        if list.len() <= SHORT_SELF {
            t.tests += sweep::all_pairs(list, |_, a, _, b| t.emit(a, b));
            return;
        }
        self.own_pairs_of(t, list.iter().copied(), lo, shift, sweeps);
    }

    /// [`Parts::own_pairs`] of the spheres `list` makes, more than [`SHORT_SELF`] of them.
    pub(super) fn own_pairs_of<F: FnMut(ProxyKey, ProxyKey)>(
        &mut self,
        t: &mut Tester<'_, F>,
        list: impl Iterator<Item = Hot>,
        lo: [u32; 3],
        shift: u32,
        sweeps: &mut Sweeps,
    ) {
        self.buf.clear();
        self.buf.extend(list);
        self.stack.clear();
        self.stack.push(Part {
            lo,
            shift,
            start: 0,
            end: self.buf.len() as u32,
        });
        while let Some(p) = self.stack.pop() {
            self.buf.truncate(p.end as usize);
            if p.end - p.start <= SHORT_SELF as u32 || p.shift == 0 {
                let list = &self.buf[p.start as usize..];
                leaf_part(t, list, p.lo, sweeps);
            } else {
                self.split(t, p);
            }
        }
    }

    /// Splits part `p` in its eight octants: tests the spheres that reach all of them against
    /// the whole part, and pushes each octant with copies of the other spheres that reach it.
    fn split<F: FnMut(ProxyKey, ProxyKey)>(&mut self, t: &mut Tester<'_, F>, p: Part) {
        let seg = p.start as usize..p.end as usize;
        let half = 1u32 << (p.shift - 1);
        let mid = p.lo.map(|l| l + half);
        self.octs.clear();
        self.octs
            .extend(self.buf[seg.clone()].iter().map(|h| octants(h, mid)));
        test_spanning(t, &self.buf[seg.clone()], &self.octs, p.lo);
        // Hand each octant copies of the spheres that reach it: count, then scatter.
        let mut count = [0u32; 8];
        for &o in self.octs.iter().filter(|&&o| o != 0xFF) {
            for c in bits(o) {
                count[c as usize] += 1;
            }
        }
        let mut at = [0u32; 8];
        let mut sum = self.buf.len() as u32;
        for c in 0..8 {
            at[c] = sum;
            sum += count[c];
        }
        let fill = self.buf[seg.start];
        self.buf.resize(sum as usize, fill);
        for (i, &o) in self.octs.iter().enumerate().filter(|&(_, &o)| o != 0xFF) {
            let h = self.buf[seg.start + i];
            for c in bits(o) {
                self.buf[at[c as usize] as usize] = h;
                at[c as usize] += 1;
            }
        }
        // Octants with fewer than two spheres leave a gap; a popped part truncates the
        // buffer to its own end, so gaps are never read.
        for c in (0..8u32).filter(|&c| count[c as usize] >= 2) {
            let end = at[c as usize];
            self.stack.push(Part {
                lo: [0, 1, 2].map(|a| p.lo[a] + ((c >> a) & 1) * half),
                shift: p.shift - 1,
                start: end - count[c as usize],
                end,
            });
        }
    }
}

/// The octants set in `m`, lowest first.
#[inline]
fn bits(mut m: u8) -> impl Iterator<Item = u32> {
    core::iter::from_fn(move || {
        (m != 0).then(|| {
            let c = m.trailing_zeros();
            m &= m - 1;
            c
        })
    })
}

/// The pairs of a part that is not split further (short, or one deepest cell) that meet in the
/// part (corner `lo`): all against all, testing only the pairs that meet here, or a sweep along
/// x for a crowd in one deepest cell.
fn leaf_part<F: FnMut(ProxyKey, ProxyKey)>(
    t: &mut Tester<'_, F>,
    list: &[Hot],
    lo: [u32; 3],
    sweeps: &mut Sweeps,
) {
    if list.len() <= SHORT_SELF {
        for (i, a) in list.iter().enumerate() {
            for b in &list[i + 1..] {
                if meets_in(a, b, lo) {
                    t.test(a, b);
                }
            }
        }
        return;
    }
    sweep::sort_entries(&mut sweeps.a, list, 0);
    let sorted = sweep::Ordered {
        order: &sweeps.a,
        items: list,
        axis: 0,
    };
    let tests = sweep::self_pairs_of(&sorted, |i, j| {
        if meets_in(&list[i], &list[j], lo) {
            t.emit(&list[i], &list[j]);
        }
    });
    t.tests += tests;
}

/// Tests the spheres of a part that reach all eight of its octants (`octs[i] == 0xFF`) against
/// every other sphere of the part, each pair once, reporting those that meet in the part.
fn test_spanning<F: FnMut(ProxyKey, ProxyKey)>(
    t: &mut Tester<'_, F>,
    list: &[Hot],
    octs: &[u8],
    lo: [u32; 3],
) {
    for (i, a) in list.iter().enumerate().filter(|&(i, _)| octs[i] == 0xFF) {
        for (j, b) in list.iter().enumerate() {
            if j != i && (octs[j] != 0xFF || j > i) && meets_in(a, b, lo) {
                t.test(a, b);
            }
        }
    }
}
