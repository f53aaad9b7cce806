//! The cost model: which pass a step runs (see the [module docs](super) for the passes and the
//! regime). Each step estimates the work of both passes from what it is about to do (movers,
//! escapes, candidates; outside the regime, from the motion just applied, see
//! [`Motion`](super::fat::Motion)) and runs the cheaper one, with some hysteresis around the regime's entry
//! and exit, so the cost never jumps when a world wakes up or settles.

use super::fat::{ENTRY_BURST_STEPS, Motion};
use super::{BroadPhase, Pass, Passes};

/// Estimated costs of a unit of work, in nanoseconds; only their ratios matter.
mod unit {
    /// The full pass, per proxy (sort, sweep, lists).
    pub(super) const FULL: f64 = 110.0;
    /// The full pass, per pair found: its sort and the lists, and the box tests of the
    /// crowded cells that pairs come with (a settled pile's full pass costs about this much
    /// more per pair than a sparse world's).
    pub(super) const FULL_PAIR: f64 = 36.0;
    /// Carrying one candidate through the step without testing it: the scan for loud sides
    /// and the patches that move it. With few loud proxies the step looks their candidates up
    /// instead of scanning (see `slack::CANDIDATES_PER_LOOKUP`), at the price of scanning that
    /// many candidates per lookup.
    pub(super) const CARRY: f64 = 7.0;
    /// Re-testing one candidate's exact boxes (a branch per outcome), while the exact boxes
    /// of every proxy fit in [`CACHE_BYTES`]: the partner's box is read from the cache.
    pub(super) const TEST: f64 = 10.0;
    /// Re-testing one candidate whose partner's box is a cache miss: in a world whose exact
    /// boxes outgrow [`CACHE_BYTES`], the share of partners that miss costs this.
    pub(super) const TEST_MISS: f64 = 33.0;
    /// The cache the exact boxes of the re-tested partners are read from, in bytes.
    pub(super) const CACHE_BYTES: f64 = 1024.0 * 1024.0;

    /// One re-test in a world of `n` proxies (32-byte exact boxes each).
    pub(super) fn test(n: f64) -> f64 {
        let missing = (1.0 - CACHE_BYTES / (32.0 * n.max(1.0))).max(0.0);
        TEST + (TEST_MISS - TEST) * missing
    }
    /// One escaped proxy in a world of about [`DENSE_CANDIDATES`] candidates per proxy or
    /// more: its structure queries, its new fat box and relink, its new candidates' sort and
    /// merge.
    pub(super) const QUERY: f64 = 1850.0;
    /// One escaped proxy in a world of no candidates (its queries find nothing to sort or
    /// merge, and visit few neighbours); between the two, in proportion to the candidates.
    pub(super) const QUERY_SPARSE: f64 = 400.0;
    /// Candidates per proxy at which an escape costs [`QUERY`].
    pub(super) const DENSE_CANDIDATES: f64 = 1.2;

    /// One escaped proxy in a world of `per_proxy` candidates per proxy.
    pub(super) fn query(per_proxy: f64) -> f64 {
        QUERY_SPARSE + (QUERY - QUERY_SPARSE) * (per_proxy / DENSE_CANDIDATES).min(1.0)
    }
}

/// The incremental regime is entered when its estimated cost is below this fraction of the
/// full pass: the headroom pays for the rebuild that enters it.
const ENTER_FRACTION: f64 = 0.8;
/// The incremental regime is left at once, without waiting for a second step over the full
/// pass's estimate, when a step's estimate is this many times the full pass's: a burst that
/// large (most proxies escaping) is a world in motion, not a passing spike.
const LEAVE_AT_ONCE: f64 = 2.0;
/// [`LEAVE_AT_ONCE`] while the regime settles after its entry ([`ENTRY_BURST_STEPS`]): the
/// entry's burst spreads the fast movers' escapes over a few steps, a world waking up sends
/// every mover out at once.
const SETTLING_LEAVE_AT_ONCE: f64 = 4.0;
/// Before the incremental regime has run, a slow mover (one that stays in its fat box) is
/// taken to re-test its candidates once in the steps it takes to drift half the smallest fat
/// skin, `1/64` of its size (see `fat::MIN_SKIN`): per step, its speed as a fraction of its
/// size times this. Once the regime has run and been left, the estimate follows what it saw
/// instead ([`Costs::loud_per_motion`]).
const LOUD_PER_MOTION: f64 = 2.0 * 64.0;
/// Per step outside the incremental regime, what the regime's last steps taught the estimate
/// ([`Costs::loud_per_motion`]) keeps this share of its distance from [`LOUD_PER_MOTION`]: a
/// world left in a burst (a landing, a wake-up) is tried again once it has calmed, instead of
/// being priced by that burst for good.
const RELEARN_KEEP: f64 = 0.9;
/// [`RELEARN_KEEP`] for the escapes per fast mover ([`Costs::escapes_per_fast`]): they follow
/// the number of fast movers already, so what was learned fades slower, and a world whose
/// fast movers keep escaping (a free fall, whose accelerating movers leave their swept boxes)
/// is not tried again every few steps.
const ESCAPE_KEEP: f64 = 0.98;

/// How many times more candidates than the doubled pairs a world gets per unit of its fast
/// movers' mean skin over their size: a box grown by `m` of its size on every side
/// overlaps about `(1 + 2m)³` as many neighbours in a packed world; this is its slope near
/// `m = 0.5`, the widest skin, which a landing's movers reach.
const CANDIDATES_PER_SKIN: f64 = 4.0;

/// What the cost estimates learn from the steps they watch.
#[derive(Clone, Copy, Debug)]
pub(super) struct Costs {
    /// Of the movers of the last incremental step, the fraction that re-tested their
    /// candidates (see [`super::slack`]).
    pub(super) loud_per_mover: f64,
    /// Of the movers of the last incremental step that stayed in their fat boxes, the
    /// fraction that re-tested their candidates.
    pub(super) loud_per_slow: f64,
    /// Outside the incremental regime, the slow movers expected to re-test their candidates
    /// per unit of their summed motion (`fat::Motion::slow_motion`): [`LOUD_PER_MOTION`] until
    /// the regime is left, then what the regime's last step saw, over the motion of the first
    /// step after it, returning towards [`LOUD_PER_MOTION`] by [`RELEARN_KEEP`] a step.
    loud_per_motion: f64,
    /// Outside the incremental regime, the escapes expected per fast mover: one in the steps
    /// a swept fat box lasts (`Motion::escapes_per_fast`), or what the regime's last step saw
    /// over the fast movers of the first step after it, returning towards the former by
    /// [`ESCAPE_KEEP`] a step.
    escapes_per_fast: f64,
    /// The incremental regime was left at the last step (with this many escapes): this
    /// step's motion, with the regime's last `loud_per_slow`, gives `loud_per_motion` and
    /// `escapes_per_fast`.
    just_left: Option<f64>,
    /// The last incremental step's estimate was over the full pass's.
    pub(super) over: bool,
    /// The step that last entered the incremental regime.
    entered: u32,
    /// Some pass has listed the pairs since this broadphase was made or restored: until one
    /// has, the pairs say nothing of how many candidates an escape will find.
    pub(super) pairs_seen: bool,
}

impl Default for Costs {
    fn default() -> Self {
        Costs {
            loud_per_mover: 1.0,
            loud_per_slow: 1.0,
            loud_per_motion: LOUD_PER_MOTION,
            escapes_per_fast: Motion::escapes_per_fast(),
            just_left: None,
            over: false,
            entered: 0,
            pairs_seen: false,
        }
    }
}

impl Costs {
    /// Outside the incremental regime, the escapes and the loud slow movers an incremental
    /// step would have with the movers of `m`; learns from the regime just left, and lets
    /// what it learned fade.
    fn expect_outside(&mut self, m: &Motion) -> (f64, f64) {
        let swept = Motion::escapes_per_fast();
        self.escapes_per_fast = swept + (self.escapes_per_fast - swept) * ESCAPE_KEEP;
        self.loud_per_motion =
            LOUD_PER_MOTION + (self.loud_per_motion - LOUD_PER_MOTION) * RELEARN_KEEP;
        if let Some(escapes) = self.just_left.take() {
            if m.fast > 0 {
                self.escapes_per_fast = (escapes / m.fast as f64).max(swept);
            }
            if m.slow_motion > 0.0 {
                self.loud_per_motion = self.loud_per_slow * m.slow as f64 / m.slow_motion;
            }
        }
        let slow_loud = (self.loud_per_motion * m.slow_motion).min(m.slow as f64);
        (self.escapes_per_fast * m.fast as f64, slow_loud)
    }
}

impl BroadPhase {
    /// Chooses the pass from the work at hand.
    pub(super) fn plan(&mut self) -> Pass {
        let movers = self.movers.len();
        if movers == 0 && self.removals == 0 && self.nudged == 0 {
            return Pass::Unchanged;
        }
        match self.config.passes {
            Passes::Full => return Pass::Full,
            Passes::Incremental if self.regime.is_some() => return Pass::Incremental,
            Passes::Incremental => return Pass::FullFat,
            Passes::Adaptive => {}
        }
        let n = self.store.len() as f64;
        let full = n * unit::FULL + self.pairs.len() as f64 * unit::FULL_PAIR;
        if self.regime.is_some() {
            // Leaving drops the candidates, which a later return rebuilds with a full pass of
            // its own: a single step over the full pass's cost (a burst of escapes) does not
            // leave, two in a row do, and so does one step far over it (a world waking up).
            let escapes = self.escaped.len() as f64;
            let inc = self.incremental_cost(movers as f64 * self.costs.loud_per_mover, escapes);
            let over = inc > full;
            let was_over = core::mem::replace(&mut self.costs.over, over);
            let settling = self.now.wrapping_sub(self.costs.entered) <= ENTRY_BURST_STEPS;
            let at_once = if settling {
                SETTLING_LEAVE_AT_ONCE
            } else {
                LEAVE_AT_ONCE
            };
            if over && ((was_over && !settling) || inc > full * at_once) {
                self.costs.just_left = Some(escapes);
                Pass::Full
            } else {
                Pass::Incremental
            }
        } else {
            // The regime is priced from the motion just applied: the fast movers escape; a
            // slow one stays in its fat box and re-tests its candidates in proportion to its
            // motion (zero for a proxy sent where it already was); see
            // [`Costs::expect_outside`]. An insert or a regroup (listed as escaped) would
            // query the structures like an escape.
            let (escapes, slow_loud) = self.costs.expect_outside(&self.motion);
            let escapes = escapes + self.escaped.len() as f64;
            let inc = self.incremental_cost(slow_loud + escapes, escapes);
            if inc < full * ENTER_FRACTION {
                self.costs.entered = self.now;
                Pass::FullFat
            } else {
                Pass::Full
            }
        }
    }

    /// The estimated cost of an incremental step in which `loud` proxies re-test their
    /// candidates, `escapes` of them after leaving their fat boxes.
    fn incremental_cost(&self, loud: f64, escapes: f64) -> f64 {
        let n = self.store.len().max(1) as f64;
        // In the regime the candidates are counted; outside it fat boxes are taken to double
        // the pairs, more where fast movers would get wide ones (their skin over their
        // size, summed, per proxy, times [`CANDIDATES_PER_SKIN`]).
        let cands = if let Some(r) = &self.regime {
            r.cand.len() as f64
        } else {
            let wide = self.motion.fast_skin / n * CANDIDATES_PER_SKIN;
            2.0 * self.pairs.len() as f64 * (1.0 + wide)
        };
        let per_proxy = cands / n;
        // Before any pass an escape is priced as a dense world's: the first step of a gas
        // has no pairs yet.
        let density = if self.costs.pairs_seen {
            per_proxy
        } else {
            unit::DENSE_CANDIDATES
        };
        // The loud proxies' candidates are looked up, or found by one scan of them all.
        let visited = cands.min(loud * super::slack::CANDIDATES_PER_LOOKUP as f64);
        visited * unit::CARRY
            + (loud * per_proxy * 2.0).min(cands) * unit::test(n)
            + escapes * unit::query(density)
    }
}
