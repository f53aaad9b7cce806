//! All overlapping pairs: one depth-first walk with a filtered ancestor stack (RTCD 7.3's
//! `TestAllCollisions`), and a subdivision of long lists.
//!
//! The walk. A sphere placed in node `n` has its integer range inside `n`'s cell, so it can
//! only overlap spheres placed in `n`, in `n`'s ancestors, or in `n`'s subtree; testing each
//! node's spheres against each other and against its ancestors' spheres finds every pair
//! exactly once (at the deeper of the two nodes). The naive walk hands every ancestor sphere to
//! every descendant, which is quadratic in the root's straddlers. Here a child receives only
//! the ancestor and parent spheres whose integer range overlaps the child's cell: a sphere `a`
//! that overlaps a sphere `b` placed in the child's subtree has a range overlapping `b`'s
//! (the cell map is monotone), and `b`'s range lies inside the child's cell, so `a` is never
//! filtered out wrongly. Ranges are clamped to the grid, so overflow spheres in the root are
//! filtered the same way. The ancestor stack is one `Vec` of segments; a frame owns the
//! segment `start..end`, and everything after `end` belongs to finished frames.
//!
//! Long lists. A node's own spheres straddle its mid planes, so they lie on up to three planes
//! — a 2-D distribution that a 1-D sweep handles in O(n^1.5) (the root of the `clustered` scene
//! holds a quarter of all spheres). Long lists (own × own, or ancestors × own) are therefore
//! split further over the node's cell, virtually: each part of the cell hands each of its
//! eight octants the spheres whose range overlaps it, until a part holds few candidate pairs or
//! reaches the deepest level. A pair can then meet in several parts; it is tested only in the
//! part that contains the integer point `p = max(qmin_a, qmin_b)` (per axis), which lies in
//! both ranges, hence in exactly one part of every subdivision level, and both spheres reach
//! that part. Spheres that overlap all eight octants of a part are tested there against the
//! whole part and not handed down, so a big sphere is never copied into many small parts.
//! A deepest-level part that is still long (a crowd) is swept along x.

use super::place::node_index;
use super::{NONE, Obj, Octree};

/// Lists (or list pairs) with at most this many candidate pairs are tested all against all;
/// longer ones are subdivided.
const LEAF_PAIRS: usize = 64;
/// Ancestors × own where one side is at most this long are tested all against all: the
/// subdivision only pays when both sides are long.
const SHORT_SIDE: usize = 4;

/// One node to visit: its place in the tree and its segment of the ancestor stack.
#[derive(Clone, Copy, Debug)]
struct Frame {
    node: u32,
    code: u32,
    level: u32,
    /// Cell coordinates at `level`.
    cell: [u32; 3],
    start: u32,
    end: u32,
}

/// A part of a node's cell in the subdivision of a long list: its integer corner and size
/// `2^shift`, and its lists in `Scratch::lists`.
#[derive(Clone, Copy, Debug)]
struct Part {
    lo: [u32; 3],
    shift: u32,
    start: u32,
    mid: u32,
    end: u32,
}

/// A sphere's extent along the sweep axis.
#[derive(Clone, Copy, Debug)]
struct Entry {
    lo: f32,
    hi: f32,
    id: u32,
}

/// Buffers of the pair walk, reused by every pass; they never shrink.
#[derive(Clone, Debug, Default)]
pub(super) struct Scratch {
    stack: Vec<Frame>,
    anc: Vec<u32>,
    own: Vec<u32>,
    /// Candidates for the children of the current node, with the octants they overlap.
    cand: Vec<(u32, u8)>,
    /// Parts of the current subdivision still to visit, and their lists (segments, like the
    /// ancestor stack): a part's first list is `start..mid`, its second `mid..end`.
    parts: Vec<Part>,
    lists: Vec<u32>,
    /// Octants of each sphere of the current part.
    octs: Vec<u8>,
    /// The two sides of a crowded part, sorted along x.
    sorted: [Vec<Entry>; 2],
    pub(super) tests: u64,
    pub(super) nodes_visited: u32,
}

/// Octants of a node with mid cell `mid` that the range of `o` overlaps (bit `x | y<<1 | z<<2`).
#[inline]
fn octants(o: &Obj, mid: [u32; 3]) -> u8 {
    const HIGH: [u8; 3] = [0xAA, 0xCC, 0xF0];
    let mut m = 0xFF;
    for a in 0..3 {
        if u32::from(o.qmin[a]) >= mid[a] {
            m &= HIGH[a];
        }
        if u32::from(o.qmax[a]) < mid[a] {
            m &= !HIGH[a];
        }
    }
    m
}

/// Tests every pair of one list sorted by `lo`.
fn sweep_self(list: &[Entry], test: &mut impl FnMut(u32, u32)) {
    for (i, e) in list.iter().enumerate() {
        for f in &list[i + 1..] {
            if f.lo > e.hi {
                break;
            }
            test(e.id, f.id);
        }
    }
}

/// Tests every pair across two lists sorted by `lo`: in merged order, each entry scans the
/// other list's entries not yet passed while they start before it ends, so a pair that
/// overlaps on the axis is tested once, by whichever of the two starts first.
fn sweep_bi(a: &[Entry], b: &[Entry], test: &mut impl FnMut(u32, u32)) {
    let (mut i, mut j) = (0, 0);
    while i < a.len() && j < b.len() {
        if a[i].lo <= b[j].lo {
            let e = a[i];
            for f in b[j..].iter().take_while(|f| f.lo <= e.hi) {
                test(e.id, f.id);
            }
            i += 1;
        } else {
            let e = b[j];
            for f in a[i..].iter().take_while(|f| f.lo <= e.hi) {
                test(f.id, e.id);
            }
            j += 1;
        }
    }
}

impl Octree {
    /// Calls `emit(i, j)` with dense ids for every overlapping pair, once; counts the AABB
    /// tests and visited nodes into `s`.
    pub(super) fn walk_pairs(&self, s: &mut Scratch, emit: &mut impl FnMut(u32, u32)) {
        s.tests = 0;
        s.nodes_visited = 0;
        s.stack.clear();
        s.anc.clear();
        if self.objs.is_empty() {
            return;
        }
        let objs = &self.objs[..];
        let mut tests = 0u64;
        let mut test = |x: u32, y: u32| {
            tests += 1;
            if objs[x as usize].aabb.overlaps(&objs[y as usize].aabb) {
                emit(x, y);
            }
        };
        s.stack.push(Frame {
            node: 0,
            code: 0,
            level: 0,
            cell: [0; 3],
            start: 0,
            end: 0,
        });
        while let Some(f) = s.stack.pop() {
            s.anc.truncate(f.end as usize);
            s.nodes_visited += 1;
            s.own.clear();
            let mut i = self.nodes.head(f.node);
            while i != NONE {
                s.own.push(i);
                i = objs[i as usize].next;
            }
            let shift = self.depth - f.level;
            let lo = f.cell.map(|c| c << shift);
            self.node_pairs(s, &f, lo, shift, &mut test);
            let mask = self.nodes.mask(f.node);
            if mask == 0 {
                continue;
            }
            // A non-empty child mask means `f.level < depth`, so `shift >= 1`.
            let mid = lo.map(|l| l + (1 << (shift - 1)));
            s.cand.clear();
            for k in f.start as usize..f.end as usize {
                let id = s.anc[k];
                let o = octants(&objs[id as usize], mid) & mask;
                if o != 0 {
                    s.cand.push((id, o));
                }
            }
            for &id in &s.own {
                let o = octants(&objs[id as usize], mid) & mask;
                if o != 0 {
                    s.cand.push((id, o));
                }
            }
            for c in (0..8u32).rev().filter(|c| mask & (1 << c) != 0) {
                let start = s.anc.len() as u32;
                s.anc.extend(
                    s.cand
                        .iter()
                        .filter(|&&(_, o)| o & (1 << c) != 0)
                        .map(|&(id, _)| id),
                );
                let code = f.code * 8 + c;
                s.stack.push(Frame {
                    node: node_index(f.level + 1, code),
                    code,
                    level: f.level + 1,
                    cell: [0, 1, 2].map(|a| f.cell[a] * 2 + ((c >> a) & 1)),
                    start,
                    end: s.anc.len() as u32,
                });
            }
        }
        s.tests = tests;
    }

    /// Pairs among the node's own spheres (`s.own`) and between them and the ancestors in
    /// `s.anc[f.start..f.end]`.
    fn node_pairs(
        &self,
        s: &mut Scratch,
        f: &Frame,
        lo: [u32; 3],
        shift: u32,
        test: &mut impl FnMut(u32, u32),
    ) {
        let n = s.own.len();
        if n * n.saturating_sub(1) / 2 <= LEAF_PAIRS {
            for (i, &x) in s.own.iter().enumerate() {
                for &y in &s.own[i + 1..] {
                    test(x, y);
                }
            }
        } else {
            s.lists.clear();
            s.lists.extend_from_slice(&s.own);
            self.split_pairs(s, lo, shift, false, test);
        }
        let anc = f.start as usize..f.end as usize;
        if anc.len() * n <= LEAF_PAIRS || anc.len().min(n) <= SHORT_SIDE {
            for &x in &s.anc[anc] {
                for &y in &s.own {
                    test(x, y);
                }
            }
        } else {
            s.lists.clear();
            s.lists.extend_from_slice(&s.anc[anc]);
            s.lists.extend_from_slice(&s.own);
            self.split_pairs(s, lo, shift, true, test);
        }
    }

    /// Tests the pairs of `s.lists` — within it (`bi == false`), or between its first part and
    /// the last `s.own.len()` entries (`bi == true`) — by subdividing the cell at `lo` of size
    /// `2^shift`; see the module docs for the rule that makes each pair meet once.
    fn split_pairs(
        &self,
        s: &mut Scratch,
        lo: [u32; 3],
        shift: u32,
        bi: bool,
        test: &mut impl FnMut(u32, u32),
    ) {
        let objs = &self.objs[..];
        let end = s.lists.len() as u32;
        let mid = if bi { end - s.own.len() as u32 } else { 0 };
        s.parts.clear();
        s.parts.push(Part {
            lo,
            shift,
            start: 0,
            mid,
            end,
        });
        while let Some(p) = s.parts.pop() {
            s.lists.truncate(p.end as usize);
            // `p = max(qmin_x, qmin_y) >= lo` per axis: the pair's point is in this part (it
            // is never past the part's far side, as both ranges overlap the part).
            let lo = p.lo;
            let mut tested = |x: u32, y: u32| {
                let (a, b) = (&objs[x as usize], &objs[y as usize]);
                if (0..3).all(|k| a.qmin[k].max(b.qmin[k]) as u32 >= lo[k]) {
                    test(x, y);
                }
            };
            let (first, second) = (
                p.start as usize..p.mid as usize,
                p.mid as usize..p.end as usize,
            );
            let pairs = if bi {
                first.len() * second.len()
            } else {
                second.len() * second.len().saturating_sub(1) / 2
            };
            if pairs <= LEAF_PAIRS || (bi && first.len().min(second.len()) <= SHORT_SIDE) {
                let l = &s.lists;
                for (i, &y) in l[second.clone()].iter().enumerate() {
                    let others = if bi {
                        &l[first.clone()]
                    } else {
                        &l[p.mid as usize + i + 1..p.end as usize]
                    };
                    for &x in others {
                        tested(x, y);
                    }
                }
                continue;
            }
            if p.shift == 0 {
                // A crowd in one deepest cell: sweep along x.
                for (side, range) in [first, second].into_iter().enumerate() {
                    let v = &mut s.sorted[side];
                    v.clear();
                    v.extend(s.lists[range].iter().map(|&id| {
                        let b = &objs[id as usize].aabb;
                        Entry {
                            lo: b.min.x,
                            hi: b.max.x,
                            id,
                        }
                    }));
                    v.sort_unstable_by(|x, y| x.lo.total_cmp(&y.lo));
                }
                if bi {
                    sweep_bi(&s.sorted[0], &s.sorted[1], &mut tested);
                } else {
                    sweep_self(&s.sorted[1], &mut tested);
                }
                continue;
            }
            let half = 1u32 << (p.shift - 1);
            let centre = lo.map(|l| l + half);
            s.octs.clear();
            s.octs.extend(
                s.lists[p.start as usize..p.end as usize]
                    .iter()
                    .map(|&id| octants(&objs[id as usize], centre)),
            );
            // Spheres overlapping all eight octants are resolved here against the whole part.
            let l = &s.lists;
            let big = |i: usize| s.octs[i - p.start as usize] == 0xFF;
            if bi {
                for i in second.clone().filter(|&i| big(i)) {
                    for j in first.clone() {
                        tested(l[j], l[i]);
                    }
                }
                for i in first.clone().filter(|&i| big(i)) {
                    for j in second.clone().filter(|&j| !big(j)) {
                        tested(l[i], l[j]);
                    }
                }
            } else {
                for i in second.clone().filter(|&i| big(i)) {
                    for j in second.clone().filter(|&j| j > i || (j < i && !big(j))) {
                        tested(l[j], l[i]);
                    }
                }
            }
            let oct = |i: usize| s.octs[i - p.start as usize];
            let reach = |r: &core::ops::Range<usize>| {
                r.clone()
                    .map(oct)
                    .filter(|&o| o != 0xFF)
                    .fold(0u8, |m, o| m | o)
            };
            let children = if bi {
                reach(&first) & reach(&second)
            } else {
                reach(&second)
            };
            for c in (0..8u32).filter(|c| children & (1 << c) != 0) {
                let keep = |i: &usize| oct(*i) != 0xFF && oct(*i) & (1 << c) != 0;
                let start = s.lists.len();
                for i in first.clone().filter(keep) {
                    s.lists.push(s.lists[i]);
                }
                let cmid = s.lists.len();
                for i in second.clone().filter(keep) {
                    s.lists.push(s.lists[i]);
                }
                let cend = s.lists.len();
                let useful = if bi {
                    cmid > start && cend > cmid
                } else {
                    cend - cmid >= 2
                };
                if useful {
                    s.parts.push(Part {
                        lo: [0, 1, 2].map(|a| lo[a] + ((c >> a) & 1) * half),
                        shift: p.shift - 1,
                        start: start as u32,
                        mid: cmid as u32,
                        end: cend as u32,
                    });
                } else {
                    s.lists.truncate(start);
                }
            }
        }
    }
}
