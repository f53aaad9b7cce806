//! An update is a store; the step applies it (but for nudges, below).
//!
//! [`BroadPhase::update_sphere`] and [`BroadPhase::update_body`] (and their batches) check
//! their input, write the new shape into the slot's entry of the dense shape array, and mark
//! the slot `MOVED | STALE` (listing it in `movers` once, however often it is updated). Nothing
//! else happens at the call (a nudge excepted): the exact box, the motion record and the
//! structure's box are the last step's until the next [`BroadPhase::step`], whose first act is
//! [`BroadPhase::apply_updates`]: one pass over the stale slots in slot order (a walk over every
//! slot's flags when many are stale, else the mover list, radix-sorted by slot when the
//! caller's order was another), each given
//! - its exact box (the shape grown by `Config::margin`) and its motion since it was last
//!   applied (for its skin and the pass estimate: a key updated several times between
//!   two steps counts one move, from where it was applied last to its last shape);
//! - its place in its structure: outside the incremental regime the exact box (a sphere
//!   that changes node gets its node at once and its node lists later: the pass that
//!   follows relinks the moved spheres beside its walk-order sort, on another thread when
//!   the sort is split, see `Octree::update_live_deferred`; a BVH leaf is written and grown,
//!   and once every slot is applied each grown leaf's ancestors are grown in one walk up,
//!   however many of its bodies moved), inside it the fat box it still lies in, or a new one.
//!
//! Slot order makes the pass stream through every per-slot array and the octree's records,
//! whatever order the caller updated in (a churn's reused keys come in none).
//!
//! **Nudges.** In the incremental regime an update whose new exact box still lies in the fat
//! box its structure holds, and which drifted under half its slack from its anchor (see
//! [`super::slack`]), changes no pair and nothing its structure holds: all the step would do
//! with it is store its exact box and flag it drifted. The update does that itself
//! ([`Nudger::nudge`]) and leaves the slot applied, not stale, so the step never visits it. A
//! settling pile, sent whole every frame, is mostly such updates. Only updates in ascending
//! slot order are nudged ([`in_order`]): in another order the step's walk in slot order costs
//! less than the scattered reads of the regime's arrays at the calls.
//!
//! **Between an update and the next step** the structures hold the stale slots at their last
//! applied boxes, so the queries (`BroadPhase::query_aabb` and the rest) skip a stale slot where a structure
//! reports it and test every stale slot's latest shape after the structures' walk instead: a
//! query costs `O(stale)` more until the next step applies them (nothing at all once the step
//! ran, or when nothing was updated). [`BroadPhase::shape`], [`BroadPhase::aabb`] and snapshots
//! read the latest shapes; [`BroadPhase::octree`] and [`BroadPhase::bvh`] show the structures as
//! the last step left them.

use super::regime::Incremental;
use super::store::flag;
use super::{BroadPhase, Shape, fat, slack};
use crate::geom::SimdBox;
use crate::radix::sort_u32_below;

/// The stale slots are applied by walking every slot's flags once at least one slot in this
/// many is stale, and by sorting the mover list below that.
const DENSE_FRACTION: usize = 8;
#[cfg(feature = "parallel")]
use super::step::TASKS_PER_THREAD;

impl BroadPhase {
    /// Applies every update since the last step, in slot order (see the module docs).
    pub(super) fn apply_updates(&mut self) {
        if self.stale == 0 {
            return;
        }
        self.apply_stale();
        self.stale = 0;
        // The bodies' leaves were written without their ancestors
        // (`Bvh::update_box_deferred`): each leaf that grew has them grown once, here.
        self.dynamic.enlarge_deferred();
        self.statics.enlarge_deferred();
    }

    /// Applies every stale slot: the dense walk (split over the pool when that pays) or the
    /// sorted movers.
    fn apply_stale(&mut self) {
        let slots = self.store.slots();
        #[cfg(feature = "parallel")]
        if self.apply_par() {
            return;
        }
        if self.stale >= slots / DENSE_FRACTION {
            // Most slots are stale: one streaming walk over the flags is cheaper than sorting
            // the mover list (whose order then stays the caller's).
            if self.apply_spheres_fat(true) == Some(0) {
                return;
            }
            for s in 0..slots {
                let f = &mut self.store.flags[s];
                if *f & flag::STALE != 0 {
                    *f &= !flag::STALE;
                    self.apply(s as u32);
                }
            }
        } else {
            if !self.movers.is_sorted() {
                sort_u32_below(
                    &mut self.movers,
                    &mut self.movers_tmp,
                    &mut self.movers_counts,
                    slots,
                );
            }
            if self.apply_spheres_fat(false) == Some(0) {
                return;
            }
            for i in 0..self.movers.len() {
                let slot = self.movers[i];
                let f = &mut self.store.flags[slot as usize];
                if *f & flag::STALE != 0 {
                    *f &= !flag::STALE;
                    self.apply(slot);
                }
            }
        }
    }

    /// Applies the stored shape of the stale live `slot`: its exact box, its motion, and its
    /// structure's box (outside the incremental regime the exact one, inside it a fat one).
    /// Always inlined into both walks: the centre then stays in registers.
    #[inline(always)]
    fn apply(&mut self, slot: u32) {
        let s = slot as usize;
        match self.store.shape[s] {
            Shape::Sphere { center, radius } => {
                let grown = fat::grown_sphere(center, radius, self.config.margin);
                if let Some(r) = &mut self.regime {
                    let old = core::mem::replace(&mut r.exact[s], grown.aabb);
                    let motion = self.note_motion(s, &old, &grown.aabb);
                    if self.refresh_fat(slot, &grown.aabb, motion) {
                        self.settle(slot);
                    }
                } else {
                    // The octree's record holds the exact box it was last applied at.
                    let old = self.octree.held_box_of(slot);
                    self.note_motion(s, &old, &grown.aabb);
                    let key = self.store.key(slot);
                    // The lists catch up in the pass that follows (see the octree's
                    // `update_live_deferred`).
                    self.octree.update_live_deferred(key, center, grown.radius);
                }
            }
            shape @ Shape::Body { kind, .. } => {
                let exact = fat::grown(shape, self.config.margin).aabb;
                // Every body's exact box is kept (see `Incremental`).
                let old = core::mem::replace(&mut self.kept_exact_mut()[s], exact);
                let motion = self.note_motion(s, &old, &exact);
                if self.regime.is_some() {
                    if self.refresh_fat(slot, &exact, motion) {
                        self.settle(slot);
                    }
                } else {
                    let key = self.store.key(slot);
                    let placed = self.tree_mut(kind).update_box_deferred(key, &exact);
                    debug_assert!(placed.is_ok(), "a live body missing from its BVH");
                }
            }
        }
    }

    /// The walk over the stale spheres in the incremental regime (every slot with `dense`, else
    /// the sorted movers), in one pass over the per-slot arrays: each gets its exact box and
    /// motion, and either still lies in its fat box, where it is classified quiet or loud at
    /// once (see [`super::slack`]), or escaped, and is listed to get its new fat box after the
    /// walk, in slot order. Returns how many stale slots it left for [`BroadPhase::apply`]: the
    /// bodies, and the spheres already listed as escaped (inserted or regrouped since the last
    /// step); `None`, having done nothing, outside the regime.
    fn apply_spheres_fat(&mut self, dense: bool) -> Option<usize> {
        let (margin, now) = (self.config.margin, self.now);
        let first_escape = self.escaped.len();
        let r = self.regime.as_mut()?;
        let (st, loud, escaped) = (&mut self.store, &mut self.loud, &mut self.escaped);
        // The motion is not counted: only the estimate outside the regime reads it.
        let rest = if dense {
            fat_walk(0..st.slots(), st, r, loud, escaped, margin, now)
        } else {
            let movers = self.movers.iter().map(|&m| m as usize);
            fat_walk(movers, st, r, loud, escaped, margin, now)
        };
        for i in first_escape..self.escaped.len() {
            // The walk left an escaped sphere's exact box, speed and stamp as they were: its
            // motion is read from the box it left, for the new fat box's sweep.
            let slot = self.escaped[i];
            let s = slot as usize;
            let new = self.exact_box(&self.store.shape[s]);
            let old = core::mem::replace(&mut self.kept_exact_mut()[s], new);
            let motion = self.note_motion(s, &old, &new);
            self.hold_moving(slot, motion);
        }
        Some(rest)
    }

    /// The dense walk with its spheres' share split over rayon's current pool, outside the
    /// incremental regime, with more than one thread and at least `PARALLEL_MIN_SPHERES`
    /// spheres, at least one slot in [`DENSE_FRACTION`] stale; false (nothing done) otherwise.
    /// Each task takes a range of slots and, for its stale spheres, computes the exact box, the
    /// motion and the octree placement, and stores the sphere in its octree record, noting
    /// the spheres that change node for the pass to relink (`Record::store_placed`); one walk
    /// in slot order then applies what is left, if anything: the spheres that enter or leave
    /// the region or the root, and the bodies. Every slot's outcome depends only on its own
    /// shape and the relinks come in slot order, so the result is the serial walk's at any
    /// thread count.
    #[cfg(feature = "parallel")]
    fn apply_par(&mut self) -> bool {
        use super::store::Kind;
        use rayon::prelude::*;
        let slots = self.store.slots();
        let threads = rayon::current_num_threads();
        if self.regime.is_some()
            || threads < 2
            || self.octree.len() < super::step::PARALLEL_MIN_SPHERES
            || self.stale < slots / DENSE_FRACTION
        {
            return false;
        }
        let chunk = slots.div_ceil(threads * TASKS_PER_THREAD).max(1);
        let tasks = slots.div_ceil(chunk);
        let moves = &mut self.par.moves;
        if moves.len() < tasks {
            moves.resize_with(tasks, Default::default);
        }
        let (margin, now) = (self.config.margin, self.now);
        let (placer, records) = self.octree.split_for_update();
        let st = &mut self.store;
        let shape = &st.shape;
        let (motion, done) = st
            .speed
            .par_chunks_mut(chunk)
            .zip(st.stamp.par_chunks_mut(chunk))
            .zip(st.flags.par_chunks_mut(chunk))
            .zip(records.par_chunks_mut(chunk))
            .zip(moves[..tasks].par_iter_mut())
            .enumerate()
            .map(|(c, ((((speed, stamp), flags), records), moves))| {
                let (mut motion, mut done, mut placer) = (fat::Motion::default(), 0, placer);
                // The records end at the highest sphere id: a chunk's later slots (and the
                // chunks after the records) hold no sphere.
                for i in 0..records.len() {
                    let s = c * chunk + i;
                    let Shape::Sphere { center, radius } = shape[s] else {
                        continue;
                    };
                    if flags[i] & flag::STALE == 0 {
                        continue;
                    }
                    let grown = fat::grown_sphere(center, radius, margin);
                    // Outside the incremental regime the sphere's record holds its exact box.
                    let v = fat::speed(&records[i].simd_box(), &grown.aabb, stamp[i], now);
                    (speed[i], stamp[i]) = (v, now);
                    motion.note(v, grown.aabb.extent().max_element());
                    let at = placer.placement_of(center, grown.radius);
                    let r = grown.radius;
                    if records[i].store_placed(&placer, s as u32, center, r, &at, moves) {
                        flags[i] &= !flag::STALE;
                        done += 1;
                    }
                }
                (motion, done)
            })
            .reduce(
                || (fat::Motion::default(), 0),
                |a, b| (a.0.add(b.0), a.1 + b.1),
            );
        self.motion = self.motion.add(motion);
        self.octree.take_moves(&mut self.par.moves[..tasks]);
        // Every stale slot is counted (`self.stale`): none left, no walk.
        if done == self.stale {
            return true;
        }
        // What is left: the bodies, and the spheres that enter or leave the region or the
        // root, placed again (the region is the one the tasks placed them in).
        for s in 0..slots {
            let f = &mut self.store.flags[s];
            if *f & flag::STALE == 0 {
                continue;
            }
            *f &= !flag::STALE;
            if self.store.kind[s] != Kind::Sphere {
                self.apply(s as u32);
                continue;
            }
            if let Shape::Sphere { center, radius } = self.store.shape[s] {
                let key = self.store.key(s as u32);
                let r = fat::grown_sphere(center, radius, margin).radius;
                self.octree.update_live_deferred(key, center, r);
            }
        }
        self.octree.order_deferred();
        true
    }

    /// True if `slot` was updated since the last step and the update is not applied yet: the
    /// structures hold its last applied box, its shape is the latest.
    #[inline]
    pub(super) fn is_stale(&self, slot: usize) -> bool {
        self.store.flags[slot] & flag::STALE != 0
    }

    /// Calls `f(slot)` for every stale live slot (see [`BroadPhase::is_stale`]), in the order
    /// they were first updated; nothing, in O(1), when there are none.
    #[inline]
    pub(super) fn for_each_stale(
        &self,
        mut f: impl FnMut(usize) -> core::ops::ControlFlow<()>,
    ) -> core::ops::ControlFlow<()> {
        if self.stale == 0 {
            return core::ops::ControlFlow::Continue(());
        }
        for &m in &self.movers {
            if self.is_stale(m as usize) {
                f(m as usize)?;
            }
        }
        core::ops::ControlFlow::Continue(())
    }
}

/// The regime's per-slot arrays a nudge reads and writes (see the module docs), cut to the
/// slot count: one bound for the compiler to check.
struct Nudger<'a> {
    exact: &'a mut [SimdBox],
    held: &'a [SimdBox],
    anchor: &'a [SimdBox],
    slack: &'a [f32],
    now: u32,
}

impl<'a> Nudger<'a> {
    /// The nudges of the regime `r` over its first `slots` slots, at step `now`.
    #[inline(always)]
    fn new(r: &'a mut Incremental, slots: usize, now: u32) -> Self {
        Nudger {
            exact: &mut r.exact[..slots],
            held: &r.held[..slots],
            anchor: &r.anchor[..slots],
            slack: &r.slack[..slots],
            now,
        }
    }

    /// Applies at once the update of the live slot `s` (its new shape already stored, no
    /// earlier update since the last step naming it) to the exact box `new()`, if all the
    /// step would do with it is store that box: the slot is neither stale nor escaped
    /// (inserted or regrouped since the last step), `new()` lies in its fat box, and it stays
    /// quiet. Returns whether it did; otherwise the caller marks the slot stale.
    #[inline(always)]
    fn nudge(
        &mut self,
        (flags, stamp): (&mut [u8], &mut [u32]),
        s: usize,
        new: impl FnOnce() -> SimdBox,
    ) -> bool {
        let f = flags[s];
        if f & (flag::STALE | flag::ESCAPED) != 0 {
            return false;
        }
        let new = new();
        let quiet =
            self.held[s].contains(&new) && slack::stays_quiet(&new, &self.anchor[s], self.slack[s]);
        if quiet {
            (self.exact[s], stamp[s]) = (new, self.now);
            flags[s] = f | flag::DRIFTED;
        }
        quiet
    }
}

/// How one update call stores its updates in the incremental regime: it nudges them while the
/// updates since the last step come in slot order, else leaves them to the step, giving back
/// the count of a slot an earlier call nudged.
pub(super) struct Nudges<'a> {
    /// The regime's arrays, while this call nudges.
    fat: Option<Nudger<'a>>,
    /// Outside slot order, some earlier call since the last step nudged a slot.
    recount: bool,
    now: u32,
}

impl<'a> Nudges<'a> {
    /// The plan of a call that updates the slots `slots` (in the caller's order; the
    /// broadphase's first `n` slots), with the broadphase's `regime`, order of updates `from`
    /// ([`in_order`]) and count of nudged slots, at step `now`.
    #[inline(always)]
    pub(super) fn plan(
        regime: &'a mut Option<Incremental>,
        (from, nudged): (&mut u32, usize),
        slots: impl Iterator<Item = u32>,
        n: usize,
        now: u32,
    ) -> Self {
        let Some(r) = regime else {
            return Nudges {
                fat: None,
                recount: false,
                now,
            };
        };
        let ordered = in_order(from, slots);
        Nudges {
            fat: ordered.then(|| Nudger::new(r, n, now)),
            recount: !ordered && nudged > 0,
            now,
        }
    }

    /// For the live slot `s`, its new shape stored and its exact box `new()`: true if the
    /// update was nudged (counted in `nudged`); else the caller marks the slot stale, and a
    /// nudge of it by an earlier call is taken back from `nudged`.
    #[inline(always)]
    pub(super) fn take(
        &mut self,
        (flags, stamp): (&mut [u8], &mut [u32]),
        s: usize,
        new: impl FnOnce() -> SimdBox,
        nudged: &mut usize,
    ) -> bool {
        if let Some(fat) = &mut self.fat {
            let done = fat.nudge((flags, stamp), s, new);
            *nudged += usize::from(done);
            done
        } else {
            if self.recount && was_nudged(flags[s], stamp[s], self.now) {
                // Nudged by an earlier call since the last step: a mover from now on.
                *nudged -= 1;
            }
            false
        }
    }
}

/// True if a batch of updates to the slots `slots` (in the caller's order) may be nudged:
/// they ascend, from `from` (one past the slot of the last update since the last step), so
/// nudges stream through the per-slot arrays as the step's walk would. Moves `from` past the
/// batch; once a batch is out of order, it stays `u32::MAX` until the next step, and the
/// step's walk applies every update in slot order instead of the calls' scattered reads.
#[inline(always)]
fn in_order(from: &mut u32, slots: impl Iterator<Item = u32>) -> bool {
    let mut next = *from;
    let ordered = slots.into_iter().all(|s| {
        let ascends = s >= next;
        next = s + 1;
        ascends
    });
    *from = if ordered { next } else { u32::MAX };
    ordered
}

/// In the incremental regime, true if the live slot of flags `f` and stamp `stamp` was nudged
/// since the last step (see [`Nudger::nudge`]): a nudge stamps the slot with the coming step, an
/// applied slot's stamp is an earlier step's, and an inserted slot is escaped.
#[inline(always)]
pub(super) fn was_nudged(f: u8, stamp: u32, now: u32) -> bool {
    f & (flag::STALE | flag::ESCAPED) == 0 && stamp == now
}

/// [`BroadPhase::apply_spheres_fat`]'s walk over `slots`: returns how many it left for
/// [`BroadPhase::apply`]. Inlined into each caller, so that the dense walk over `0..slots`
/// needs no bounds checks on the cut slices.
#[inline(always)]
fn fat_walk(
    slots: impl Iterator<Item = usize>,
    st: &mut super::store::Store,
    r: &mut Incremental,
    loud: &mut Vec<u32>,
    escaped: &mut Vec<u32>,
    margin: f32,
    now: u32,
) -> usize {
    let n = st.slots();
    let (flags, shape, stamp) = (&mut st.flags[..n], &st.shape[..n], &mut st.stamp[..n]);
    let (exact, held) = (&mut r.exact[..n], &r.held[..n]);
    let (anchor, slk) = (&mut r.anchor[..n], &mut r.slack[..n]);
    let mut rest = 0;
    for s in slots {
        let f = flags[s];
        if f & flag::STALE == 0 {
            continue;
        }
        let Shape::Sphere { center, radius } = shape[s] else {
            rest += 1;
            continue;
        };
        if f & flag::ESCAPED != 0 {
            // Inserted or regrouped since the last step: already listed as escaped.
            rest += 1;
            continue;
        }
        let new = fat::grown_sphere(center, radius, margin).aabb;
        if !held[s].contains(&new) {
            // Its exact box and motion are noted with its new fat box, after the walk.
            flags[s] = f & !flag::STALE | flag::ESCAPED;
            escaped.push(s as u32);
            continue;
        }
        // Its speed is measured when it leaves its fat box (from this box and stamp), the only
        // time the incremental regime reads it.
        (exact[s], stamp[s]) = (new, now);
        // Still in its fat box: quiet or loud (see `slack::settle`; nothing is loud yet).
        if slack::stays_quiet(&new, &anchor[s], slk[s]) {
            flags[s] = f & !flag::STALE | flag::DRIFTED;
        } else {
            flags[s] = f & !(flag::STALE | flag::DRIFTED) | flag::LOUD;
            loud.push(s as u32);
            (anchor[s], slk[s]) = (new, f32::MAX);
        }
    }
    rest
}

#[cfg(test)]
mod tests {
    use crate::broadphase::{BroadPhase, Config, Pass};
    use crate::brute::{self, Proxy};
    use crate::{Aabb, BodyKind, Vec3};

    /// In the incremental regime, jitters under half the slack sent in slot order are nudges:
    /// applied by the update calls (batch, single and body), so the step finds nothing stale
    /// and no movers; a move out of reach after a nudge makes the slot a mover after all,
    /// counted once; a batch out of slot order is left to the step.
    #[test]
    fn jitters_in_the_regime_are_applied_by_the_update() {
        let mut bp = BroadPhase::new(Config::default());
        let at = |i: usize| Vec3::new((i % 10) as f32, (i / 10) as f32, 0.0) * 0.95;
        // One at a time, so that the slots follow `i`.
        let mut spheres = Vec::new();
        for i in 0..100 {
            spheres.push(bp.insert_sphere(at(i), 0.5).unwrap());
        }
        let body_box = |dx: f32| Aabb {
            min: Vec3::new(dx, -3.0, 0.0),
            max: Vec3::new(dx + 1.0, -2.0, 1.0),
        };
        let body = bp.insert_body(body_box(0.0), BodyKind::Dynamic).unwrap();
        let send = |bp: &mut BroadPhase, d: f32| {
            let batch: Vec<_> = (0..99)
                .map(|i| (spheres[i], at(i) + Vec3::new(d, 0.0, 0.0), 0.5))
                .collect();
            bp.update_spheres(&batch).unwrap();
            bp.update_sphere(spheres[99], at(99) + Vec3::new(d, 0.0, 0.0), 0.5)
                .unwrap();
            bp.update_body(body, body_box(d)).unwrap();
        };
        for _ in 0..4 {
            send(&mut bp, 0.0);
            bp.step();
        }
        assert_eq!(bp.stats().pass, Pass::Incremental);
        send(&mut bp, 0.0001);
        assert_eq!((bp.stale, bp.movers.len(), bp.nudged), (0, 0, 101));
        bp.validate();
        // One sphere again, far: it leaves the nudged count for the movers.
        bp.update_sphere(spheres[0], at(0) + Vec3::splat(0.4), 0.5)
            .unwrap();
        assert_eq!((bp.stale, bp.movers.len(), bp.nudged), (1, 1, 100));
        bp.step();
        bp.validate();
        assert_eq!(bp.stats().pass, Pass::Incremental);
        assert_eq!(bp.stats().updated, 101);
        // A batch out of slot order is not nudged: the step's walk applies it in slot order.
        let batch: Vec<_> = (0..100)
            .rev()
            .map(|i| (spheres[i], at(i) + Vec3::new(0.0003, 0.0, 0.0), 0.5))
            .collect();
        bp.update_spheres(&batch).unwrap();
        assert_eq!((bp.stale, bp.movers.len(), bp.nudged), (100, 100, 0));
        bp.step();
        bp.validate();
        assert_eq!(bp.stats().updated, 100);
        // Nudged, then one of them sent again out of order: each counted once.
        send(&mut bp, 0.0002);
        bp.update_sphere(spheres[0], at(0) + Vec3::splat(0.4), 0.5)
            .unwrap();
        bp.step();
        bp.validate();
        assert_eq!(bp.stats().pass, Pass::Incremental);
        assert_eq!(bp.stats().updated, 101);
        // The pairs, from the test's own boxes: each sphere where it was sent last, the body at
        // its last box.
        let grown = 0.5 + bp.config().margin;
        let mut proxies: Vec<Proxy> = (0..100)
            .map(|i| {
                let d = if i == 0 {
                    Vec3::splat(0.4)
                } else {
                    Vec3::X * 0.0002
                };
                Proxy::new(spheres[i], Aabb::from_center_radius(at(i) + d, grown))
            })
            .collect();
        let body_grown = body_box(0.0002).grown(bp.config().margin);
        proxies.push(Proxy::new(body, body_grown));
        assert_eq!(bp.pairs(), brute::pairs(&proxies));
    }
}
