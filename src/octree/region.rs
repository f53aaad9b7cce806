//! The growing region of [`Octree::growing`]: when a tree re-roots, and over which cube.
//!
//! A growing tree's root region is a cube derived from the spheres it holds, and is replaced
//! (the tree *re-roots*: every sphere is placed again, O(n), which may allocate) by
//! [`Octree::maintain`], which the pair passes call first and a caller that only queries calls
//! itself. It re-roots when
//! - more spheres are *overflow* (outside the region, kept in the root) than [`overflow_limit`]
//!   allows: the world moved or grew;
//! - the tree holds more than twice the spheres it held at its last re-root (the first fill
//!   included): its region was chosen for another world;
//! - an audit, run every so many calls to `maintain` (the period doubles each time an audit
//!   finds nothing to gain, up to [`MAX_AUDIT_PERIOD`]), finds that a fresh region would give
//!   the typical sphere cells at least [`AUDIT_GAIN`] times smaller (or, strict, larger): the
//!   spheres shrank, grew, or gathered in a corner of a region chosen for a wider world. An
//!   audit first looks at a sample of at most [`AUDIT_SAMPLE`] spheres (every k-th id) and
//!   compares its median radius and its span with the same sample's at the last re-root: while
//!   neither changed by [`AUDIT_SAMPLE_CHANGE`], the typical cells cannot have, and the audit
//!   ends there, so a world at rest pays O(sample) per audit instead of the full proposal's
//!   O(n) sorts (a pause of several steps' work in a large resting world).
//!
//! The cube. Let `r` be the median radius of the spheres and `c = CELL_DIAMETERS · 2r` the
//! cell a sphere of that radius should get. The cube's side is `c · 2^k` for the least `k` that
//! covers the spheres' boxes grown by [`GROW`], so that level `k`'s cells are `c` wherever the
//! world is and however wide it is, as long as `k <= MAX_DEPTH`; a wider world gets a side of
//! its span and cells wider than `c`. Loose trees get levels down to `k +`
//! [`LEVELS_BELOW_TYPICAL`] (capped at `MAX_DEPTH`) for the spheres smaller than typical;
//! strict trees [`depth_for`] the region and `r`.
//!
//! Sparse worlds. In a world whose spheres lie far apart (a thin open world), cells of `c`
//! would give nearly every sphere node pages of its own, and every neighbour lookup of the
//! pass would miss the cache. So `c` is doubled while the spheres per occupied cell of the
//! doubled size stay below [`SPHERES_PER_CELL`], counted over the spheres themselves (never
//! estimated from the span's volume: two dense clusters far apart keep cells that fit their
//! spheres), and the coarsened cells are then the deepest level. Worlds of fewer than
//! [`MIN_SPHERES_TO_COARSEN`] spheres are not coarsened.
//!
//! Outliers. If covering every box would need cells wider than `c` at `MAX_DEPTH` (one sphere
//! teleported to 1e7 m would put a whole world of small spheres in one cell), the cube covers
//! instead, per axis, the boxes between the `q`-th lowest minimum and the `q`-th highest
//! maximum, `q = min(overflow_limit / 16, n / 16)`, when that is at most half as wide; the at
//! most `6q <= 3/8 · overflow_limit` spheres left out stay overflow, fewer than half the limit.
//!
//! Why no pass between two re-roots is quadratic: after a re-root at most `3/8` of the limit
//! is overflow (none, unless outliers were left out), and `maintain` runs before every pass,
//! so a pass sees at most [`overflow_limit`] overflow spheres: `max(64, n / 64)`. Each meets
//! the tree through its own clamped cell range (the strict pass's filtered ancestor stack, the
//! loose pass's per-sphere descent from the root), which an overflow sphere's box reaches only
//! on the region's faces, and the overflow spheres meet each other through the root's own
//! list, which both passes split over the root cell by their clamped ranges. The hysteresis
//! ([`GROW`], and the power of two above it) lets a world drift by a quarter of its span or
//! more before the next re-root, and a world that moved since the last re-root gets room ahead
//! of it for as much motion again, so a world in flight re-roots less often the faster it
//! goes: re-roots are amortised like a growing `Vec`'s copies.

use super::cell::{self, level_of};
use super::placement::{Lattice, depth_for};
use super::{MAX_DEPTH, NONE, Obj, Octree, Placement};
use crate::geom::{self, Aabb, from_ordered_bits, ordered_bits};
use glam::Vec3;

impl Octree {
    /// A growing tree re-roots here if it needs to (see [`Octree::growing`]): when more
    /// spheres lie outside its region than `max(64, len / 64)` (and than twice as many as
    /// right after its last re-root), when it holds more than twice the spheres it held at its
    /// last re-root, or when a periodic audit (its period doubling while audits find nothing,
    /// up to 1024 calls) finds cells that no longer fit the spheres. O(1) otherwise; a re-root
    /// places every sphere again, O(n), and may allocate. The pair passes call it first; a
    /// caller that moves spheres and only queries should call it after each batch of moves
    /// (queries stay exact without it, but pay for every sphere outside the region). Does
    /// nothing for a tree with a fixed region.
    pub fn maintain(&mut self) {
        if !self.growing {
            return;
        }
        if self.live == 0 {
            self.regrow.rooted = 0;
            return;
        }
        let limit = overflow_limit(self.live).max(2 * self.overflow_after as usize);
        if self.overflow as usize > limit || self.live > 2 * self.regrow.rooted {
            match self.propose() {
                Some(p) => self.reroot(&p),
                None => {
                    // No finite region covers the world: keep this one, and wait for twice
                    // the overflow (or spheres) before trying again.
                    let sampled = self.audit_sample();
                    self.regrow.rooted(self.live, None, sampled);
                    self.overflow_after = self.overflow;
                }
            }
            return;
        }
        if self.regrow.tick() {
            let sampled = self.audit_sample();
            if self.regrow.sample_unchanged(sampled) {
                self.regrow.back_off();
                return;
            }
            self.regrow.full_audits += 1;
            match self.propose() {
                Some(p) if worth_it(&self.lattice, &p) => self.reroot(&p),
                _ => self.regrow.back_off(),
            }
        }
    }

    /// The audit's sample of the spheres now (`Sampled::of`, with the walk order's
    /// buffer lent as scratch).
    fn audit_sample(&mut self) -> Option<Sampled> {
        Sampled::of(&self.objs, self.passes.walk.idle_items())
    }

    /// The region and depth the spheres call for now (`Regrow::propose` over this tree's
    /// spheres, hint and placement, with the walk order's buffers lent as scratch).
    fn propose(&mut self) -> Option<Proposal> {
        self.regrow.propose(
            &self.objs,
            self.live,
            self.hint,
            self.lattice.placement,
            self.passes.walk.idle_items(),
        )
    }

    /// Places every sphere again in a tree over the proposal's region and depth.
    #[inline(never)]
    fn reroot(&mut self, p: &Proposal) {
        self.lattice = Lattice::new(p.bounds, p.depth, self.lattice.placement);
        self.memo = super::placement::LevelMemo::EMPTY;
        self.nodes.reset(cell::node_count(p.depth));
        self.per_level = [0; MAX_DEPTH as usize + 1];
        self.overflow = 0;
        // Every sphere is linked again from scratch below: the lists owe nothing.
        self.deferred.clear();
        for id in 0..self.objs.len() as u32 {
            let o = &mut self.objs[id as usize];
            if o.node == NONE {
                continue;
            }
            let at = self.lattice.locate(o.center, o.radius);
            self.per_level[level_of(at.node()) as usize] += 1;
            self.overflow += u32::from(at.outside());
            self.link(id, at.node());
        }
        let sampled = self.audit_sample();
        self.regrow.rooted(self.live, Some(p.span_center), sampled);
        self.overflow_after = self.overflow;
        self.reroots += 1;
    }
}

/// Cells of the level the median sphere lives at span this many of its diameters. Below 2, so
/// the median sphere is placed at that level; above 1 by enough that a skin on its
/// radius does not lift it a level.
const CELL_DIAMETERS: f32 = 1.25;
/// A re-rooted region covers the spheres' boxes grown by this factor around their centre,
/// before rounding its side up to a power of two cells.
const GROW: f32 = 1.5;
/// Loose trees get this many levels below the median sphere's, for smaller spheres.
const LEVELS_BELOW_TYPICAL: u32 = 1;
/// The overflow limit is at least this many spheres.
const MIN_OVERFLOW: usize = 64;
/// ...and at least one in this many of the live spheres.
const OVERFLOW_SHARE: usize = 64;
/// The first audit comes after this many calls to `maintain`, as does the first after a
/// re-root.
const FIRST_AUDIT_PERIOD: u32 = 16;
/// Audits that find nothing to gain double their period up to this many calls.
const MAX_AUDIT_PERIOD: u32 = 1024;
/// An audit re-roots when a fresh region changes the median sphere's cell by this factor.
const AUDIT_GAIN: f32 = 2.0;
/// An audit samples at most this many spheres before it computes a full proposal.
const AUDIT_SAMPLE: usize = 4096;
/// An audit computes a full proposal once its sample's median radius or span changed by this
/// factor since the last re-root (well below [`AUDIT_GAIN`]: the sample's figures are
/// estimates).
const AUDIT_SAMPLE_CHANGE: f32 = 1.25;
/// Cells are doubled past the median sphere's while the spheres per occupied cell of the
/// doubled size stay below this: a sparse world gets cells near its spacing, so its spheres
/// share node pages and neighbour lookups instead of each touching pages of its own, while a
/// dense world (a few spheres per doubled cell) keeps cells that fit its spheres.
const SPHERES_PER_CELL: f32 = 2.0;
/// Worlds of fewer spheres keep the median sphere's cells: their nodes fit the caches anyway.
const MIN_SPHERES_TO_COARSEN: usize = 4096;
/// Bits per axis of the cell coordinates the occupancy count interleaves into a `u64`.
const OCCUPANCY_BITS: u32 = 21;

/// The most overflow spheres a growing tree of `live` spheres keeps before it re-roots.
#[must_use]
pub(super) fn overflow_limit(live: usize) -> usize {
    MIN_OVERFLOW.max(live / OVERFLOW_SHARE)
}

/// A region and depth to re-root at, from [`propose`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Proposal {
    pub(super) bounds: Aabb,
    pub(super) depth: u32,
    /// The cell size the median sphere gets.
    pub(super) typical_cell: f32,
    /// The median radius.
    pub(super) typical_radius: f32,
    /// The centre of the spheres' span the region was built around.
    pub(super) span_center: Vec3,
}

/// The growing policy's state: when to audit, and where the last re-root centred the region.
#[derive(Clone, Debug, Default)]
pub(super) struct Regrow {
    /// Live spheres at the last re-root (0 before the first).
    pub(super) rooted: usize,
    /// The centre of the spheres' span at the last re-root, if any: a world that moved since
    /// gets its next region shifted ahead of its motion.
    last_center: Option<Vec3>,
    /// Calls to `maintain` left until the next audit, and the current period.
    countdown: u32,
    period: u32,
    /// The audit sample's figures at the last re-root, if one was taken.
    sampled: Option<Sampled>,
    /// Audits that went on past their sample to a full proposal (a count for tests).
    pub(super) full_audits: u32,
}

/// An audit's sample of the spheres: its median radius and the largest extent of its span.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Sampled {
    radius: f32,
    side: f32,
}

impl Sampled {
    /// Every k-th id's sphere of `objs` (holes skipped), k chosen so that at most
    /// [`AUDIT_SAMPLE`] ids are read; `None` if it holds none. `s` is scratch.
    pub(super) fn of(objs: &[Obj], s: &mut Vec<u64>) -> Option<Sampled> {
        let stride = objs.len().div_ceil(AUDIT_SAMPLE).max(1);
        let sample = || objs.iter().step_by(stride).filter(|o| o.node != NONE);
        let radius = median(s, sample().map(|o| o.radius));
        let span = sample().fold(Aabb::EMPTY, |b, o| b.union(&o.aabb()));
        let side = span.extent().max_element();
        (!s.is_empty()).then_some(Sampled { radius, side })
    }

    /// True if `self` is within [`AUDIT_SAMPLE_CHANGE`] of `then` in both figures (a
    /// non-finite figure never is).
    fn unchanged_since(&self, then: &Sampled) -> bool {
        let near = |a: f32, b: f32| {
            a.is_finite()
                && b.is_finite()
                && a <= b * AUDIT_SAMPLE_CHANGE
                && b <= a * AUDIT_SAMPLE_CHANGE
        };
        near(self.radius, then.radius) && near(self.side, then.side)
    }
}

impl Regrow {
    /// Resets the audit clock after a re-root of `live` spheres around `span_center` (`None`:
    /// no region was found, the tree kept its own), whose audit sample is `sampled`.
    pub(super) fn rooted(
        &mut self,
        live: usize,
        span_center: Option<Vec3>,
        sampled: Option<Sampled>,
    ) {
        self.rooted = live;
        if span_center.is_some() {
            self.last_center = span_center;
        }
        self.sampled = sampled;
        self.period = FIRST_AUDIT_PERIOD;
        self.countdown = FIRST_AUDIT_PERIOD;
    }

    /// True if an audit may stop at its sample (`now`): the sample at the last re-root is
    /// known and neither figure changed by [`AUDIT_SAMPLE_CHANGE`] since.
    pub(super) fn sample_unchanged(&self, now: Option<Sampled>) -> bool {
        match (now, self.sampled) {
            (Some(now), Some(then)) => now.unchanged_since(&then),
            _ => false,
        }
    }

    /// Counts one call to `maintain`; true when an audit is due.
    pub(super) fn tick(&mut self) -> bool {
        self.countdown = self.countdown.saturating_sub(1);
        self.countdown == 0
    }

    /// An audit found nothing to gain: waits twice as long for the next.
    pub(super) fn back_off(&mut self) {
        self.period = (self.period.max(1) * 2).min(MAX_AUDIT_PERIOD);
        self.countdown = self.period;
    }

    /// The region and depth a tree of `placement` holding `objs` (holes included) should
    /// re-root at, covering `hint` too where that keeps the typical cells, or `None` if it
    /// holds nothing or no finite region covers enough of it.
    pub(super) fn propose(
        &mut self,
        objs: &[Obj],
        live: usize,
        hint: Option<Aabb>,
        placement: Placement,
        scratch: &mut Vec<u64>,
    ) -> Option<Proposal> {
        if live == 0 {
            return None;
        }
        // `scratch` is the pair passes' walk-order list, which holds nothing between passes:
        // one value per live sphere for the median and the quantiles, then the occupancy
        // count's cell codes. Exactly one per live sphere: the walk order's sort fills it so.
        crate::radix::grow_to(scratch, live);
        let r = median(
            scratch,
            objs.iter().filter(|o| o.node != NONE).map(|o| o.radius),
        );
        let cell = CELL_DIAMETERS * 2.0 * r;
        let (span, span_center) = self.span(objs, live, hint, cell, scratch)?;
        let (bounds, depth) = cube(objs, live, &span, (cell, r), placement, scratch)?;
        let lattice = Lattice::new(bounds, depth, placement);
        Some(Proposal {
            bounds,
            depth,
            typical_cell: lattice.typical_cell(r),
            typical_radius: r,
            span_center,
        })
    }

    /// The box a region for cells of `cell` should cover, and the centre of the spheres'
    /// span: the spheres' boxes (and `hint` where that still fits), or the boxes between the
    /// quantiles when an outlier would need cells wider than `cell`, then room ahead for the
    /// motion since the last re-root. `None` if the span has no finite centre.
    fn span(
        &self,
        objs: &[Obj],
        live: usize,
        hint: Option<Aabb>,
        cell: f32,
        scratch: &mut Vec<u64>,
    ) -> Option<(Aabb, Vec3)> {
        let mut full = Aabb::EMPTY;
        for o in objs.iter().filter(|o| o.node != NONE) {
            full = full.union(&o.aabb());
        }
        let mut span = full;
        if let Some(h) = hint {
            let both = full.union(&h);
            if fits(wide(&both), cell) {
                span = both;
            }
        }
        if !fits(wide(&span), cell) {
            let q = (overflow_limit(live) / 16).min(live / 16);
            if q > 0 {
                let robust = quantile_box(scratch, objs, q);
                if robust.is_finite() && wide(&robust) <= 0.5 * wide(&full) {
                    span = robust;
                }
            }
        }
        let span_center = span.center();
        if !span_center.is_finite() {
            return None;
        }
        // A world that moved since the last re-root gets room for as much motion again, ahead
        // of it: re-roots of a world in flight come further apart the faster it flies.
        let moved = self
            .last_center
            .map_or(Vec3::ZERO, |last| span_center - last);
        let ahead = span.union(&Aabb::new(span.min + moved, span.max + moved));
        if ahead.is_finite() && fits(wide(&ahead), cell) {
            span = ahead;
        }
        Some((span, span_center))
    }
}

/// The side of a cube over `b` with the hysteresis [`GROW`].
fn wide(b: &Aabb) -> f32 {
    b.extent().max_element() * GROW
}

/// True if a cube of `side` is finite and split into cells of `cell` within `MAX_DEPTH`
/// levels.
fn fits(side: f32, cell: f32) -> bool {
    side.is_finite() && side <= cell * (1u32 << MAX_DEPTH) as f32
}

/// The cube over `span` and its depth for spheres of median radius `r` wanting cells of
/// `cell`, the cells coarsened for a sparse world: `None` if no valid bounds
/// come out.
fn cube(
    objs: &[Obj],
    live: usize,
    span: &Aabb,
    (cell, r): (f32, f32),
    placement: Placement,
    scratch: &mut Vec<u64>,
) -> Option<(Aabb, u32)> {
    let center = span.center();
    let side = wide(span);
    // The side's floor: a cube a few float steps wide at the region's distance from the
    // origin, so its corners stay apart.
    let floor = center.abs().max_element().max(1.0) * f32::EPSILON * 64.0;
    // The cells the spheres would get: the median sphere's, or wider where the side
    // needs more than `MAX_DEPTH` levels of them.
    let finest = if fits(side, cell) {
        cell
    } else {
        side / (1u32 << MAX_DEPTH) as f32
    };
    let doublings = if finest > 0.0 && finest.is_finite() && live >= MIN_SPHERES_TO_COARSEN {
        doublings(objs, live, span.min, finest, side, scratch)
    } else {
        0
    };
    let cell = if doublings > 0 {
        finest * (1u32 << doublings) as f32
    } else {
        cell
    };
    let (side, k) = if cell > 0.0 && cell.is_finite() && side <= cell {
        (cell.max(floor), 0)
    } else if fits(side, cell) && cell > 0.0 {
        let k = (side / cell).log2().ceil().clamp(0.0, MAX_DEPTH as f32) as u32;
        ((cell * (1u32 << k) as f32).max(floor), k)
    } else {
        (side.max(floor), MAX_DEPTH)
    };
    let half = Vec3::splat(side * 0.5);
    let bounds = Aabb::new(center - half, center + half);
    geom::check_bounds(&bounds).ok()?;
    // Cells coarsened for occupancy are the deepest: a level below them would have cells
    // of at least the median diameter again, and the spheres would move down to it.
    let depth = match placement {
        Placement::Strict if doublings > 0 => depth_for(&bounds, r).min(k),
        Placement::Strict => depth_for(&bounds, r),
        Placement::Loose if doublings > 0 => k,
        Placement::Loose => (k + LEVELS_BELOW_TYPICAL).min(MAX_DEPTH),
    };
    Some((bounds, depth))
}

/// How many times to double the cell `cell` so that the spheres per occupied cell stay
/// below [`SPHERES_PER_CELL`] (cells no wider than `side`). Counts the distinct cells of
/// the live spheres' centres on a grid from `origin` (an estimate: the tree's own lattice is
/// offset from it), by sorting their interleaved cell coordinates once: a cell twice as
/// wide is the code shifted by 3 bits, so each coarser count is one scan of the sorted
/// codes. O(n); runs only when a region is proposed.
fn doublings(
    objs: &[Obj],
    live: usize,
    origin: Vec3,
    cell: f32,
    side: f32,
    codes: &mut Vec<u64>,
) -> u32 {
    let top = ((1u32 << OCCUPANCY_BITS) - 1) as f32;
    codes.clear();
    codes.extend(objs.iter().filter(|o| o.node != NONE).map(|o| {
        let q = ((o.center - origin) / cell).clamp(Vec3::ZERO, Vec3::splat(top));
        spread(q.x as u64) | spread(q.y as u64) << 1 | spread(q.z as u64) << 2
    }));
    // In place: a radix sort's second buffer would be one more per-sphere array kept for a
    // proposal that runs only when the region may change.
    codes.sort_unstable();
    let mut doublings = 0;
    while doublings < MAX_DEPTH && cell * (2u32 << doublings) as f32 <= side {
        let shift = 3 * (doublings + 1);
        let mut occupied = 0usize;
        let mut last = None;
        for &c in codes.iter() {
            let c = c >> shift;
            if last != Some(c) {
                occupied += 1;
                last = Some(c);
            }
        }
        if live as f32 >= SPHERES_PER_CELL * occupied as f32 {
            break;
        }
        doublings += 1;
    }
    doublings
}

/// The bits of `v` below [`OCCUPANCY_BITS`] spread to every third bit (Morton interleave).
fn spread(v: u64) -> u64 {
    let mut x = v & ((1 << OCCUPANCY_BITS) - 1);
    x = (x | x << 32) & 0x001f_0000_0000_ffff;
    x = (x | x << 16) & 0x001f_0000_ff00_00ff;
    x = (x | x << 8) & 0x100f_00f0_0f00_f00f;
    x = (x | x << 4) & 0x10c3_0c30_c30c_30c3;
    x = (x | x << 2) & 0x1249_2492_4924_9249;
    x
}

/// True if an audit's `fresh` proposal is worth a re-root of a tree on `current`: it changes
/// the median sphere's cell by [`AUDIT_GAIN`] (loose: only a smaller cell counts; a loose
/// sphere's level follows its radius, so a wider region only costs where it caps the depth).
pub(super) fn worth_it(current: &Lattice, fresh: &Proposal) -> bool {
    let now = current.typical_cell(fresh.typical_radius);
    let finer = now > AUDIT_GAIN * fresh.typical_cell;
    let coarser = fresh.typical_cell > AUDIT_GAIN * now;
    finer || (current.placement == Placement::Strict && coarser)
}

/// `x` as a key of the lent `u64` buffers that sorts as `f32::total_cmp` does.
fn ordered(x: f32) -> u64 {
    u64::from(ordered_bits(x))
}

/// The `k`-th smallest of the values in `s` (as [`ordered`] keys), by `f32::total_cmp`.
fn select(s: &mut [u64], k: usize) -> f32 {
    from_ordered_bits(*s.select_nth_unstable(k).1 as u32)
}

/// The median of `values` (the upper one of an even count), 0 for none; `s` is scratch.
fn median(s: &mut Vec<u64>, values: impl Iterator<Item = f32>) -> f32 {
    s.clear();
    s.extend(values.map(ordered));
    if s.is_empty() {
        return 0.0;
    }
    let mid = s.len() / 2;
    select(s, mid)
}

/// Per axis, from the `q`-th lowest box minimum to the `q`-th highest box maximum of the live
/// spheres (`q` counted from 0, so `q` boxes lie below and `q` above); `s` is scratch.
fn quantile_box(s: &mut Vec<u64>, objs: &[Obj], q: usize) -> Aabb {
    let mut b = Aabb::EMPTY;
    for axis in 0..3 {
        s.clear();
        s.extend(
            objs.iter()
                .filter(|o| o.node != NONE)
                .map(|o| ordered(o.aabb().min[axis])),
        );
        b.min[axis] = select(s, q);
        s.clear();
        s.extend(
            objs.iter()
                .filter(|o| o.node != NONE)
                .map(|o| ordered(o.aabb().max[axis])),
        );
        let hi = s.len() - 1 - q;
        b.max[axis] = select(s, hi);
    }
    b
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The median selects by `f32::total_cmp` through the lent `u64` buffers (the key mapping
    /// itself is `geom::ordered_bits`, tested there).
    #[test]
    fn median_of_ordered_keys() {
        let mut s = Vec::new();
        assert_eq!(median(&mut s, [3.0, -1.0, 2.0, 8.0, 0.5].into_iter()), 2.0);
        assert_eq!(median(&mut s, core::iter::empty()), 0.0);
    }
}
