//! One step: the passes.
//!
//! The two passes and the incremental regime are defined on
//! [`BroadPhase`](super::BroadPhase#the-passes-and-the-incremental-regime); [`super::cost`]
//! picks one each step. This file runs them: the full pass over the structures, the
//! incremental pass's queries of the escaped proxies (its scan is [`super::slack`]'s), and the
//! pair list's sort and diff.
//!
//! **Threads** (feature `parallel`). With more than one thread in rayon's current pool and at
//! least [`PARALLEL_MIN_SPHERES`] spheres or [`PARALLEL_MIN_BODIES`] dynamic bodies, the step
//! (outside the incremental regime; inside it, a full pass) runs as one job on the pool, the
//! full pass split in [`TASKS_PER_THREAD`] tasks per thread at each
//! phase: the octree sorts its walk order by a radix scatter whose tasks take ranges of its
//! records, and passes its runs in chunks
//! (each with its own pass state), the BVH passes hand their descents' items to as many tasks
//! (each with its own stack), and one task runs the sphere × body queries; every producer cuts its pairs into
//! the parts of the pair sort as it finds them (at the quantiles of the last step's pairs),
//! each part is sorted by its own task, and the event diff is split the same way. Each pair is
//! found by one producer, once, and every part covers a key range, so the lists are the
//! serial pass's at any thread count. What stays serial: the octree's relinks (one task,
//! beside the walk-order sort) and the body leaves of the updates' apply,
//! the refits, the sphere × body queries (one task), and the incremental
//! pass.

use super::packed::{
    HIT, key_pair, keys_into, null_pair, pack_allowed, pack_pair, sort_scratch, unpack,
};
use super::*;
#[cfg(feature = "parallel")]
use crate::radix;
use crate::radix::{PairBits, ahead, grow_to, sort_u64_kept};

/// A full pass splits over rayon's current pool only with at least this many spheres or
/// [`PARALLEL_MIN_BODIES`] dynamic bodies (and more than one thread): below this many spheres
/// handing out the octree's chunks costs about what the second thread saves.
#[cfg(feature = "parallel")]
pub(super) const PARALLEL_MIN_SPHERES: usize = 10_000;
/// The dynamic bodies from which a full pass splits over the pool whatever the spheres: a
/// body costs the pass several times what a sphere does, so fewer of them pay for the split.
/// Below it the BVH pass is short enough that a worker asleep since the last step wakes up
/// when the pass is nearly over, and the split's own work makes two threads slower than one.
#[cfg(feature = "parallel")]
const PARALLEL_MIN_BODIES: usize = 16_384;
/// Pairs per part of the parallel pair sort and event diff, at least: a part's fixed costs
/// (the sort's counters, handing out the task) outweigh the split below it.
#[cfg(feature = "parallel")]
const MIN_PART_PAIRS: usize = 4096;
/// Tasks per thread in each split phase of a parallel pass and of the parallel apply, so that
/// a thread that finishes its share early takes over part of a slower one's.
#[cfg(feature = "parallel")]
pub(super) const TASKS_PER_THREAD: usize = 4;
/// The most tasks of one phase: the pair sort keeps a list per producer and part, so their
/// number grows with its square.
#[cfg(feature = "parallel")]
const MAX_TASKS: usize = 64;

/// Buffers of the parallel full pass (feature `parallel`), reused by every pass; they never
/// shrink.
#[cfg(feature = "parallel")]
#[derive(Clone, Debug, Default)]
pub(super) struct Parallel {
    /// The first keys of the pair sort's parts (see [`radix::split_points`]).
    splitters: Vec<u64>,
    /// Pairs found, packed, per producer with their parts of the sort: one producer per chunk of
    /// the octree's pass, one per task of the BVH passes, then the sphere × body queries.
    found: Vec<radix::Parted>,
    /// The split BVH passes' items and per-task stacks.
    split: crate::bvh::SplitScratch,
    /// The pair sort's parts' bounds (its second buffer is the serial sort's, see
    /// [`sort_scratch`]), and the table of its producers' stretches.
    sort_bounds: Vec<usize>,
    stretches: radix::Stretches,
    /// Per part of the event diff: its `added` and `removed`.
    diff: Vec<[Vec<u64>; 2]>,
    /// The diff's parts' first positions in the current and the previous pair lists.
    cur_at: Vec<usize>,
    prev_at: Vec<usize>,
    /// Per task of the parallel apply: the spheres it moved to another node.
    pub(super) moves: Vec<crate::octree::Moves>,
}

#[cfg(feature = "parallel")]
impl Parallel {
    /// Heap bytes held (capacities).
    pub(super) fn heap_bytes(&self) -> usize {
        let lists = |v: &[Vec<u64>]| v.iter().map(Vec::capacity).sum::<usize>();
        (self.splitters.capacity()
            + self.sort_bounds.capacity()
            + self.diff.iter().map(|d| lists(d)).sum::<usize>()
            + self.cur_at.capacity()
            + self.prev_at.capacity())
            * 8
            + self.split.heap_bytes()
            + self
                .found
                .iter()
                .map(radix::Parted::heap_bytes)
                .sum::<usize>()
            + self.stretches.heap_bytes()
            + self
                .moves
                .iter()
                .map(crate::octree::Moves::heap_bytes)
                .sum::<usize>()
    }
}

#[cfg(feature = "parallel")]
impl Parallel {
    /// Applies `trim` (the broadphase's event-list policy) to the lists a burst of pairs
    /// leaves oversized: the producers' and the diff's parts.
    pub(super) fn trim(&mut self, trim: fn(&mut Vec<u64>, usize)) {
        for producer in &mut self.found {
            producer.trim(trim);
        }
        for list in self.diff.iter_mut().flatten() {
            trim(list, 0);
        }
    }
}

/// The incremental pass's patch lists keep room for at least one entry per this many
/// proxies: their lengths follow the escapes and the pairs that change, which swing.
const PATCH_FLOOR: usize = 32;

/// An incremental step refits the dynamic BVH once this fraction of its bodies got new fat
/// boxes since its last refit: until then the boxes grown on update keep it exact, only
/// looser.
const REFIT_FRACTION: f64 = 0.125;

impl BroadPhase {
    /// Runs `pass`, then clears the step's marks.
    pub(super) fn run(&mut self, pass: Pass) {
        let updated = self.movers.len() + self.removals + core::mem::take(&mut self.nudged);
        self.nudge_from = 0;
        let escaped = self.escaped.len();
        self.stats = StepStats {
            pass,
            updated,
            escaped: if self.regime.is_some() { escaped } else { 0 },
            ..StepStats::default()
        };
        match pass {
            Pass::Unchanged => {
                self.added.clear();
                self.removed.clear();
            }
            Pass::Full => self.full(false),
            Pass::FullFat => self.full(true),
            Pass::Incremental => self.incremental_pass(),
        }
        self.costs.pairs_seen |= pass != Pass::Unchanged;
        self.stats.pairs = self.pairs.len();
        self.stats.octree_per_level = self.octree.stats().per_level;
        let (d, st) = (self.dynamic.refit_stats(), self.statics.refit_stats());
        self.stats.dynamic_cost_ratio = d.0;
        self.stats.dynamic_rebuilds = d.1;
        self.stats.static_rebuilds = st.1;
        self.stats.candidates = self.regime.as_ref().map_or(0, |r| r.cand.len());
        let mut removed_movers = 0;
        for &s in &self.movers {
            let f = &mut self.store.flags[s as usize];
            // A proxy updated and then removed counts once in `updated`, as removed.
            removed_movers += usize::from(*f & flag::GONE != 0);
            *f &= !(flag::MOVED | flag::ESCAPED);
        }
        self.stats.updated -= removed_movers;
        for &s in &self.loud {
            self.store.flags[s as usize] &= !flag::LOUD;
        }
        self.loud.clear();
        self.movers.clear();
        if self.regime.is_none() {
            // Outside the incremental regime only inserts and regroups are listed as escaped:
            // the list gives back the room a burst of inserts (the first step's) left far
            // above that. Inside it the escapes swing from step to step, and it keeps its room.
            super::trim(&mut self.escaped, self.store.len() / 8);
        }
        self.escaped.clear();
        self.removals = 0;
        self.motion = super::fat::Motion::default();
        self.store.release_quarantine();
        self.keep_headroom();
    }

    /// Grows the lists whose length swings from step to step ahead of their peaks, so that a
    /// world in steady state stops allocating after its first few swings.
    fn keep_headroom(&mut self) {
        ahead(&mut self.fresh);
        self.pairs.ahead();
        let n = self.store.len();
        let mut cands = 0;
        if let Some(r) = &mut self.regime {
            r.cand.ahead();
            ahead(&mut self.loud);
            ahead(&mut self.pending);
            r.patch.keep_headroom(n / PATCH_FLOOR);
            cands = r.cand.len();
        }
        // A full pass finds every pair (or candidate) into `fresh` and sorts it there, diffs
        // the key pairs against it and refills them from it; the incremental steps fill
        // `fresh` only with the escaped proxies' new candidates and patch the key pairs in
        // place. `fresh` stays ready for the largest list a full pass can make. It is also the
        // octree's walk-order sort's second buffer (`Octree::prepare_pass`), and the pair
        // sort's second buffer may be the octree's walk order: each is sized exactly for the
        // spheres when they grow, so both are kept half again ahead of the pairs, and a pair
        // count near the sphere count does not cross the growth threshold at some later step.
        let most = cands.max(self.pairs.len());
        let scratch = sort_scratch(&mut self.octree, &mut self.sort_buf);
        for v in [&mut self.fresh, scratch] {
            if v.capacity() < most + most / 2 {
                grow_to(v, most + most * 3 / 4);
            }
        }
        for v in [&mut self.added_packed, &mut self.removed_packed] {
            grow_to(v, n / 8);
        }
        for v in [&mut self.added, &mut self.removed] {
            grow_to(v, n / 8);
        }
    }

    /// The full pass: the structures' pair passes over the boxes they hold. With `fat`, every
    /// proxy is first given a fat box and the pairs found are the new candidate list; without,
    /// the structures first hold the exact boxes again if they held fat ones.
    fn full(&mut self, fat: bool) {
        match self.tasks() {
            // Run on the pool's threads as one job: a caller outside the pool hands the pass
            // over once, instead of once per split phase (each hand-over wakes a worker and
            // then the caller, and queues a job, whose queue allocates now and then).
            #[cfg(feature = "parallel")]
            tasks @ 2.. => rayon::scope(|_| self.full_in(fat, tasks)),
            _ => self.full_in(fat, 1),
        }
    }

    /// [`BroadPhase::full`] with its split phases in `tasks` tasks each (1: serial). The
    /// previous step's pairs are the key pairs, read packed (see [`pack_pair`]) until the new
    /// sorted list in `fresh` replaces them.
    #[inline(always)]
    fn full_in(&mut self, fat: bool, tasks: usize) {
        // Entering or staying in the regime gives every proxy a new fat box; leaving it gives
        // every proxy its exact box again.
        let hold_all = fat || self.regime.is_some();
        match (fat, self.regime.is_some()) {
            (true, false) => self.enter_regime(),
            (false, true) => {
                self.leave_regime();
                self.costs.over = false;
            }
            _ => {}
        }
        if hold_all {
            for s in 0..self.store.slots() as u32 {
                if self.store.kind[s as usize] != Kind::Free {
                    self.hold(s);
                }
            }
        }
        self.refit(true);
        match tasks {
            #[cfg(feature = "parallel")]
            2.. => {
                self.stats.split_tasks = tasks;
                self.sorted_pairs_par(tasks, PairBits::for_slots(self.store.slots()));
            }
            _ => {
                self.fresh.clear();
                self.structure_pairs();
                self.sort_fresh();
            }
        }
        if let Some(r) = &mut self.regime {
            // The candidates are copied out, and `fresh` keeps those whose exact boxes
            // overlap, in place and in order: the new pair list.
            let (exact, fresh) = (&r.exact, &mut self.fresh);
            let tested = fresh.len();
            r.cand.refill(tested, 0, |cand| {
                let mut hits = 0;
                for i in 0..fresh.len() {
                    let c = fresh[i];
                    let (a, b) = unpack(c);
                    let hit = exact[a].overlaps(&exact[b]);
                    cand.push(c | if hit { HIT } else { 0 });
                    fresh[hits] = c;
                    hits += usize::from(hit);
                }
                fresh.truncate(hits);
            });
            self.stats.candidates_tested = tested;
        }
        match tasks {
            #[cfg(feature = "parallel")]
            2.. if self.fresh.len() >= 2 * MIN_PART_PAIRS => {
                self.emit_par(tasks.min(self.fresh.len() / MIN_PART_PAIRS));
            }
            _ => self.emit(),
        }
        if fat {
            // Its scratch is `fresh`, free again now that the pairs are refilled.
            self.anchor_all();
        }
    }

    /// How many tasks each split phase of a full pass hands to rayon's current pool: 1 (the
    /// serial pass) without the feature `parallel`, on one thread, or with few spheres.
    #[cfg(feature = "parallel")]
    pub(super) fn tasks(&self) -> usize {
        let threads = rayon::current_num_threads();
        let small =
            self.octree.len() < PARALLEL_MIN_SPHERES && self.dynamic.len() < PARALLEL_MIN_BODIES;
        if threads < 2 || small {
            1
        } else {
            (threads * TASKS_PER_THREAD).min(MAX_TASKS)
        }
    }

    #[cfg(not(feature = "parallel"))]
    #[inline(always)]
    pub(super) fn tasks(&self) -> usize {
        1
    }

    /// Refits the trees whose held boxes changed: the static one always, the dynamic one
    /// with `all`, else once enough of its bodies got new fat boxes since its last refit.
    fn refit(&mut self, all: bool) {
        if self.statics_changed {
            self.statics.refit();
            self.statics_changed = false;
        }
        let due = self.dynamic_escapes as f64 > REFIT_FRACTION * self.dynamic.len() as f64;
        if self.dynamic_changed && (all || due) {
            self.dynamic.refit();
            self.dynamic_changed = false;
            self.dynamic_escapes = 0;
        }
    }

    /// Appends to `fresh` every pair of held boxes that overlap (never static × static) and
    /// whose groups allow it, packed, each once, unsorted.
    fn structure_pairs(&mut self) {
        // The octree's walk-order sort borrows `fresh`, which holds nothing until the pass.
        self.octree.prepare_pass(&mut self.fresh, 1);
        let (store, fresh, groups) = (&self.store, &mut self.fresh, self.any_groups);
        let mut push = |a: ProxyKey, b: ProxyKey| {
            let (a, b) = (crate::pair::slot(a), crate::pair::slot(b));
            if let Some(p) = pack_allowed(store, groups, a, b) {
                fresh.push(p);
            }
        };
        self.octree.for_each_pair(&mut push);
        self.dynamic.for_each_pair(&mut push);
        self.dynamic.for_each_pair_with(&self.statics, &mut push);
        sphere_body_pairs(&self.octree, &self.dynamic, &self.statics, &mut push);
    }

    /// [`BroadPhase::structure_pairs`] and the sort, over rayon's current pool in `tasks`
    /// tasks per split phase: the octree's pass in chunks, beside the BVH passes in as many
    /// tasks and one task for the sphere × body queries. Each producer cuts its pairs into the sort's
    /// parts as it finds them (at the quantiles of the last step's pairs, which the new ones
    /// resemble; one part if there were few), and each part is then sorted into `fresh` by its
    /// own task. `fresh` ends as the serial path leaves it.
    #[cfg(feature = "parallel")]
    fn sorted_pairs_par(&mut self, tasks: usize, layout: PairBits) {
        // The octree's walk-order sort borrows `fresh`, which holds nothing until the sort
        // of the pairs found fills it.
        self.octree.prepare_pass(&mut self.fresh, tasks);
        let par = &mut self.par;
        let parts = tasks.min(self.pairs.len() / MIN_PART_PAIRS).max(1);
        radix::split_points(&self.pairs, pack_pair, parts, &mut par.splitters);
        let parts = par.splitters.len() + 1;
        let producers = 2 * tasks + 1;
        if par.found.len() < producers {
            par.found.resize_with(producers, Default::default);
        }
        for found in &mut par.found[..producers] {
            found.reset(parts);
        }
        let (store, groups, splitters) = (&self.store, self.any_groups, &par.splitters[..]);
        let emit = |found: &mut radix::Parted, a: ProxyKey, b: ProxyKey| {
            let (a, b) = (crate::pair::slot(a), crate::pair::slot(b));
            if let Some(p) = pack_allowed(store, groups, a, b) {
                found.push(radix::part_of(splitters, p), p);
            }
        };
        let (chunks, rest) = par.found[..producers].split_at_mut(tasks);
        let (body_chunks, rest) = rest.split_at_mut(tasks);
        let spheres_bodies = &mut rest[0];
        let (dynamic, statics, split) = (&self.dynamic, &self.statics, &mut par.split);
        self.octree.for_each_pair_chunked(chunks, &emit, |octree| {
            rayon::join(
                || dynamic.for_each_pair_split(statics, split, body_chunks, &emit),
                || {
                    let mut push = |a, b| emit(spheres_bodies, a, b);
                    sphere_body_pairs(octree, dynamic, statics, &mut push);
                },
            );
        });
        let scratch = sort_scratch(&mut self.octree, &mut self.sort_buf);
        radix::sort_parts(
            &par.found[..producers],
            parts,
            &mut self.fresh,
            scratch,
            (&mut par.sort_bounds, &mut par.stretches),
            layout,
        );
        for found in &mut par.found[..producers] {
            found.ahead();
        }
    }

    /// The incremental pass (see the module docs and [`super::slack`]): the pair list and the
    /// key pairs are patched in place, so the previous step's are not kept.
    fn incremental_pass(&mut self) {
        self.refit(false);
        self.fresh.clear();
        self.query_escaped();
        self.sort_fresh();
        self.fresh.dedup();
        self.classify();
        self.update_candidates();
        let movers = self.movers.len().max(1) as f64;
        self.costs.loud_per_mover = (self.loud.len() as f64 / movers).min(1.0);
        let escaped = self.escaped.len();
        let slow = self.movers.len().saturating_sub(escaped).max(1) as f64;
        let slow_loud = self.loud.len().saturating_sub(escaped) as f64;
        self.costs.loud_per_slow = (slow_loud / slow).min(1.0);
    }

    /// New candidates of each escaped proxy: every held box its own overlaps, in the octree
    /// and both BVHs (a static proxy skips the static BVH), that its groups allow.
    fn query_escaped(&mut self) {
        let Some(r) = &self.regime else {
            return;
        };
        let (store, fresh, groups) = (&self.store, &mut self.fresh, self.any_groups);
        for &e in &self.escaped {
            let es = e as usize;
            if store.flags[es] & flag::GONE != 0 {
                continue;
            }
            let held = r.held[es].aabb();
            let mut push = |k: ProxyKey| {
                let s = crate::pair::slot(k);
                if s != e
                    && let Some(p) = pack_allowed(store, groups, e, s)
                {
                    fresh.push(p);
                }
            };
            self.octree.query_aabb_unchecked(&held, &mut push);
            self.dynamic.query_aabb_unchecked(&held, &mut push);
            if store.kind[es] != Kind::Static {
                self.statics.query_aabb_unchecked(&held, &mut push);
            }
        }
    }

    /// Sorts `fresh` (packed pairs) in place, with the pair sorts' second buffer
    /// ([`sort_scratch`]).
    pub(super) fn sort_fresh(&mut self) {
        let layout = PairBits::for_slots(self.store.slots());
        let scratch = sort_scratch(&mut self.octree, &mut self.sort_buf);
        sort_u64_kept(&mut self.fresh, scratch, layout);
    }

    /// [`BroadPhase::emit`] over rayon's current pool: the current list is cut into `parts`
    /// stretches of equal length (`parts` at most its length), the previous one at the same
    /// keys, each pair of stretches diffed by its own task; the parts' events are then joined
    /// in order, and the key lists mapped in parallel. The lists are the serial ones.
    #[cfg(feature = "parallel")]
    fn emit_par(&mut self, parts: usize) {
        use rayon::prelude::*;
        let (prev, cur, par) = (&*self.pairs, &self.fresh, &mut self.par);
        par.cur_at.clear();
        par.prev_at.clear();
        for p in 0..parts {
            let at = cur.len() * p / parts;
            par.cur_at.push(at);
            par.prev_at.push(if p == 0 {
                0
            } else {
                prev.partition_point(|x| pack_pair(x) < cur[at])
            });
        }
        par.cur_at.push(cur.len());
        par.prev_at.push(prev.len());
        if par.diff.len() < parts {
            par.diff.resize_with(parts, Default::default);
        }
        let (cur_at, prev_at) = (&par.cur_at, &par.prev_at);
        par.diff[..parts]
            .par_iter_mut()
            .enumerate()
            .for_each(|(p, [added, removed])| {
                crate::pair::diff_mapped(
                    &prev[prev_at[p]..prev_at[p + 1]],
                    pack_pair,
                    &cur[cur_at[p]..cur_at[p + 1]],
                    added,
                    removed,
                );
            });
        self.added_packed.clear();
        self.removed_packed.clear();
        for [added, removed] in &mut par.diff[..parts] {
            self.added_packed.extend_from_slice(added);
            self.removed_packed.extend_from_slice(removed);
            ahead(added);
            ahead(removed);
        }
        let store = &self.store;
        let to_pair = |&p: &u64| key_pair(store, p);
        let fresh = &self.fresh;
        self.pairs.refill(fresh.len(), null_pair(), |pairs| {
            pairs.par_extend(fresh.par_iter().map(to_pair));
        });
        super::packed::keys_into_par(store, &self.added_packed, &mut self.added);
        super::packed::keys_into_par(store, &self.removed_packed, &mut self.removed);
    }

    /// `added` / `removed` from the previous step's key pairs (read packed) and this step's
    /// sorted packed pairs in `fresh`, then the three key lists.
    fn emit(&mut self) {
        crate::pair::diff_mapped(
            &self.pairs,
            pack_pair,
            &self.fresh,
            &mut self.added_packed,
            &mut self.removed_packed,
        );
        let store = &self.store;
        let to_pair = |&p: &u64| key_pair(store, p);
        let fresh = &self.fresh;
        self.pairs.refill(fresh.len(), null_pair(), |pairs| {
            pairs.extend(fresh.iter().map(to_pair));
        });
        keys_into(store, &self.added_packed, &mut self.added);
        keys_into(store, &self.removed_packed, &mut self.removed);
    }
}

/// Calls `push(a, b)` for every sphere of `octree` and body of `dynamic` or `statics` whose
/// held boxes overlap: the smaller side queries the other side's structure.
fn sphere_body_pairs(
    octree: &Octree,
    dynamic: &Bvh,
    statics: &Bvh,
    push: &mut impl FnMut(ProxyKey, ProxyKey),
) {
    let bodies = dynamic.len() + statics.len();
    if bodies == 0 || octree.is_empty() {
        return;
    }
    if bodies <= octree.len() {
        for tree in [dynamic, statics] {
            tree.for_each(|body, aabb| {
                octree.query_aabb_unchecked(&aabb, |sphere| push(body, sphere));
            });
        }
    } else {
        octree.for_each(|sphere, aabb| {
            dynamic.query_aabb_unchecked(&aabb, |body| push(sphere, body));
            statics.query_aabb_unchecked(&aabb, |body| push(sphere, body));
        });
    }
}

#[cfg(test)]
mod tests {
    use crate::broadphase::{BodyKind, BroadPhase, Config};
    use crate::brute::{self, Proxy};
    use crate::{Aabb, Vec3};

    /// While the octree holds spheres the pair sorts borrow its idle buffer, and the
    /// broadphase's own second buffer stays unallocated; the octree's walk-order sort borrows
    /// `fresh` in turn, so the octree keeps no second buffer of its own. Once the spheres are
    /// gone the pairs of the bodies are sorted with the broadphase's own. Pairs equal brute
    /// force throughout.
    #[test]
    fn the_pair_sort_borrows_the_octrees_buffer_while_it_holds_spheres() {
        let mut bp = BroadPhase::new(Config::default());
        let at = |i: usize| Vec3::new((i % 30) as f32, ((i / 30) % 30) as f32, (i / 900) as f32);
        let mut spheres: Vec<_> = (0..2700)
            .map(|i| (bp.insert_sphere(at(i) * 0.9, 0.5).unwrap(), at(i) * 0.9))
            .collect();
        let bodies: Vec<_> = (0..300)
            .map(|i| {
                let c = at(i) * 0.9 + Vec3::splat(0.3);
                let b = Aabb::new(c, c + Vec3::splat(1.0));
                (bp.insert_body(b, BodyKind::Dynamic).unwrap(), b)
            })
            .collect();
        let expect = |spheres: &[(crate::ProxyKey, Vec3)]| {
            let mut all: Vec<Proxy> = spheres
                .iter()
                .map(|&(k, c)| Proxy::new(k, Aabb::from_center_radius(c, 0.5)))
                .collect();
            all.extend(bodies.iter().map(|&(k, b)| Proxy::new(k, b)));
            brute::pairs(&all)
        };
        for step in 0..4 {
            for (i, (k, c)) in spheres.iter_mut().enumerate() {
                *c = at(i) * 0.9 + Vec3::splat(0.01 * ((i + step) % 3) as f32);
                bp.update_sphere(*k, *c, 0.5).unwrap();
            }
            bp.step();
            bp.validate();
            assert_eq!(bp.pairs(), &expect(&spheres)[..], "step {step}");
            assert_eq!(bp.sort_buf.capacity(), 0, "step {step}");
            assert_eq!(bp.octree.own_sort_buffer(), 0, "step {step}");
        }
        for &(k, _) in &spheres {
            bp.remove(k).unwrap();
        }
        spheres.clear();
        for _ in 0..3 {
            bp.step();
            bp.validate();
            assert_eq!(bp.pairs(), &expect(&spheres)[..]);
        }
        assert!(bp.octree().is_empty() && !bp.pairs().is_empty());
    }

    /// Outside the incremental regime the escaped list holds only inserts: after the first
    /// step's burst of them, the next step gives back its room, down to the room kept for an
    /// eighth of the proxies.
    #[test]
    fn the_escaped_list_gives_back_the_first_steps_inserts() {
        let mut bp = BroadPhase::new(Config {
            passes: crate::broadphase::Passes::Full,
            ..Config::default()
        });
        let n = 20_000;
        for i in 0..n {
            let c = Vec3::new((i % 100) as f32, (i / 100) as f32, 0.0) * 2.0;
            bp.insert_sphere(c, 0.5).unwrap();
        }
        assert!(bp.escaped.capacity() >= n);
        bp.step();
        bp.step();
        assert!(
            bp.escaped.capacity() <= 2 * (n / 8),
            "{}",
            bp.escaped.capacity()
        );
    }
}
