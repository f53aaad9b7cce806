//! The sorted column grid: every proxy box in flat arrays, sorted by column, then by `min` on
//! the sweep axis; one pass of the sweep kernel per column and per forward neighbour column.
//!
//! A build picks a sweep axis `A` (the widest spread of box centres) and a cell size `c` (most
//! boxes are at most `FIT · c` wide on every axis). The two other axes `u`, `v` cut space into
//! columns of `c × c`, and a box lives in the column of its `min` corner. Two boxes that both
//! fit and overlap start less than `c` apart on `u` and on `v`, so their columns differ by at
//! most one on each: a column meets itself and its eight neighbours, and visiting only the
//! four forward ones (`(u, v+1)`, `(u+1, v−1)`, `(u+1, v)`, `(u+1, v+1)`) sees each pair of
//! columns once. Boxes that do not fit (too large, or too far from the origin for the column
//! arithmetic to stay exact) are *large*: they are kept in their own list and query the
//! columns they reach.
//!
//! Between builds the arrays keep their order and each entry's box is rewritten in place
//! (`boxes[pos[slot]]`): an entry whose box changed may have left its column, so it is *dirty*
//! and queries test it from the owner's dirty list instead. Inserted entries are appended past
//! the sorted part; removed ones are marked [`DEAD`] and dropped by the next build.

use crate::geom::SimdBox;
use crate::sweep;
use glam::Vec3A;

/// Set in a slot word for a static body: two static entries never pair.
pub(super) const STATIC_BIT: u32 = 1 << 31;
/// The slot word of a removed entry.
pub(super) const DEAD: u32 = u32::MAX;

/// A box fits a column when it is at most this fraction of the cell wide on every axis; the
/// slack covers the rounding of the column arithmetic.
const FIT: f32 = 0.875;
/// Column coordinates stay within this many cells of the origin (so that `f32` rounding of
/// the cell arithmetic stays far below a cell); farther boxes are large.
const MAX_CELLS: f32 = 32_768.0;
/// Boxes sampled to choose the axis and the cell size.
const SAMPLES: usize = 1024;
/// The fraction of sampled boxes that must fit the cell: the rest are large, and every query
/// tests every large box, so they must stay few.
const FIT_QUANTILE: f32 = 0.995;
/// A ray piece's box is widened by this fraction of its coordinates against rounding.
const RAY_SLACK: f32 = 1e-5;
/// Dense column tables larger than this many columns per entry use a comparison sort.
const MAX_COLUMNS_PER_ENTRY: usize = 4;

/// The grid. Entries `[0, normal)` are sorted by column then `min[A]`; `[normal, sorted)` are
/// the large ones sorted by `min[A]`; `[sorted, len)` were appended since the build.
#[derive(Clone, Debug, Default)]
pub(super) struct Grid {
    /// Each entry's box. 32 bytes per entry.
    pub(super) boxes: Vec<SimdBox>,
    /// Each entry's slot, `| STATIC_BIT` for a static body, or [`DEAD`]. 4 bytes per entry.
    pub(super) slots: Vec<u32>,
    /// Each built entry's `min[A]` as it was at the build: the order queries search, which
    /// stays sorted while dirty entries' boxes change in place. 4 bytes per entry.
    mins: Vec<f32>,
    normal: usize,
    sorted: usize,
    frame: Frame,
    /// Dense key of each column, ascending.
    cols: Vec<u32>,
    /// Where each column's entries start; one more than `cols` (the end of the last).
    col_start: Vec<u32>,
    /// Per dense key, its index in `cols` or `u32::MAX`; empty for sparse worlds (then
    /// `cols` is searched).
    col_of: Vec<u32>,
    /// The largest `max − min` on the sweep axis among the normal entries (f64: exact).
    reach: f64,
    /// The same among the large entries (may be infinite).
    large_reach: f64,
    /// Build scratch: each entry's dense column key.
    keys: Vec<u32>,
    /// Build scratch: the arrays being filled in sorted order.
    next_boxes: Vec<SimdBox>,
    next_slots: Vec<u32>,
    counts: Vec<u32>,
    samples: Vec<f32>,
    order: Vec<(u32, u32)>,
}

/// How positions map to columns, fixed at each build.
#[derive(Clone, Copy, Debug)]
struct Frame {
    /// The sweep axis, 0..3; the column axes are `(axis + 1) % 3` and `(axis + 2) % 3`.
    axis: usize,
    cell: f32,
    inv_cell: f32,
    origin_u: f32,
    origin_v: f32,
    /// Smallest occupied column coordinates minus one (the dense keys have a border).
    base_u: i32,
    base_v: i32,
    /// Dense row width: occupied `v` span plus the border on both sides.
    width: u32,
    /// Largest dense key in use, for the bounds of column searches.
    rows: u32,
}

impl Default for Frame {
    fn default() -> Self {
        Frame {
            axis: 0,
            cell: 1.0,
            inv_cell: 1.0,
            origin_u: 0.0,
            origin_v: 0.0,
            base_u: 0,
            base_v: 0,
            width: 3,
            rows: 0,
        }
    }
}

impl Frame {
    #[inline]
    fn uv(&self) -> (usize, usize) {
        ((self.axis + 1) % 3, (self.axis + 2) % 3)
    }

    /// The column coordinates of a box that fits, or `None` for a large one.
    #[inline]
    fn column(&self, b: &SimdBox) -> Option<(i32, i32)> {
        let (u, v) = self.uv();
        let ext = b.max - b.min;
        let fits = ext.max_element() <= FIT * self.cell;
        // Shifted to be positive, truncation is the floor (and needs no libm call); the
        // shift's rounding is far inside the slack `FIT` leaves.
        let qu = (b.min[u] - self.origin_u) * self.inv_cell + MAX_CELLS;
        let qv = (b.min[v] - self.origin_v) * self.inv_cell + MAX_CELLS;
        let near = (0.0..2.0 * MAX_CELLS).contains(&qu) && (0.0..2.0 * MAX_CELLS).contains(&qv);
        let shift = MAX_CELLS as i32;
        (fits && near).then(|| (qu as i32 - shift, qv as i32 - shift))
    }

    /// The dense key of column `(cu, cv)`; `None` outside the occupied range and its border.
    #[inline]
    fn key(&self, cu: i32, cv: i32) -> Option<u32> {
        let du = i64::from(cu) - i64::from(self.base_u);
        let dv = i64::from(cv) - i64::from(self.base_v);
        if du < 0 || dv < 0 || dv >= i64::from(self.width) || du > i64::from(self.rows) {
            return None;
        }
        Some((du as u32) * self.width + dv as u32)
    }

    /// The column range (inclusive) a query box must visit on `u` and on `v`: the columns of
    /// every fitting box that can overlap it. Such a box starts at most `FIT · cell` before
    /// the query's `min`, so a full cell before it, mapped like the boxes were, is enough.
    fn reach_of(&self, q: &SimdBox) -> ((i32, i32), (i32, i32)) {
        let (u, v) = self.uv();
        let map = |x: f32, o: f32| {
            let q = ((x - o) * self.inv_cell + MAX_CELLS).clamp(0.0, 2.0 * MAX_CELLS - 1.0);
            q as i32 - MAX_CELLS as i32
        };
        let c = self.cell;
        (
            (
                map(q.min[u] - c, self.origin_u),
                map(q.max[u], self.origin_u),
            ),
            (
                map(q.min[v] - c, self.origin_v),
                map(q.max[v], self.origin_v),
            ),
        )
    }
}

impl Grid {
    /// Entries (live, dead and appended).
    pub(super) fn len(&self) -> usize {
        self.slots.len()
    }

    /// Heap bytes held (capacity, not length).
    pub(super) fn heap_bytes(&self) -> usize {
        (self.boxes.capacity() + self.next_boxes.capacity()) * 32
            + (self.slots.capacity()
                + self.next_slots.capacity()
                + self.mins.capacity()
                + self.keys.capacity()
                + self.cols.capacity()
                + self.col_start.capacity()
                + self.col_of.capacity()
                + self.counts.capacity()
                + self.samples.capacity())
                * 4
            + self.order.capacity() * 8
    }

    /// Appends an entry (it is dirty until the next build) and returns its index.
    pub(super) fn push(&mut self, b: SimdBox, slot_word: u32) -> u32 {
        self.boxes.push(b);
        self.slots.push(slot_word);
        (self.slots.len() - 1) as u32
    }

    /// Marks entry `i` removed.
    pub(super) fn kill(&mut self, i: u32) {
        self.slots[i as usize] = DEAD;
        self.boxes[i as usize] = SimdBox::EMPTY;
    }

    /// Entries appended since the last build.
    pub(super) fn appended(&self) -> core::ops::Range<usize> {
        self.sorted..self.slots.len()
    }

    /// Sorts every live entry into its column, dropping dead ones, and writes each slot's new
    /// index to `pos`. The previous order seeds the sort, so a world that moved little since
    /// the last build is nearly sorted already.
    pub(super) fn build(&mut self, pos: Option<&mut [u32]>) {
        self.compact();
        self.choose_frame();
        let n = self.slots.len();
        let large = self.column_keys();
        let dense = self.dense_columns() <= (MAX_COLUMNS_PER_ENTRY * n).max(1 << 16);
        if dense {
            self.counting_sort(large);
        } else {
            self.comparison_sort();
        }
        self.normal = n - large;
        self.sorted = n;
        match self.frame.axis {
            0 => self.finish::<0>(),
            1 => self.finish::<1>(),
            _ => self.finish::<2>(),
        }
        if let Some(pos) = pos {
            for (i, &s) in self.slots.iter().enumerate() {
                pos[(s & !STATIC_BIT) as usize] = i as u32;
            }
        }
        self.col_of.clear();
        if dense {
            self.col_of.resize(self.dense_columns(), u32::MAX);
            for (c, &k) in self.cols.iter().enumerate() {
                self.col_of[k as usize] = c as u32;
            }
        }
    }

    /// Drops dead entries, keeping the order of the rest.
    fn compact(&mut self) {
        let mut w = 0;
        for r in 0..self.slots.len() {
            if self.slots[r] != DEAD {
                self.slots[w] = self.slots[r];
                self.boxes[w] = self.boxes[r];
                w += 1;
            }
        }
        self.slots.truncate(w);
        self.boxes.truncate(w);
    }

    /// Picks the sweep axis, the cell and the origin from a sample of the boxes.
    fn choose_frame(&mut self) {
        let n = self.boxes.len();
        let stride = (n / SAMPLES).max(1);
        let (mut lo, mut hi) = (Vec3A::INFINITY, Vec3A::NEG_INFINITY);
        self.samples.clear();
        for b in self.boxes.iter().step_by(stride) {
            let c = (b.min + b.max) * 0.5;
            if c.is_finite() {
                lo = lo.min(c);
                hi = hi.max(c);
            }
            self.samples.push((b.max - b.min).max_element());
        }
        let spread = if lo.x <= hi.x { hi - lo } else { Vec3A::ZERO };
        let axis = if spread.x >= spread.y && spread.x >= spread.z {
            0
        } else if spread.y >= spread.z {
            1
        } else {
            2
        };
        let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
        self.samples.sort_unstable_by(f32::total_cmp);
        let q = ((self.samples.len() as f32 * FIT_QUANTILE) as usize)
            .min(self.samples.len().saturating_sub(1));
        let size = self.samples.get(q).copied().unwrap_or(0.0) / FIT;
        // Not so small that columns hold far less than one box each.
        let area = f64::from(spread[u]) * f64::from(spread[v]);
        let sparse = (area / n.max(1) as f64).sqrt() as f32;
        let mut cell = size.max(sparse);
        if !(cell.is_finite() && cell > 1e-30) {
            cell = 1.0;
        }
        let mid = |a: usize| {
            if lo.x <= hi.x {
                (lo[a] + hi[a]) * 0.5
            } else {
                0.0
            }
        };
        self.frame = Frame {
            axis,
            cell,
            inv_cell: 1.0 / cell,
            origin_u: mid(u),
            origin_v: mid(v),
            ..Frame::default()
        };
    }

    /// Each entry's dense column key (`u32::MAX` for a large one) into `keys`; sets the
    /// frame's dense layout. Returns the number of large entries.
    fn column_keys(&mut self) -> usize {
        let (mut umin, mut umax, mut vmin, mut vmax) = (i32::MAX, i32::MIN, i32::MAX, i32::MIN);
        self.keys.clear();
        let mut large = 0;
        for b in &self.boxes {
            match self.frame.column(b) {
                Some((cu, cv)) => {
                    umin = umin.min(cu);
                    umax = umax.max(cu);
                    vmin = vmin.min(cv);
                    vmax = vmax.max(cv);
                    // Packed raw coordinates for now, made dense below.
                    self.keys
                        .push((((cu + 32_768) as u32) << 16) | (cv + 32_768) as u32);
                }
                None => {
                    large += 1;
                    self.keys.push(u32::MAX);
                }
            }
        }
        if umin > umax {
            (umin, umax, vmin, vmax) = (0, 0, 0, 0);
        }
        let f = &mut self.frame;
        f.base_u = umin - 1;
        f.base_v = vmin - 1;
        f.width = (vmax - vmin + 3) as u32;
        f.rows = (umax - umin + 2) as u32;
        let frame = *f;
        for k in &mut self.keys {
            if *k != u32::MAX {
                let cu = (*k >> 16) as i32 - 32_768;
                let cv = (*k & 0xFFFF) as i32 - 32_768;
                *k = frame.key(cu, cv).unwrap_or(u32::MAX - 1);
            }
        }
        large
    }

    /// Dense column keys in use (rows × width).
    fn dense_columns(&self) -> usize {
        (self.frame.rows as usize + 1) * self.frame.width as usize
    }

    /// Stable counting sort of the entries by dense key (large ones last), moving the boxes
    /// with scattered stores while reading them in order.
    fn counting_sort(&mut self, large: usize) {
        let n = self.slots.len();
        let buckets = self.dense_columns() + 1;
        self.counts.clear();
        self.counts.resize(buckets + 1, 0);
        for &k in &self.keys {
            let b = if k == u32::MAX {
                buckets - 1
            } else {
                k as usize
            };
            self.counts[b + 1] += 1;
        }
        for i in 1..self.counts.len() {
            self.counts[i] += self.counts[i - 1];
        }
        debug_assert_eq!(self.counts[buckets] as usize, n);
        debug_assert_eq!(
            (self.counts[buckets] - self.counts[buckets - 1]) as usize,
            large
        );
        self.next_boxes.resize(n, SimdBox::EMPTY);
        self.next_slots.resize(n, 0);
        for i in 0..n {
            let k = self.keys[i];
            let b = if k == u32::MAX {
                buckets - 1
            } else {
                k as usize
            };
            let to = self.counts[b] as usize;
            self.counts[b] += 1;
            self.next_boxes[to] = self.boxes[i];
            self.next_slots[to] = self.slots[i];
        }
        // `counts[b]` now ends bucket `b`; keys sorted alongside for the column table.
        self.swap_in();
        self.keys_sorted_from_counts(buckets);
    }

    /// After a counting sort: rewrites `keys` in sorted order from the bucket ends.
    fn keys_sorted_from_counts(&mut self, buckets: usize) {
        let n = self.slots.len();
        self.keys.clear();
        self.keys.resize(n, u32::MAX);
        let mut start = 0usize;
        for b in 0..buckets {
            let end = self.counts[b] as usize;
            let key = if b == buckets - 1 { u32::MAX } else { b as u32 };
            self.keys[start..end].fill(key);
            start = end;
        }
    }

    /// The same order by a comparison sort, for sparse worlds whose dense table would be far
    /// larger than the entries.
    fn comparison_sort(&mut self) {
        let n = self.slots.len();
        self.order.clear();
        self.order
            .extend(self.keys.iter().enumerate().map(|(i, &k)| (k, i as u32)));
        self.order.sort_unstable();
        self.next_boxes.resize(n, SimdBox::EMPTY);
        self.next_slots.resize(n, 0);
        for (to, &(_, from)) in self.order.iter().enumerate() {
            self.next_boxes[to] = self.boxes[from as usize];
            self.next_slots[to] = self.slots[from as usize];
        }
        self.swap_in();
        self.keys.clear();
        self.keys.extend(self.order.iter().map(|&(k, _)| k));
    }

    fn swap_in(&mut self) {
        core::mem::swap(&mut self.boxes, &mut self.next_boxes);
        core::mem::swap(&mut self.slots, &mut self.next_slots);
    }

    /// Sorts each column (and the large list) by `min[A]`, builds the column table and the
    /// reach.
    fn finish<const A: usize>(&mut self) {
        self.cols.clear();
        self.col_start.clear();
        let mut reach = 0.0f64;
        let mut i = 0;
        while i < self.normal {
            let key = self.keys[i];
            let mut end = i + 1;
            while end < self.normal && self.keys[end] == key {
                end += 1;
            }
            self.insertion_sort::<A>(i, end);
            for b in &self.boxes[i..end] {
                reach = reach.max(extent_up(b, A));
            }
            self.cols.push(key);
            self.col_start.push(i as u32);
            i = end;
        }
        self.col_start.push(self.normal as u32);
        let (normal, sorted) = (self.normal, self.sorted);
        self.insertion_sort_or_sort::<A>(normal, sorted);
        self.reach = reach;
        self.large_reach = self.boxes[normal..sorted]
            .iter()
            .map(|b| extent_up(b, A))
            .fold(0.0, f64::max);
        self.mins.clear();
        self.mins.extend(self.boxes.iter().map(|b| b.min[A]));
    }

    /// Insertion sort of `[lo, hi)` by `min[A]`: linear on the nearly sorted columns.
    fn insertion_sort<const A: usize>(&mut self, lo: usize, hi: usize) {
        for i in lo + 1..hi {
            let (b, s) = (self.boxes[i], self.slots[i]);
            let mut j = i;
            while j > lo && self.boxes[j - 1].min[A] > b.min[A] {
                self.boxes[j] = self.boxes[j - 1];
                self.slots[j] = self.slots[j - 1];
                j -= 1;
            }
            self.boxes[j] = b;
            self.slots[j] = s;
        }
    }

    /// The large list's sort: few entries, but in no guaranteed order.
    fn insertion_sort_or_sort<const A: usize>(&mut self, lo: usize, hi: usize) {
        if hi - lo <= 32 {
            self.insertion_sort::<A>(lo, hi);
            return;
        }
        self.order.clear();
        self.order.extend((lo..hi).map(|i| (0, i as u32)));
        let boxes = &self.boxes;
        self.order
            .sort_by(|p, q| boxes[p.1 as usize].min[A].total_cmp(&boxes[q.1 as usize].min[A]));
        self.next_boxes.clear();
        self.next_slots.clear();
        for &(_, i) in &self.order {
            self.next_boxes.push(self.boxes[i as usize]);
            self.next_slots.push(self.slots[i as usize]);
        }
        self.boxes[lo..hi].copy_from_slice(&self.next_boxes);
        self.slots[lo..hi].copy_from_slice(&self.next_slots);
    }

    /// Calls `f(slot_word, slot_word)` for every overlapping pair of built entries (the grid
    /// must have no appended entries and no changed box since [`Grid::build`]), each once.
    pub(super) fn for_each_pair(&self, f: impl FnMut(u32, u32)) {
        debug_assert_eq!(self.sorted, self.slots.len(), "build before pairing");
        match self.frame.axis {
            0 => self.pairs::<0>(f),
            1 => self.pairs::<1>(f),
            _ => self.pairs::<2>(f),
        }
    }

    fn pairs<const A: usize>(&self, mut f: impl FnMut(u32, u32)) {
        let width = self.frame.width;
        let mut up = 0; // first column of the row above not yet passed
        for (c, &key) in self.cols.iter().enumerate() {
            let own = self.column_range(c);
            let mine = &self.boxes[own.clone()];
            let words = &self.slots[own.clone()];
            sweep::self_pairs::<A>(mine, |i, j| f(words[i], words[j]));
            let mut cross = |other: usize| {
                let range = self.column_range(other);
                let theirs = &self.boxes[range.clone()];
                let their_words = &self.slots[range];
                sweep::cross_pairs::<A>(mine, theirs, |i, j| f(words[i], their_words[j]));
            };
            if self.cols.get(c + 1) == Some(&(key + 1)) {
                cross(c + 1);
            }
            let first = key + width - 1;
            while up < self.cols.len() && self.cols[up] < first {
                up += 1;
            }
            // Columns are sorted and distinct, so `first + d` can only sit at `up + d` or
            // before: the three targets are among the next three columns.
            for target in first..first + 3 {
                if let Some(at) = self.find_from(up, target) {
                    cross(at);
                }
            }
        }
        self.large_pairs::<A>(&mut f);
    }

    /// The index of column `key` at or after `from` within three places, if present.
    #[inline]
    fn find_from(&self, from: usize, key: u32) -> Option<usize> {
        (from..(from + 3).min(self.cols.len())).find(|&i| self.cols[i] == key)
    }

    #[inline]
    fn column_range(&self, c: usize) -> core::ops::Range<usize> {
        self.col_start[c] as usize..self.col_start[c + 1] as usize
    }

    /// Large × large by the sweep, and each large entry against the columns it reaches.
    fn large_pairs<const A: usize>(&self, f: &mut impl FnMut(u32, u32)) {
        let large = self.normal..self.sorted;
        let boxes = &self.boxes[large.clone()];
        let words = &self.slots[large];
        sweep::self_pairs::<A>(boxes, |i, j| f(words[i], words[j]));
        for (b, &w) in boxes.iter().zip(words) {
            self.visit_columns::<A>(b, |i| f(w, self.slots[i]));
        }
    }

    /// Calls `f(entry)` for every normal entry whose box overlaps `q`.
    fn visit_columns<const A: usize>(&self, q: &SimdBox, mut f: impl FnMut(usize)) {
        if self.cols.is_empty() {
            return;
        }
        let ((u0, u1), (v0, v1)) = self.frame.reach_of(q);
        let f0 = &self.frame;
        // Clamp to the occupied rows and row width so that far queries cost nothing extra.
        let u0 = u0.max(f0.base_u);
        let u1 = u1.min(f0.base_u.saturating_add(f0.rows as i32));
        let v0 = v0.max(f0.base_v);
        let v1 = v1.min(f0.base_v.saturating_add(f0.width as i32 - 1));
        if u0 > u1 || v0 > v1 {
            return;
        }
        let start = start_down(q.min[A], self.reach);
        for cu in u0..=u1 {
            let (Some(lo), Some(hi)) = (f0.key(cu, v0), f0.key(cu, v1)) else {
                continue;
            };
            let mut c = if self.col_of.is_empty() {
                self.cols.partition_point(|&k| k < lo)
            } else {
                // The first occupied column at or after `lo` in this row, if any.
                match (lo..=hi).find_map(|k| {
                    let c = self.col_of[k as usize];
                    (c != u32::MAX).then_some(c as usize)
                }) {
                    Some(c) => c,
                    None => continue,
                }
            };
            while c < self.cols.len() && self.cols[c] <= hi {
                let range = self.column_range(c);
                let mins = &self.mins[range.clone()];
                let first = range.start + mins.partition_point(|&m| f64::from(m) < start);
                for i in first..range.end {
                    if self.mins[i] > q.max[A] {
                        break;
                    }
                    if self.boxes[i].overlaps(q) {
                        f(i);
                    }
                }
                c += 1;
            }
        }
    }

    /// Calls `f(slot_word)` for every built entry (normal or large) whose box overlaps `q`:
    /// the caller filters dirty entries, and tests appended ones itself.
    pub(super) fn query(&self, q: &SimdBox, mut f: impl FnMut(u32)) {
        match self.frame.axis {
            0 => self.visit_columns::<0>(q, |i| live(self.slots[i], &mut f)),
            1 => self.visit_columns::<1>(q, |i| live(self.slots[i], &mut f)),
            _ => self.visit_columns::<2>(q, |i| live(self.slots[i], &mut f)),
        }
        // The large list is sorted by `min[A]`: only entries starting after `q.min[A]` minus
        // the longest of them, and before `q.max[A]`, can overlap.
        let large = &self.mins[self.normal..self.sorted];
        let start = start_down(q.min[self.frame.axis], self.large_reach);
        let first = self.normal + large.partition_point(|&m| f64::from(m) < start);
        for i in first..self.sorted {
            if self.mins[i] > q.max[self.frame.axis] {
                break;
            }
            if self.boxes[i].overlaps(q) {
                live(self.slots[i], &mut f);
            }
        }
    }

    /// Grows every buffer ahead of `n` entries (to half again as many) when it is close to
    /// full, so that a grid refilled every step stops allocating once it has seen its peak.
    pub(super) fn reserve_ahead(&mut self, n: usize) {
        if self.boxes.capacity() >= n + n / 4 {
            return;
        }
        let want = n + n / 2;
        self.boxes.reserve(want.saturating_sub(self.boxes.len()));
        self.slots.reserve(want.saturating_sub(self.slots.len()));
        self.mins.reserve(want.saturating_sub(self.mins.len()));
        self.keys.reserve(want.saturating_sub(self.keys.len()));
        self.next_boxes
            .reserve(want.saturating_sub(self.next_boxes.len()));
        self.next_slots
            .reserve(want.saturating_sub(self.next_slots.len()));
        self.order.reserve(want.saturating_sub(self.order.len()));
        self.cols.reserve(want.saturating_sub(self.cols.len()));
        self.col_start
            .reserve((want + 1).saturating_sub(self.col_start.len()));
    }

    /// Forgets every entry (keeps the buffers).
    pub(super) fn clear(&mut self) {
        self.boxes.clear();
        self.slots.clear();
        self.mins.clear();
        self.cols.clear();
        self.col_start.clear();
        self.col_of.clear();
        self.normal = 0;
        self.sorted = 0;
    }

    /// Calls `visit(slot_word)` for built entries whose box the ray may hit, in roughly
    /// increasing distance (an entry may be visited more than once); `visit` returns the
    /// closest hit so far, and the walk stops once nothing nearer can follow.
    ///
    /// The ray is cut into pieces of at most one cell on every axis, and each piece's box
    /// queries the columns like any box query (with the same widening), so no column the ray
    /// passes is missed at a cell boundary.
    pub(super) fn ray_candidates(
        &self,
        origin: Vec3A,
        dir: Vec3A,
        max_t: f32,
        mut visit: impl FnMut(u32) -> f32,
    ) {
        let mut best = max_t;
        for i in self.normal..self.sorted {
            if self.slots[i] != DEAD && ray_box(origin, dir, &self.boxes[i], best).is_some() {
                best = best.min(visit(self.slots[i]));
            }
        }
        let Some((t0, t1)) = self.clip_ray(origin, dir, max_t) else {
            return;
        };
        let dt = self.frame.cell / dir.abs().max_element();
        let mut k = 0u32;
        loop {
            let ta = t0 + dt * k as f32;
            if ta.partial_cmp(&t1.min(best)).is_none_or(|o| o.is_gt()) {
                break;
            }
            let tb = (t0 + dt * (k + 1) as f32).min(t1).min(best);
            let (p0, p1) = (origin + dir * ta, origin + dir * tb);
            let slack = Vec3A::splat(RAY_SLACK) * p0.abs().max(p1.abs()).max(Vec3A::ONE);
            let piece = SimdBox {
                min: p0.min(p1) - slack,
                max: p0.max(p1) + slack,
            };
            let mut test = |i: usize| {
                if self.slots[i] != DEAD && ray_box(origin, dir, &self.boxes[i], best).is_some() {
                    best = best.min(visit(self.slots[i]));
                }
            };
            match self.frame.axis {
                0 => self.visit_columns::<0>(&piece, &mut test),
                1 => self.visit_columns::<1>(&piece, &mut test),
                _ => self.visit_columns::<2>(&piece, &mut test),
            }
            if tb >= t1 || k == u32::MAX {
                break;
            }
            k += 1;
        }
    }

    /// The parameter range in which the ray is over the occupied columns (two cells of slack
    /// on each side: boxes reach a cell past their column), or `None` if it never is.
    fn clip_ray(&self, origin: Vec3A, dir: Vec3A, max_t: f32) -> Option<(f32, f32)> {
        if self.cols.is_empty() {
            return None;
        }
        let fr = &self.frame;
        let (u, v) = fr.uv();
        let (mut t0, mut t1) = (0.0f32, max_t);
        for (a, o, base, span) in [
            (u, fr.origin_u, fr.base_u, fr.rows),
            (v, fr.origin_v, fr.base_v, fr.width),
        ] {
            let lo = o + (base as f32 - 2.0) * fr.cell;
            let hi = o + (base as f32 + span as f32 + 2.0) * fr.cell;
            if dir[a] == 0.0 {
                if !(lo..=hi).contains(&origin[a]) {
                    return None;
                }
            } else {
                let (a0, a1) = ((lo - origin[a]) / dir[a], (hi - origin[a]) / dir[a]);
                t0 = t0.max(a0.min(a1));
                t1 = t1.min(a0.max(a1));
            }
        }
        (t0 <= t1).then_some((t0, t1))
    }

    /// Checks the built part: columns sorted and disjoint, entries in the column their box
    /// names and sorted by `min[A]` within it, large entries that do not fit. Panics on the
    /// first broken rule; `still` says whether entry `i` is expected unchanged since the build.
    pub(super) fn validate(&self, still: impl Fn(usize) -> bool) {
        assert_eq!(self.boxes.len(), self.slots.len());
        assert!(self.normal <= self.sorted && self.sorted <= self.slots.len());
        assert!(
            self.cols.windows(2).all(|w| w[0] < w[1]),
            "columns unsorted"
        );
        let built = !self.col_start.is_empty();
        assert_eq!(self.col_start.len(), self.cols.len() + usize::from(built));
        let a = self.frame.axis;
        for c in 0..self.cols.len() {
            let range = self.column_range(c);
            assert!(!range.is_empty(), "empty column");
            for i in range.clone() {
                if !still(i) {
                    continue;
                }
                let (cu, cv) = self
                    .frame
                    .column(&self.boxes[i])
                    .expect("large box in a column");
                assert_eq!(
                    self.frame.key(cu, cv),
                    Some(self.cols[c]),
                    "entry {i} misfiled"
                );
                assert!(
                    f64::from(self.boxes[i].max[a]) - f64::from(self.boxes[i].min[a]) <= self.reach
                );
            }
            let mins = &self.mins[range];
            assert!(mins.windows(2).all(|w| w[0] <= w[1]), "column {c} unsorted");
        }
        for i in 0..self.sorted {
            if still(i) {
                assert_eq!(
                    self.mins[i], self.boxes[i].min[a],
                    "entry {i} moved but is not dirty"
                );
            }
        }
        for i in self.normal..self.sorted {
            if still(i) {
                assert!(
                    self.frame.column(&self.boxes[i]).is_none(),
                    "a fitting box in the large list"
                );
            }
        }
        assert_eq!(*self.col_start.last().unwrap_or(&0) as usize, self.normal);
    }
}

/// Calls `f(word)` unless the entry was removed: a removed entry's box is empty (`+∞..−∞`),
/// which a box reaching infinity on an axis would still "overlap" there.
#[inline]
fn live(word: u32, f: &mut impl FnMut(u32)) {
    if word != DEAD {
        f(word);
    }
}

/// `max − min` of `b` on `axis`, rounded up: an upper bound even where `f64` cannot hold the
/// difference of two far-apart `f32`s exactly.
#[inline]
fn extent_up(b: &SimdBox, axis: usize) -> f64 {
    (f64::from(b.max[axis]) - f64::from(b.min[axis])).next_up()
}

/// `min − reach` rounded down: no box of extent at most `reach` that starts before it can
/// reach `min`.
#[inline]
fn start_down(min: f32, reach: f64) -> f64 {
    (f64::from(min) - reach).next_down()
}

/// The ray's entry parameter into `b` if it hits it within `[0, max_t]` (slab test; `dir`
/// lanes may be zero).
#[inline]
pub(super) fn ray_box(origin: Vec3A, dir: Vec3A, b: &SimdBox, max_t: f32) -> Option<f32> {
    let inv = dir.recip();
    let t0 = (b.min - origin) * inv;
    let t1 = (b.max - origin) * inv;
    // 0 · ∞ is NaN where the ray lies on a face plane: it must not decide the test.
    let near = t0.min(t1);
    let far = t0.max(t1);
    let mut lo = 0.0f32;
    let mut hi = max_t;
    for a in 0..3 {
        if dir[a] == 0.0 {
            if origin[a] < b.min[a] || origin[a] > b.max[a] {
                return None;
            }
        } else {
            lo = lo.max(near[a]);
            hi = hi.min(far[a]);
        }
    }
    (lo <= hi).then_some(lo)
}
