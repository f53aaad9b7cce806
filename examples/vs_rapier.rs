//! broadleaf's `BroadPhase` against rapier3d's broad phase on the same seeded scene.
//!
//! ```text
//! cargo run --release --features profiler --example vs_rapier -- --scene gas --n 100000
//!     [--steps 30] [--warmup 5] [--placement strict|loose] [--seed 1] [--skin 0]
//!     [--groups G] [--every]
//! ```
//!
//! `--scene` is `gas`, `clustered`, `bodies`, `churn`, `pile`, `fall`, `idle`, one of the worlds no
//! fixed region suits (`far`: the `gas` cube 3 km from the origin; `open`: spheres moving like
//! `gas` over 4 km × 40 m × 4 km; `sparse`: the same over 1 km × 40 m × 1 km; `large`: r = 5 m
//! at 10 % fill, an 806 m cube; `flying`: the `gas` cube crossing x = 512 m at 600 m/s;
//! `fixtures::scene::worlds`) or `all` (every scene at its default N: fall 4000, bodies and
//! pile 10 000, the others 100 000; `--n` overrides it for all; `all` runs `idle` at 1 % and at 10 %
//! moving). `idle` is the `gas`
//! spheres at rest but for a fixed random `--moving P` % of them (default 1) that move like
//! `gas`; the others are never updated, in broadleaf or in rapier. `bodies --moving P` moves
//! only a fixed P % of its dynamic boxes (default 100). `--moving` takes a list
//! (`--moving 0,1,2,5,10,20,50,100`): one row per P, and with more than one P and no
//! `--scene` the scene is `idle`; `--plot PATH.svg` then draws ns/object/step against P (a
//! linear P axis), otherwise against N (`--sizes`, log–log). `pile` is recorded first from a
//! dynamic rapier run (`fixtures::rapier_world::record_pile`, 240 settling steps, untimed) and
//! then replayed like the others. The scene's frames are
//! generated first; then broadleaf runs all of them, then rapier does (`--interleave`
//! alternates the two per step instead, so each also pays for the other evicting its caches).
//! Each step the scene's motion is fed to both:
//!
//! - broadleaf: the frame's removes, inserts and new positions/boxes (one `update_spheres` and
//!   one `update_bodies` batch; `--per-object` calls `update_sphere` / `update_body` for each
//!   object instead), then `step()`; spheres go in with `insert_sphere` (into the octree),
//!   boxes as bodies (into the BVHs). The Config is `Config::default()` (no region: the
//!   octree's follows the spheres) unless `--placement`, `--skin` (`Config::skin`) or
//!   `--passes` is given. The frame's batches (keys, centres, boxes: `Feed::stage`) are built
//!   before the timer starts; `Instant` times the library's calls only (`Feed::commit`: the
//!   removes, inserts and update batches, then `step()`), as rapier's pose writes happen
//!   outside its counter.
//! - rapier: kinematic position-based bodies, ball or cuboid colliders with
//!   `ActiveCollisionTypes::all()`, fixed bodies for static boxes; moved with
//!   `set_next_kinematic_translation`, then `PhysicsPipeline::step`. Its broad-phase time per
//!   step is `counters.cd.broad_phase_time` (the BVH update and pair search at the start of
//!   the step, including a deferred tree optimisation it joins) plus
//!   `counters.cd.final_broad_phase_time` (the end-of-step leaf refits).
//!
//! rapier detects collisions at the start of its step, before the kinematic bodies reach
//! their targets, so its pairs lag one step: a body enters rapier's world after the step that
//! detects the previous frame, and one extra, untimed rapier step after the last measured one
//! yields rapier's pairs of the last measured frame. Those are compared with broadleaf's pairs
//! of that frame and with brute force (`exact ⊆ ours ⊆ rapier`, static×static left out).
//!
//! `--groups G` (default 0: none) spreads every scene's objects over G collision groups
//! round-robin by scene id, each pairing only within itself (`memberships = filter =
//! 1 << (id % G)`, `fixtures::scene::round_robin_groups`, G ≤ 32): broadleaf gets them with
//! `set_groups` as each object is inserted (`Feed::groups`), rapier as the same
//! `InteractionGroups` (`And` mode) on each collider (`SceneWorld::groups`), and the brute-force
//! reference is filtered by the same rule (`Feed::retain_allowed`). The scene cell says
//! `(G groups)`.
//!
//! `fall` (`fixtures::rapier_world::record_fall`, the demo's drop: N balls of r = 0.5 m from
//! a grid into an open box) is not a kinematic replay: rapier simulates the drop for real
//! (dynamic balls, fixed walls, default `IntegrationParameters`, sleeping on) for 600 steps
//! (N ≤ 4000) or 900 (above; `--steps` and `--warmup` do not apply), and rapier's column is
//! its broad-phase counter at each step of that run. broadleaf (walls as static bodies)
//! replays the recorded frames: each frame's batch of the balls whose centre changed
//! (`--every`: all balls) is built before the timer, which covers `update_centers` and
//! `step()` only (frame 0: inserting the balls and the first step, against rapier's first
//! step, which builds its tree). Its row in the main table holds the means over the whole run;
//! a phase table follows (falling: until the mean speed drops under 1 m/s after its peak;
//! settling; resting: after the last step with more than 1 % of the balls awake, when there is
//! one; whole run), with the worst 30-step window. Every frame's pairs are checked against
//! brute force (untimed); missed and extra are summed over the frames, and the rapier pairs
//! cell repeats the exact count (rapier's own pairs of its dynamic run are not recorded).
//!
//! Times are medians over the measured steps after the warm-up, in ns per object (every live
//! object, static ones included) per step. The last line is exactly
//! `ratio=<speed-up> missed=<n> extra=<n>`; for `--scene all` the ratio is the worst (smallest)
//! speed-up of the scenes and `missed`/`extra` are summed over them.
//!
//! `--queries` runs scene queries instead of the step table: on `gas` (N = `--n`, default
//! 100 000) after the warm-up steps (`--warmup`), 100 000 box queries (cubes of 1–4 m edge, centres uniform in the
//! scene's cube) and 100 000 closest-hit rays (origins uniform in the cube, directions uniform
//! on the sphere, `max_t` the cube's edge), timed in broadleaf (`query_aabb`, `cast_ray`) and in
//! rapier's query pipeline over the same colliders (`BroadPhaseBvh::as_query_pipeline`:
//! `intersect_aabb_conservative` re-tested against each collider's exact AABB, so both return
//! the same set, and `cast_ray` with `solid`). Every 100th query is checked: the same key set
//! for a box; for a ray the same `t` within 1e-4 and the same collider, or (a tie, as for an
//! origin inside two overlapping spheres) one of the scene's spheres hit at that `t`. Then
//! 100 000 sphere casts (radius 0.25 m, origins and directions drawn like the rays') and
//! 100 000 nearest-object queries (points uniform in the cube): broadleaf's `cast_sphere` and
//! `nearest(p, 1)` against rapier's `cast_shape` with a `Ball` (`stop_at_penetration`, so a
//! start touching is `t = 0` as in broadleaf) and `project_point` with `solid` (distance
//! `|p − projection|`, 0 inside a ball, as broadleaf's distance to the sphere). The sampled
//! checks follow the ray's rule: the same `t` or distance within 1e-4, and the same collider
//! or, in a tie, one whose scene sphere gives that value. With `--scene bodies` (N = `--n`,
//! default 10 000, plus the static boxes and the floor) the same queries run on a world of
//! boxes after one step of its motion, each box given to both engines as its world AABB
//! (rapier: an axis-aligned cuboid), since broadleaf answers on a body's box; there a sphere
//! cast of rapier's at a box also agrees if it names the same box at a `t` where the ball is
//! within `RAPIER_CAST_GAP_TOLERANCE` of touching it (rapier stops its cast within a
//! tolerance). Every sampled query is also checked against brute force over the scene's own
//! shapes: the same key and exactly the same `t` or distance, ties to the smaller key. Its own
//! table; the last line is `queries mismatches=<n>` (rapier's and brute force's summed).

use broadleaf::fixtures::cli::{self, Flags, Stop};
use broadleaf::fixtures::rapier_world::{
    FallRecording, SceneWorld, fall_steps, record_fall, record_pile,
};
use broadleaf::fixtures::scene::{
    Bodies, CentersFeed, Churn, Feed, Flying, Frame, GAS_RADIUS, Gas, Idle, Object, Rng, Scene,
    Spawn,
};
use broadleaf::fixtures::sim::DropConfig;
use broadleaf::rapier::Comparison;
use broadleaf::{
    Aabb, BodyKind, BroadPhase, Config, Pair, Passes, Placement, ProxyKey, Vec3, brute, geom,
};
use plotters::prelude::*;
use rapier3d::math::Pose;
use rapier3d::parry::bounding_volume::BoundingVolume;
use rapier3d::parry::query::{Ray, ShapeCastOptions};
use rapier3d::parry::shape::Ball;
use std::collections::HashMap;
use std::hint::black_box;
use std::time::Instant;

struct Args {
    scene: String,
    n: Option<usize>,
    steps: usize,
    warmup: usize,
    placement: Option<Placement>,
    /// `Config::skin`.
    skin: f32,
    /// `Config::passes`.
    passes: Passes,
    seed: u64,
    /// Several sizes of one scene instead of `n` (`--sizes 1000,10000,100000`).
    sizes: Vec<usize>,
    /// Where to write an SVG plot of ns/object/step against N.
    plot: Option<String>,
    /// Alternate the two engines step by step instead of running each back to back.
    interleave: bool,
    /// Percentages of movers for `idle` and `bodies` (`--moving 1` or `--moving 0,1,10`);
    /// empty: each scene's default.
    moving: Vec<f64>,
    /// True if `--scene` was given (with several `--moving` values the default is `idle`).
    scene_given: bool,
    /// Feed the moves one `update_*` call per object instead of in batches.
    per_object: bool,
    /// Time scene queries instead of steps.
    queries: bool,
    /// Round-robin collision groups of every scene (0: none).
    groups: u32,
    /// `fall`: send every ball each frame, not only the ones that moved.
    every: bool,
}

const USAGE: &str = "usage: vs_rapier [--scene gas|clustered|bodies|churn|pile|fall|idle|far|open|\
                     sparse|large|flying|all] [--n N] [--steps 30] [--warmup 5] \
                     [--placement strict|loose] [--skin 0] [--passes adaptive|full|incremental] [--seed 1] \
                     [--sizes N1,N2,...] [--moving P1,P2,...] [--plot PATH.svg] [--interleave] \
                     [--per-object] [--queries] [--groups G] [--every]";

fn parse_args(argv: impl IntoIterator<Item = String>) -> Result<Args, Stop> {
    let mut args = Args {
        scene: "gas".into(),
        n: None,
        steps: 30,
        warmup: 5,
        placement: None,
        skin: 0.0,
        passes: Passes::Adaptive,
        seed: 1,
        sizes: Vec::new(),
        plot: None,
        interleave: false,
        moving: Vec::new(),
        scene_given: false,
        per_object: false,
        queries: false,
        groups: 0,
        every: false,
    };
    let mut flags = Flags::new(argv);
    while let Some(flag) = flags.next_flag()? {
        match flag.as_str() {
            "--interleave" => args.interleave = true,
            "--per-object" => args.per_object = true,
            "--queries" => args.queries = true,
            "--every" => args.every = true,
            "--scene" => {
                args.scene = flags.value(&flag)?;
                args.scene_given = true;
            }
            "--moving" => {
                args.moving = flags
                    .value(&flag)?
                    .split(',')
                    .map(|v| match v.parse::<f64>() {
                        Ok(p) if (0.0..=100.0).contains(&p) => Ok(p),
                        _ => Err(format!("--moving {v}: a percentage in [0, 100]")),
                    })
                    .collect::<Result<_, _>>()?;
            }
            "--n" => args.n = Some(flags.parse(&flag)?),
            "--steps" => args.steps = flags.parse::<usize>(&flag)?.max(1),
            "--warmup" => args.warmup = flags.parse(&flag)?,
            "--seed" => args.seed = flags.parse(&flag)?,
            "--groups" => {
                args.groups = match flags.parse(&flag)? {
                    g @ 0..=32 => g,
                    g => return Err(format!("--groups {g}: at most 32 groups").into()),
                };
            }
            "--sizes" => {
                let value = flags.value(&flag)?;
                let number = |v: &str| v.parse::<usize>().map_err(|e| format!("{flag} {v}: {e}"));
                args.sizes = value.split(',').map(number).collect::<Result<_, _>>()?;
            }
            "--plot" => args.plot = Some(flags.value(&flag)?),
            "--passes" => args.passes = flags.choice(&flag, &cli::PASSES)?,
            "--skin" => args.skin = flags.parse(&flag)?,
            "--placement" => {
                let placements = [("strict", Placement::Strict), ("loose", Placement::Loose)];
                args.placement = Some(flags.choice(&flag, &placements)?);
            }
            _ => return Err(Stop::unknown(&flag)),
        }
    }
    if args.moving.len() > 1 && !args.scene_given {
        args.scene = "idle".into();
    }
    if args.every && !matches!(args.scene.as_str(), "fall" | "all") {
        return Err(format!("--every applies to fall, not {}", args.scene).into());
    }
    Ok(args)
}

/// Unrecorded rapier steps that let the `pile` scene settle before its frames are recorded.
const PILE_SETTLE_STEPS: usize = 240;

/// `--scene all` runs these scenes, then `idle` at each of [`ALL_IDLE_MOVING`].
const ALL_SCENES: [&str; 11] = [
    "gas",
    "clustered",
    "bodies",
    "churn",
    "pile",
    "fall",
    "far",
    "open",
    "sparse",
    "large",
    "flying",
];

/// `--scene all` runs `idle` at each of these percentages of movers.
const ALL_IDLE_MOVING: [f64; 2] = [1.0, 10.0];

/// `moving` is the percentage of movers for `idle` and `bodies`, ignored by the others.
fn make_scene(
    name: &str,
    n: usize,
    seed: u64,
    steps: usize,
    moving: f64,
) -> Option<Box<dyn Scene>> {
    Some(match name {
        "pile" => Box::new(record_pile(n, seed, PILE_SETTLE_STEPS, steps + 1)),
        "gas" => Box::new(Gas::new(n, seed)),
        "clustered" => Box::new(Gas::clustered(n, seed)),
        "bodies" => Box::new(Bodies::with_moving(n, seed, moving)),
        "churn" => Box::new(Churn::new(n, seed)),
        "idle" => Box::new(Idle::new(n, seed, moving)),
        "far" => Box::new(Gas::far(n, seed)),
        "open" => Box::new(Gas::open(n, seed)),
        "sparse" => Box::new(Gas::sparse(n, seed)),
        "large" => Box::new(Gas::large(n, seed)),
        "flying" => Box::new(Flying::new(n, seed)),
        _ => return None,
    })
}

/// The percentages of movers a scene runs at: `--moving`, else its default (`idle` 1 %,
/// `bodies` 100 %); `None` for a scene without movers.
fn moving_for(scene: &str, args: &Args) -> Result<Vec<Option<f64>>, String> {
    let default = match scene {
        "idle" => 1.0,
        "bodies" => 100.0,
        _ if args.moving.is_empty() => return Ok(vec![None]),
        _ => return Err(format!("--moving applies to idle and bodies, not {scene}")),
    };
    if args.moving.is_empty() {
        Ok(vec![Some(default)])
    } else {
        Ok(args.moving.iter().map(|&p| Some(p)).collect())
    }
}

/// The table's scene cell: the name, with the percentage of movers for `idle` and for
/// `bodies` when not every box moves.
fn label(scene: &str, moving: Option<f64>) -> String {
    match moving {
        Some(p) if scene == "idle" || p < 100.0 => format!("{scene} {p}%"),
        _ => scene.to_string(),
    }
}

fn default_n(scene: &str) -> usize {
    match scene {
        "fall" => 4000,
        "bodies" | "pile" => 10_000,
        _ => 100_000,
    }
}

/// How many threads broadleaf's step may use: rayon's current pool with the feature
/// `parallel` (set by `RAYON_NUM_THREADS`), else 1.
fn broadleaf_threads() -> usize {
    #[cfg(feature = "parallel")]
    {
        rayon::current_num_threads()
    }
    #[cfg(not(feature = "parallel"))]
    {
        1
    }
}

impl Args {
    /// The broadphase's configuration: the defaults (no region: the octree's follows the
    /// spheres) but for what the flags set.
    fn config(&self) -> Config {
        let d = Config::default();
        Config {
            octree_placement: self.placement.unwrap_or(d.octree_placement),
            skin: self.skin,
            passes: self.passes,
            ..d
        }
    }
}

/// broadleaf's side: the broadphase and the key of each scene id.
struct Ours {
    bp: BroadPhase,
    feed: Feed,
}

impl Ours {
    fn new(args: &Args) -> Self {
        Ours {
            bp: BroadPhase::new(args.config()),
            feed: Feed::new(false)
                .per_object(args.per_object)
                .groups(args.groups),
        }
    }
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    let m = v.len() / 2;
    if v.len() % 2 == 1 {
        v[m]
    } else {
        0.5 * (v[m - 1] + v[m])
    }
}

struct Row {
    scene: String,
    /// The scene's name without the percentage of movers.
    name: String,
    /// Percentage of movers (`idle`, `bodies`).
    moving: Option<f64>,
    n: usize,
    ours_ns: f64,
    rapier_ns: f64,
    cmp: Comparison,
    /// More to print after the table (the `fall` scene's phases).
    detail: Option<String>,
}

/// Both engines with `scene`'s objects inserted and one step taken; also the spawns.
fn spawn_both(scene: &dyn Scene, args: &Args) -> (Ours, SceneWorld, Vec<Spawn>) {
    let mut ours = Ours::new(args);
    let mut theirs = SceneWorld::new().groups(args.groups);
    let mut spawns = Vec::new();
    scene.spawns(&mut spawns);
    ours.feed
        .spawn(&mut ours.bp, &spawns)
        .expect("scene objects are finite");
    for s in &spawns {
        theirs.insert(s);
    }
    ours.bp.step();
    theirs.step();
    (ours, theirs, spawns)
}

fn run(name: &str, n: usize, moving: Option<f64>, args: &Args) -> Row {
    if name == "fall" {
        return run_fall(n, args);
    }
    let steps = args.warmup + args.steps;
    let mut scene =
        make_scene(name, n, args.seed, steps, moving.unwrap_or(100.0)).expect("known scene");
    let name = &match args.groups {
        0 => label(name, moving),
        g => format!("{} ({g} groups)", label(name, moving)),
    };
    let (mut ours, mut theirs, mut spawns) = spawn_both(&*scene, args);
    // The motion is generated up front, so each engine can run its steps back to back (a
    // real program runs one broadphase, and alternating the two per step makes each pay for
    // the other evicting its caches); `--interleave` alternates them as before.
    let mut frames = Vec::with_capacity(steps);
    let mut live = Vec::with_capacity(steps);
    for _ in 0..steps {
        let mut frame = Frame::default();
        scene.advance(&mut frame);
        frames.push(frame);
        live.push(scene.len().max(1) as f64);
    }
    let (mut ours_ns, mut rapier_ns) = (Vec::new(), Vec::new());
    let mut last_pairs = Vec::new();
    // `BROADLEAF_TRACE=1` prints every step's time and StepStats on stderr.
    let trace = std::env::var_os("BROADLEAF_TRACE").is_some();
    let live_now = scene.len().max(1) as f64;
    let mut ours_step = |frame: &Frame| {
        // The frame's batches (keys, centres, boxes) are built before the timer starts, as an
        // engine's arrays are ready before its broadphase runs and as rapier's pose writes
        // happen outside its counter; the timer covers the library's calls only.
        ours.feed.stage(frame).expect("scene frames are valid");
        let t = Instant::now();
        ours.feed
            .commit(&mut ours.bp, frame)
            .expect("scene frames are valid");
        ours.bp.step();
        let ns = t.elapsed().as_nanos() as f64;
        last_pairs.clear();
        last_pairs.extend_from_slice(ours.bp.pairs());
        if trace {
            eprintln!("{:.1} ns/object {:?}", ns / live_now, ours.bp.stats());
        }
        ns
    };
    let mut theirs_step = |frame: &Frame| {
        theirs.set_targets(frame);
        let ns = theirs.step().as_nanos() as f64;
        theirs.apply_structure(frame);
        ns
    };
    if args.interleave {
        for (k, frame) in frames.iter().enumerate() {
            let (a, b) = (ours_step(frame), theirs_step(frame));
            if k >= args.warmup {
                ours_ns.push(a / live[k]);
                rapier_ns.push(b / live[k]);
            }
        }
    } else {
        for (k, frame) in frames.iter().enumerate() {
            let a = ours_step(frame);
            if k >= args.warmup {
                ours_ns.push(a / live[k]);
            }
        }
        for (k, frame) in frames.iter().enumerate() {
            let b = theirs_step(frame);
            if k >= args.warmup {
                rapier_ns.push(b / live[k]);
            }
        }
    }
    // On stderr, so the table stays as other tools read it: how the adaptive step went.
    eprintln!("{name}: broadleaf's last step: {:?}", ours.bp.stats());
    // rapier detects the last frame's poses (and holds its inserts) in one more step.
    theirs.step();
    let (rapier_pairs, unmapped) = theirs.pairs(&ours.feed);
    // The reference: the scene's own objects after the last frame (the state both engines were
    // given), not the broadphase's record of them.
    spawns.clear();
    scene.spawns(&mut spawns);
    let proxies = ours
        .feed
        .brute_proxies(&spawns, ours.bp.config().margin)
        .expect("the feed holds every live scene object");
    let mut exact = brute::sweep_pairs(&proxies);
    ours.feed.retain_allowed(&spawns, &mut exact);
    let mut cmp = Comparison::new(&last_pairs, &rapier_pairs, &exact);
    cmp.unmapped = unmapped;
    Row {
        scene: name.to_string(),
        name: name.split(' ').next().unwrap_or(name).to_string(),
        moving,
        n: scene.len(),
        ours_ns: median(&mut ours_ns),
        rapier_ns: median(&mut rapier_ns),
        cmp,
        detail: None,
    }
}

/// Steps in the `fall` scene's sliding window, for its worst-window ratio.
const FALL_WINDOW: usize = 30;

/// `fall`: rapier's recorded drop of `n` balls replayed through broadleaf. Per frame the batch
/// (the keys and centres of the changed balls, or with `--every` of all balls) is built
/// first; the timer covers `update_centers` and `step()` only. Frame 0 times inserting the
/// balls (the walls are in from the start) and the first step, as rapier's first step builds
/// its tree. Every frame's pairs are checked against brute force, untimed. The row holds the
/// whole run's means; its phase table is the row's `detail`.
fn run_fall(n: usize, args: &Args) -> Row {
    let rec = record_fall(&DropConfig::new(n, GAS_RADIUS, args.seed), fall_steps(n))
        .unwrap_or_else(|e| cli::fail(USAGE, &format!("--n {n}: {e}")));
    let mut bp = BroadPhase::new(args.config());
    let walls: Vec<ProxyKey> = rec
        .walls
        .iter()
        .map(|&w| bp.insert_body(w, BodyKind::Static).expect("finite walls"))
        .collect();
    let objects = rec.balls() + walls.len();
    let mut feed = CentersFeed::default();
    let mut ours_ns = Vec::with_capacity(rec.frames());
    let (mut missed, mut extra, mut differ, mut cmp) = (0, 0, 0, Comparison::default());
    let trace = std::env::var_os("BROADLEAF_TRACE").is_some();
    for k in 0..rec.frames() {
        let (ids, moved) = rec.changed(k);
        let ns = if k == 0 {
            feed.stage_first(moved);
            let t = Instant::now();
            feed.insert(&mut bp, rec.radius).expect("finite balls");
            bp.step();
            t.elapsed()
        } else {
            feed.stage(ids, moved, args.every);
            let t = Instant::now();
            feed.commit(&mut bp).expect("valid batches");
            bp.step();
            t.elapsed()
        };
        ours_ns.push(ns.as_nanos() as f64 / objects as f64);
        if trace {
            eprintln!("{k}: {:.1} ns/object {:?}", ours_ns[k], bp.stats());
        }
        let exact = fall_exact(&bp, &rec, &feed.balls, &walls, &feed.centers);
        // Against brute force alone (rapier's pairs of its dynamic run are not recorded):
        // `missed` = exact \ ours, `extra` = ours \ exact.
        cmp = Comparison::new(bp.pairs(), &exact, &exact);
        missed += cmp.missed;
        extra += cmp.extra;
        differ += usize::from(!cmp.ours_equals_exact);
    }
    eprintln!("fall: broadleaf's last step: {:?}", bp.stats());
    let rapier_ns: Vec<f64> = rec
        .broad_phase_time
        .iter()
        .map(|t| t.as_nanos() as f64 / objects as f64)
        .collect();
    let detail = fall_table(&rec, &ours_ns, &rapier_ns, args.every)
        + &format!(
            "pairs checked against brute force at every frame ({} frames): missed {missed}, \
             extra {extra}, frames that differ {differ}\n",
            rec.frames()
        );
    (cmp.missed, cmp.extra) = (missed, extra);
    Row {
        scene: if args.every { "fall --every" } else { "fall" }.to_string(),
        name: "fall".to_string(),
        moving: None,
        n: objects,
        ours_ns: mean(&ours_ns),
        rapier_ns: mean(&rapier_ns),
        cmp,
        detail: Some(detail),
    }
}

/// The exact pairs of a `fall` frame from the recorded centres and walls (each grown by the
/// margin), not from the broadphase.
fn fall_exact(
    bp: &BroadPhase,
    rec: &FallRecording,
    balls: &[ProxyKey],
    walls: &[ProxyKey],
    centers: &[Vec3],
) -> Vec<Pair> {
    let margin = bp.config().margin;
    let ball = |(&key, &c): (&ProxyKey, &Vec3)| {
        brute::Proxy::new(key, Aabb::from_center_radius(c, rec.radius + margin))
    };
    let wall = |(&key, w): (&ProxyKey, &Aabb)| brute::Proxy {
        key,
        aabb: w.grown(margin),
        is_static: true,
    };
    let proxies: Vec<brute::Proxy> = balls
        .iter()
        .zip(centers)
        .map(ball)
        .chain(walls.iter().zip(&rec.walls).map(wall))
        .collect();
    brute::sweep_pairs(&proxies)
}

fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len().max(1) as f64
}

/// The `fall` scene's phase table (means of ns/object/step over each phase's frames) and its
/// worst [`FALL_WINDOW`]-step window.
fn fall_table(rec: &FallRecording, ours: &[f64], rapier: &[f64], every: bool) -> String {
    use std::fmt::Write;
    let mut out = format!(
        "fall: {} balls (r = {} m) and {} walls, {} frames recorded from rapier (dynamic balls, \
         default parameters, sleeping on); broadleaf sent {} each frame; times: mean \
         ns/object/step over each phase\n\n\
         | phase | frames | steps | broadleaf ns/object/step | rapier ns/object/step | speed-up |\n\
         |---|---|---:|---:|---:|---:|\n",
        rec.balls(),
        rec.radius,
        rec.walls.len(),
        rec.frames(),
        if every {
            "every ball"
        } else {
            "the balls that moved"
        },
    );
    for (phase, range) in rec.phases().rows() {
        let (a, b) = (mean(&ours[range.clone()]), mean(&rapier[range.clone()]));
        let _ = writeln!(
            out,
            "| {phase} | {}–{} | {} | {a:.1} | {b:.1} | {:.2} |",
            range.start,
            range.end,
            range.len(),
            b / a
        );
    }
    let window = FALL_WINDOW.min(ours.len());
    let worst = (0..=ours.len() - window)
        .map(|s| {
            let (a, b) = (mean(&ours[s..s + window]), mean(&rapier[s..s + window]));
            (s, b / a, a, b)
        })
        .min_by(|x, y| x.1.total_cmp(&y.1));
    if let Some((s, ratio, a, b)) = worst {
        let _ = writeln!(
            out,
            "\nworst {window}-step window: frames {s}–{}, speed-up {ratio:.2} (broadleaf {a:.1}, \
             rapier {b:.1} ns/object/step)",
            s + window
        );
    }
    out
}

fn main() {
    let args = cli::or_exit(USAGE, parse_args(std::env::args().skip(1)));
    if args.queries {
        let mismatches = run_queries(&args);
        println!("queries mismatches={mismatches}");
        return;
    }
    let names: Vec<(&str, Option<f64>)> = match args.scene.as_str() {
        "all" => ALL_SCENES
            .map(|name| (name, None))
            .into_iter()
            .chain(ALL_IDLE_MOVING.map(|p| ("idle", Some(p))))
            .collect(),
        s if s == "fall" || make_scene(s, 0, 0, 0, 0.0).is_some() => {
            let moving = moving_for(s, &args).unwrap_or_else(|e| cli::fail(USAGE, &e));
            moving.into_iter().map(|p| (s, p)).collect()
        }
        s => cli::fail(USAGE, &format!("unknown scene {s}")),
    };
    let config = args.config();
    println!(
        "spheres in the octree (region and depth follow the spheres, {:?} placement), bodies in the BVHs (rebuild at {}× \
         the built SAH cost), skin {}, passes {:?}, {} measured steps after {} warm-up, seed {}, \
         {}; times: median ns/object/step",
        config.octree_placement,
        config.rebuild_threshold,
        config.skin,
        config.passes,
        args.steps,
        args.warmup,
        args.seed,
        if args.interleave {
            "engines alternating per step"
        } else {
            "each engine's steps back to back"
        }
    );
    println!("broadleaf threads: {}", broadleaf_threads());
    println!();
    println!(
        "| scene | N | broadleaf ns/object/step | rapier ns/object/step | speed-up | pairs (broadleaf) | pairs (rapier) | exact pairs | missed | extra |"
    );
    println!("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|");
    let mut rows = Vec::new();
    let runs: Vec<(&str, usize, Option<f64>)> = if args.sizes.is_empty() {
        names
            .iter()
            .map(|&(name, p)| (name, args.n.unwrap_or_else(|| default_n(name)), p))
            .collect()
    } else {
        names
            .iter()
            .flat_map(|&(name, p)| args.sizes.iter().map(move |&n| (name, n, p)))
            .collect()
    };
    for (name, n, moving) in runs {
        let r = run(name, n, moving, &args);
        println!(
            "| {} | {} | {:.1} | {:.1} | {:.2} | {} | {} | {} | {} | {} |",
            r.scene,
            r.n,
            r.ours_ns,
            r.rapier_ns,
            r.rapier_ns / r.ours_ns,
            r.cmp.ours,
            r.cmp.rapier,
            r.cmp.exact,
            r.cmp.missed,
            r.cmp.extra
        );
        rows.push(r);
    }
    println!();
    for detail in rows.iter().filter_map(|r| r.detail.as_ref()) {
        println!("{detail}");
    }
    if args.groups > 0 {
        println!(
            "groups: every object of a scene in group (scene id mod {g}) of {g}, pairing only \
             within it (memberships = filter = 1 << (id % {g})): broadleaf `set_groups` on \
             insert, rapier the same InteractionGroups (And) on its colliders, the brute force \
             filtered by the same rule",
            g = args.groups
        );
        println!();
    }
    for r in &rows {
        if !r.cmp.holds() {
            println!(
                "WARNING {}: the cross-check does not hold: {}",
                r.scene, r.cmp
            );
        }
    }
    if let Some(path) = &args.plot {
        let by_moving = args.moving.len() > 1;
        let drawn = if by_moving {
            plot_moving(&rows, path)
        } else {
            plot_sizes(&rows, path)
        };
        match drawn {
            Ok(()) => println!("wrote {path}"),
            Err(e) => eprintln!("cannot write {path}: {e}"),
        }
    }
    let ratio = rows
        .iter()
        .map(|r| r.rapier_ns / r.ours_ns)
        .fold(f64::INFINITY, f64::min);
    let missed: usize = rows.iter().map(|r| r.cmp.missed).sum();
    let extra: usize = rows.iter().map(|r| r.cmp.extra).sum();
    println!("ratio={ratio:.2} missed={missed} extra={extra}");
}

/// Size of the plots in pixels.
const PLOT_SIZE: (u32, u32) = (820, 500);
/// Room right of the plot area, in pixels, so the last x label is not cut off.
const PLOT_RIGHT_MARGIN: u32 = 40;

/// A log axis's tick label: only 1, 2 and 5 times a power of ten are written, so the ticks
/// that crowd at the top of each decade stay unlabelled.
fn log_label(v: f64) -> String {
    let mantissa = v / 10f64.powf(v.log10().floor());
    if [1.0, 2.0, 5.0, 10.0]
        .iter()
        .any(|m| (mantissa - m).abs() < 1e-6)
    {
        format!("{v}")
    } else {
        String::new()
    }
}

/// A plot's engine: name, colour, and which time of a row it draws.
type Engine = (&'static str, RGBColor, fn(&Row) -> f64);

fn ours_ns(r: &Row) -> f64 {
    r.ours_ns
}

fn rapier_ns(r: &Row) -> f64 {
    r.rapier_ns
}

const ENGINES: [Engine; 2] = [
    ("broadleaf", RGBColor(0x2a, 0x9d, 0x8f), ours_ns),
    ("rapier", RGBColor(0xe7, 0x6f, 0x51), rapier_ns),
];

type Plotted = Result<(), Box<dyn std::error::Error>>;

/// The whole decades around every value of `v` (positive values), for a log axis.
fn decades(v: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) = v
        .filter(|x| *x > 0.0)
        .fold((f64::INFINITY, 0.0f64), |(lo, hi), x| {
            (lo.min(x), hi.max(x))
        });
    if lo > hi {
        return (1.0, 10.0);
    }
    let (lo, hi) = (
        10f64.powf(lo.log10().floor()),
        10f64.powf(hi.log10().ceil()),
    );
    (lo, if hi > lo { hi } else { lo * 10.0 })
}

/// One series: a line (solid for the first group, dashed after) with a dot at each point,
/// and its legend entry.
fn series<X, Y>(
    chart: &mut ChartContext<'_, SVGBackend<'_>, Cartesian2d<X, Y>>,
    points: Vec<(f64, f64)>,
    colour: RGBColor,
    dashed: bool,
    name: String,
) -> Plotted
where
    X: Ranged<ValueType = f64>,
    Y: Ranged<ValueType = f64>,
{
    let style = colour.stroke_width(2);
    let legend = move |(x, y): (i32, i32)| PathElement::new(vec![(x, y), (x + 20, y)], style);
    if dashed {
        chart
            .draw_series(DashedLineSeries::new(points.clone(), 6, 4, style))?
            .label(name)
            .legend(legend);
    } else {
        chart
            .draw_series(LineSeries::new(points.clone(), style))?
            .label(name)
            .legend(legend);
    }
    chart.draw_series(
        points
            .into_iter()
            .map(|p| Circle::new(p, 3, colour.filled())),
    )?;
    Ok(())
}

/// ns/object/step against N (`--sizes`), both axes logarithmic since the sizes span
/// decades; one line per engine and scene.
fn plot_sizes(rows: &[Row], path: &str) -> Plotted {
    let (x0, x1) = decades(rows.iter().map(|r| r.n as f64));
    let (y0, y1) = decades(rows.iter().flat_map(|r| [r.ours_ns, r.rapier_ns]));
    let root = SVGBackend::new(path, PLOT_SIZE).into_drawing_area();
    root.fill(&WHITE)?;
    let mut chart = ChartBuilder::on(&root)
        .caption("one broadphase step against N", ("sans-serif", 20))
        .margin(12)
        .margin_right(PLOT_RIGHT_MARGIN)
        .x_label_area_size(45)
        .y_label_area_size(70)
        .build_cartesian_2d((x0..x1).log_scale(), (y0..y1).log_scale())?;
    chart
        .configure_mesh()
        .x_desc("objects N")
        .y_desc("ns / object / step")
        .x_label_formatter(&|x| log_label(*x))
        .y_label_formatter(&|y| log_label(*y))
        .draw()?;
    let mut scenes: Vec<&str> = rows.iter().map(|r| r.scene.as_str()).collect();
    scenes.dedup();
    for (k, scene) in scenes.iter().enumerate() {
        for (engine, colour, value) in ENGINES {
            let points = rows
                .iter()
                .filter(|r| r.scene == *scene)
                .map(|r| (r.n as f64, value(r)))
                .collect();
            series(
                &mut chart,
                points,
                colour,
                k > 0,
                format!("{engine} {scene}"),
            )?;
        }
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .draw()?;
    root.present()?;
    Ok(())
}

/// ns/object/step against the percentage of movers (`--moving`), on a linear P axis (P = 0 is
/// a point like any other) and a logarithmic time axis (the engines differ by up to a
/// decade); one line per engine and scene size, and for broadleaf the no-cliff bound of
/// `benchmarks.md` (1.1 × its time at the largest P) as a dotted line.
fn plot_moving(rows: &[Row], path: &str) -> Plotted {
    let p_of = |r: &Row| r.moving.unwrap_or(100.0);
    let x1 = rows.iter().map(p_of).fold(1.0, f64::max);
    let (y0, y1) = decades(rows.iter().flat_map(|r| [r.ours_ns, r.rapier_ns]));
    let root = SVGBackend::new(path, PLOT_SIZE).into_drawing_area();
    root.fill(&WHITE)?;
    let mut chart = ChartBuilder::on(&root)
        .caption(
            "one broadphase step against the share of objects moving",
            ("sans-serif", 20),
        )
        .margin(12)
        .margin_right(PLOT_RIGHT_MARGIN)
        .x_label_area_size(45)
        .y_label_area_size(70)
        .build_cartesian_2d(0.0..x1, (y0..y1).log_scale())?;
    chart
        .configure_mesh()
        .x_desc("objects moving per step, %")
        .y_desc("ns / object / step (all objects)")
        .x_label_formatter(&|x| format!("{x:.0}"))
        .y_label_formatter(&|y| log_label(*y))
        .draw()?;
    let mut groups: Vec<(String, usize)> = rows.iter().map(|r| (r.name.clone(), r.n)).collect();
    groups.dedup();
    for (k, (name, n)) in groups.iter().enumerate() {
        let of_group: Vec<&Row> = rows
            .iter()
            .filter(|r| r.name == *name && r.n == *n)
            .collect();
        for (engine, colour, value) in ENGINES {
            let mut points: Vec<(f64, f64)> =
                of_group.iter().map(|r| (p_of(r), value(r))).collect();
            points.sort_by(|a, b| a.0.total_cmp(&b.0));
            series(
                &mut chart,
                points,
                colour,
                k > 0,
                format!("{engine} {name} N={n}"),
            )?;
        }
        if let Some(full) = of_group.iter().max_by(|a, b| p_of(a).total_cmp(&p_of(b))) {
            let bound = NO_CLIFF * full.ours_ns;
            chart
                .draw_series(DashedLineSeries::new(
                    [(0.0, bound), (x1, bound)],
                    2,
                    4,
                    ENGINES[0].1.stroke_width(1),
                ))?
                .label(format!(
                    "{NO_CLIFF} × broadleaf at {}% ({name} N={n})",
                    p_of(full)
                ))
                .legend(|(x, y)| {
                    PathElement::new(vec![(x, y), (x + 20, y)], ENGINES[0].1.stroke_width(1))
                });
        }
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::LowerRight)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .draw()?;
    root.present()?;
    Ok(())
}

/// `benchmarks.md`'s no-cliff target: ns/object at any P at most this times the figure at
/// 100 % moving.
const NO_CLIFF: f64 = 1.1;

/// Box queries and rays `--queries` times per engine.
const QUERY_COUNT: usize = 100_000;
/// Edge range of the query cubes, in metres.
const QUERY_EDGE: (f32, f32) = (1.0, 4.0);
/// Every this many-th query is checked against the other engine.
const QUERY_CHECK_EVERY: usize = 100;
/// Largest difference of the two engines' ray or cast `t` (or nearest distance) that still
/// counts as the same answer.
const RAY_T_TOLERANCE: f32 = 1e-4;
/// How far from touching (in metres, the cast ball's distance to the box minus its radius,
/// either sign) rapier's sphere cast at a box may stop: it ends within a tolerance of the
/// contact, so its `t` may be a little early or late. Its answer still agrees if it names the
/// same box as broadleaf at a `t` where the ball is within this of touching it.
const RAPIER_CAST_GAP_TOLERANCE: f32 = 2e-3;
/// Radius of the spheres `--queries` casts, in metres.
const CAST_RADIUS: f32 = 0.25;

/// Whether the two engines' closest answers agree: both none, or the same value (`t` or
/// distance) within [`RAY_T_TOLERANCE`] and the same key, or a tie (as for a start inside two
/// overlapping spheres, both at 0) that rapier broke the other way: `value_of` rapier's key,
/// computed from the scene's own sphere, equals broadleaf's value within the tolerance.
fn same_closest(
    ours: Option<(ProxyKey, f32)>,
    rapier: Option<(Option<ProxyKey>, f32)>,
    value_of: impl Fn(ProxyKey) -> Option<f32>,
) -> bool {
    match (ours, rapier) {
        (None, None) => true,
        (Some((ka, va)), Some((Some(kr), vr))) => {
            (va - vr).abs() <= RAY_T_TOLERANCE
                && (ka == kr || value_of(kr).is_some_and(|v| (v - va).abs() <= RAY_T_TOLERANCE))
        }
        _ => false,
    }
}

/// A direction uniform on the unit sphere (rejection from the cube, then normalised).
fn unit_dir(rng: &mut Rng) -> Vec3 {
    loop {
        let v = rng.vec3_in(Vec3::splat(-1.0), Vec3::splat(1.0));
        let l2 = v.length_squared();
        if l2 > 1e-6 && l2 <= 1.0 {
            return v / l2.sqrt();
        }
    }
}

fn to_parry(b: &Aabb) -> rapier3d::parry::bounding_volume::Aabb {
    rapier3d::parry::bounding_volume::Aabb::new(b.min, b.max)
}

/// The world `--queries` asks: both engines over the same shapes after the scene's motion, the cube the queries are drawn in, and each key's shape as the scene gave
/// it (what brute force and rapier's ties are computed from, never the broadphase's record).
struct QueryWorld {
    ours: Ours,
    theirs: SceneWorld,
    bounds: Aabb,
    shapes: Vec<(ProxyKey, Object)>,
    /// The table's heading: the scene and its size.
    label: String,
}

/// `gas` (N spheres) after the warm-up steps: each engine applies the scene's frames.
fn gas_world(args: &Args) -> QueryWorld {
    let n = args.n.unwrap_or(100_000);
    let mut scene = Gas::new(n, args.seed);
    let (mut ours, mut theirs, _) = spawn_both(&scene, args);
    // The warm-up steps of motion (at least one), so the queries see a running world in its
    // steady regime, not the step that woke it; rapier's extra step moves nothing and leaves
    // its tree at the targets' poses.
    let mut frame = Frame::default();
    for _ in 0..args.warmup.max(1) {
        scene.advance(&mut frame);
        ours.feed
            .apply(&mut ours.bp, &frame)
            .expect("scene frames are valid");
        ours.bp.step();
        theirs.set_targets(&frame);
        theirs.step();
    }
    theirs.step();
    let mut spawns = Vec::new();
    scene.spawns(&mut spawns);
    let shapes = shapes_of(&ours, &spawns);
    QueryWorld {
        ours,
        theirs,
        bounds: scene.bounds,
        shapes,
        label: format!("gas N={n} after {} steps", args.warmup.max(1)),
    }
}

/// `bodies` (N dynamic boxes, N/10 static ones and the floor) after one step of the scene's
/// motion, each box given to both engines as its world AABB: broadleaf answers queries on a
/// body's box, so rapier gets an axis-aligned cuboid of exactly that box.
fn bodies_world(args: &Args) -> QueryWorld {
    let n = args.n.unwrap_or_else(|| default_n("bodies"));
    let mut scene = Bodies::new(n, args.seed);
    scene.advance(&mut Frame::default());
    let mut spawns = Vec::new();
    scene.spawns(&mut spawns);
    for s in &mut spawns {
        s.object = s.object.boxed();
    }
    let mut ours = Ours::new(args);
    let mut theirs = SceneWorld::new().groups(args.groups);
    ours.feed
        .spawn(&mut ours.bp, &spawns)
        .expect("scene objects are finite");
    for s in &spawns {
        theirs.insert(s);
    }
    ours.bp.step();
    theirs.step();
    let shapes = shapes_of(&ours, &spawns);
    QueryWorld {
        ours,
        theirs,
        bounds: scene.bounds,
        shapes,
        label: format!(
            "bodies N={n} (+{} static) after one step",
            scene.statics.len()
        ),
    }
}

/// Each spawned object under its broadleaf key.
fn shapes_of(ours: &Ours, spawns: &[Spawn]) -> Vec<(ProxyKey, Object)> {
    spawns
        .iter()
        .filter_map(|s| Some((ours.feed.key(s.id)?, s.object)))
        .collect()
}

/// The shape broadleaf answers about: a sphere as itself, a box as its world AABB.
fn ray_t(o: &Object, origin: Vec3, dir: Vec3, max_t: f32) -> Option<f32> {
    match *o {
        Object::Sphere { center, radius } => geom::ray_sphere(origin, dir, center, radius, max_t),
        Object::Cuboid { .. } => o.aabb().ray_entry(origin, geom::inverse_dir(dir), max_t),
    }
}

/// The first touch of a sphere of `radius` cast from `origin` along `dir` with `o`.
fn cast_t(o: &Object, origin: Vec3, radius: f32, dir: Vec3, max_t: f32) -> Option<f32> {
    match *o {
        Object::Sphere { center, radius: r } => {
            geom::sphere_cast_sphere(origin, radius, dir, max_t, center, r)
        }
        Object::Cuboid { .. } => geom::sphere_cast_aabb(origin, radius, dir, max_t, &o.aabb()),
    }
}

/// The distance from `p` to `o` (0 inside).
fn distance_to(o: &Object, p: Vec3) -> f32 {
    match *o {
        Object::Sphere { center, radius } => geom::point_sphere_distance(p, center, radius),
        Object::Cuboid { .. } => geom::point_aabb_distance(p, &o.aabb()),
    }
}

/// Brute force over every shape: the smallest `(value, key)` of `value_of`.
fn brute_min(
    shapes: &[(ProxyKey, Object)],
    value_of: impl Fn(&Object) -> Option<f32>,
) -> Option<(ProxyKey, f32)> {
    shapes
        .iter()
        .filter_map(|(k, o)| Some((*k, value_of(o)?)))
        .min_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)))
}

/// `--queries`: prints the query table of `--scene` (`gas` or `bodies`) and returns the
/// number of sampled queries on which broadleaf disagrees with rapier or with brute force.
fn run_queries(args: &Args) -> usize {
    let world = match args.scene.as_str() {
        "gas" => gas_world(args),
        "bodies" => bodies_world(args),
        s => cli::fail(USAGE, &format!("--queries runs on gas or bodies, not {s}")),
    };
    let QueryWorld {
        ours,
        theirs,
        bounds,
        shapes,
        label,
    } = &world;
    let bounds = *bounds;
    let mut rng = Rng::new(args.seed ^ 0x7175_6572_7973);
    let boxes: Vec<Aabb> = (0..QUERY_COUNT)
        .map(|_| {
            let c = rng.vec3_in(bounds.min, bounds.max);
            let half = 0.5 * rng.range(QUERY_EDGE.0, QUERY_EDGE.1);
            Aabb::from_center_half_extents(c, Vec3::splat(half))
        })
        .collect();
    let max_t = bounds.extent().x;
    let rays: Vec<(Vec3, Vec3)> = (0..QUERY_COUNT)
        .map(|_| (rng.vec3_in(bounds.min, bounds.max), unit_dir(&mut rng)))
        .collect();
    let casts: Vec<(Vec3, Vec3)> = (0..QUERY_COUNT)
        .map(|_| (rng.vec3_in(bounds.min, bounds.max), unit_dir(&mut rng)))
        .collect();
    let points: Vec<Vec3> = (0..QUERY_COUNT)
        .map(|_| rng.vec3_in(bounds.min, bounds.max))
        .collect();
    let ball = Ball::new(CAST_RADIUS);
    // Like broadleaf's cast: a start touching or overlapping is a hit at t = 0, and the
    // contact geometry broadleaf does not compute is not asked for there either.
    let cast_options = ShapeCastOptions {
        max_time_of_impact: max_t,
        target_distance: 0.0,
        stop_at_penetration: true,
        compute_impact_geometry_on_penetration: false,
    };
    let qp = theirs.query_pipeline();
    let rapier_box = |b: &Aabb, mut f: Box<dyn FnMut(rapier3d::geometry::ColliderHandle) + '_>| {
        let q = to_parry(b);
        for (h, co) in qp.intersect_aabb_conservative(q) {
            if co.compute_aabb().intersects(&q) {
                f(h);
            }
        }
    };

    let per_query = |t: Instant| t.elapsed().as_nanos() as f64 / QUERY_COUNT as f64;
    let (mut ours_hits, mut rapier_hits) = (0usize, 0usize);
    let t = Instant::now();
    for b in &boxes {
        ours.bp.query_aabb(b, |_| ours_hits += 1);
    }
    let ours_box = per_query(t);
    let t = Instant::now();
    for b in &boxes {
        let q = to_parry(b);
        rapier_hits += qp
            .intersect_aabb_conservative(q)
            .filter(|(_, co)| co.compute_aabb().intersects(&q))
            .count();
    }
    let rapier_box_ns = per_query(t);
    let (mut ours_rays, mut rapier_rays) = (0usize, 0usize);
    let t = Instant::now();
    for &(o, d) in &rays {
        ours_rays += usize::from(black_box(ours.bp.cast_ray(o, d, max_t)).is_some());
    }
    let ours_ray = per_query(t);
    let t = Instant::now();
    for &(o, d) in &rays {
        let hit = qp.cast_ray(&Ray::new(o, d), max_t, true);
        rapier_rays += usize::from(black_box(hit).is_some());
    }
    let rapier_ray = per_query(t);
    let (mut ours_casts, mut rapier_casts) = (0usize, 0usize);
    let t = Instant::now();
    for &(o, d) in &casts {
        let hit = ours.bp.cast_sphere(o, CAST_RADIUS, d, max_t);
        ours_casts += usize::from(black_box(hit).is_some());
    }
    let ours_cast = per_query(t);
    let t = Instant::now();
    for &(o, d) in &casts {
        let hit = qp.cast_shape(&Pose::from_translation(o), d, &ball, cast_options);
        rapier_casts += usize::from(black_box(hit).is_some());
    }
    let rapier_cast = per_query(t);
    let (mut ours_near, mut rapier_near) = (0usize, 0usize);
    let t = Instant::now();
    for &p in &points {
        ours_near += black_box(ours.bp.nearest(p, 1)).len();
    }
    let ours_nearest = per_query(t);
    let t = Instant::now();
    for &p in &points {
        let hit = qp.project_point(p, f32::MAX, true);
        rapier_near += usize::from(black_box(hit).is_some());
    }
    let rapier_nearest = per_query(t);

    // The sample: every QUERY_CHECK_EVERY-th query, both engines' answers in broadleaf keys,
    // and brute force over the scene's own shapes (ties to the smaller key, as broadleaf).
    let key_of = |h| theirs.scene_id(h).and_then(|id| ours.feed.key(id));
    let shape_of: HashMap<ProxyKey, Object> = shapes.iter().copied().collect();
    let (mut box_bad, mut ray_bad, mut checked) = (0, 0, 0);
    let (mut cast_bad, mut near_bad) = (0, 0);
    let mut brute_bad = [0usize; 4];
    for b in boxes.iter().step_by(QUERY_CHECK_EVERY) {
        let mut a: Vec<ProxyKey> = Vec::new();
        ours.bp.query_aabb(b, |k| a.push(k));
        let mut r: Vec<Option<ProxyKey>> = Vec::new();
        rapier_box(b, Box::new(|h| r.push(key_of(h))));
        let mut want: Vec<ProxyKey> = shapes
            .iter()
            .filter(|(_, o)| o.aabb().overlaps(b))
            .map(|&(k, _)| k)
            .collect();
        a.sort_unstable();
        want.sort_unstable();
        brute_bad[0] += usize::from(a != want);
        let mut a: Vec<Option<ProxyKey>> = a.into_iter().map(Some).collect();
        a.sort_unstable();
        r.sort_unstable();
        box_bad += usize::from(a != r);
        checked += 1;
    }
    for &(o, d) in rays.iter().step_by(QUERY_CHECK_EVERY) {
        let a = ours.bp.cast_ray(o, d, max_t);
        let r = qp
            .cast_ray(&Ray::new(o, d), max_t, true)
            .map(|(h, t)| (key_of(h), t));
        // A tie (two shapes hit at the same t, e.g. an origin inside two overlapping shapes,
        // both t = 0) may go to either: rapier's pick agrees if the scene's shape of that key
        // is hit at the same t.
        let t_of = |k: ProxyKey| ray_t(shape_of.get(&k)?, o, d, max_t);
        let same = same_closest(a, r, t_of);
        if !same {
            eprintln!("ray mismatch: origin {o} dir {d}: broadleaf {a:?}, rapier {r:?}");
        }
        ray_bad += usize::from(!same);
        let want = brute_min(shapes, |s| ray_t(s, o, d, max_t));
        if a != want {
            eprintln!("ray differs from brute force: origin {o} dir {d}: {a:?}, brute {want:?}");
        }
        brute_bad[1] += usize::from(a != want);
    }
    for &(o, d) in casts.iter().step_by(QUERY_CHECK_EVERY) {
        let a = ours.bp.cast_sphere(o, CAST_RADIUS, d, max_t);
        let r = qp
            .cast_shape(&Pose::from_translation(o), d, &ball, cast_options)
            .map(|(h, hit)| (key_of(h), hit.time_of_impact));
        let t_of = |k: ProxyKey| cast_t(shape_of.get(&k)?, o, CAST_RADIUS, d, max_t);
        // The cast sphere's distance to the key's shape at `t` (the radius at an exact first
        // touch).
        let gap = |k: ProxyKey, t: f32| Some(distance_to(shape_of.get(&k)?, o + t * d));
        // Rapier casts a ball at a box iteratively and stops once the distance is within its
        // tolerance of the radius: its `t` may be off by the time that tolerance takes.
        let near_touch = match (a, r) {
            (Some((ka, _)), Some((Some(kr), tr))) => {
                ka == kr
                    && gap(kr, tr)
                        .is_some_and(|g| (g - CAST_RADIUS).abs() <= RAPIER_CAST_GAP_TOLERANCE)
            }
            _ => false,
        };
        let same = same_closest(a, r, t_of) || near_touch;
        if !same {
            // The cast sphere's distance to the key's shape at each engine's t (the radius at
            // an exact first touch).
            eprintln!(
                "sphere cast mismatch: origin {o} dir {d}: broadleaf {a:?} (gap {:?}), rapier \
                 {r:?} (gap {:?})",
                a.and_then(|(k, t)| gap(k, t)),
                r.and_then(|(k, t)| gap(k?, t))
            );
        }
        cast_bad += usize::from(!same);
        let want = brute_min(shapes, |s| cast_t(s, o, CAST_RADIUS, d, max_t));
        if a != want {
            eprintln!(
                "sphere cast differs from brute force: origin {o} dir {d}: {a:?}, brute {want:?}"
            );
        }
        brute_bad[2] += usize::from(a != want);
    }
    for &p in points.iter().step_by(QUERY_CHECK_EVERY) {
        let a = ours.bp.nearest(p, 1).first().copied();
        // Solid: a point inside a shape projects onto itself, distance 0 as in broadleaf.
        let r = qp
            .project_point(p, f32::MAX, true)
            .map(|(h, proj)| (key_of(h), p.distance(proj.point)));
        let d_of = |k: ProxyKey| Some(distance_to(shape_of.get(&k)?, p));
        let same = same_closest(a, r, d_of);
        if !same {
            eprintln!("nearest mismatch: point {p}: broadleaf {a:?}, rapier {r:?}");
        }
        near_bad += usize::from(!same);
        let want = brute_min(shapes, |s| Some(distance_to(s, p)));
        if a != want {
            eprintln!("nearest differs from brute force: point {p}: {a:?}, brute {want:?}");
        }
        brute_bad[3] += usize::from(a != want);
    }

    println!(
        "queries on {label}, seed {}, {QUERY_COUNT} of each; rapier: \
         query pipeline of its BroadPhaseBvh (boxes: intersect_aabb_conservative re-tested \
         against each collider's exact AABB; rays: cast_ray, solid); checked: every \
         {QUERY_CHECK_EVERY}th query, against rapier and against brute force (the same key \
         and the same t or distance, ties to the smaller key)",
        args.seed
    );
    println!(
        "sphere casts: radius {CAST_RADIUS} m, origins and directions drawn like the rays', \
         rapier cast_shape with a Ball (stop at penetration: t = 0 for a start touching, like \
         broadleaf); nearest: points uniform in the cube, broadleaf nearest(p, 1) against \
         rapier project_point (solid), its distance |p - projection|"
    );
    println!();
    println!(
        "| query | count | broadleaf ns/query | rapier ns/query | speed-up | hits (broadleaf) | hits (rapier) | checked | mismatches (rapier) | mismatches (brute force) |"
    );
    println!("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|");
    let edge = format!("box {}–{} m", QUERY_EDGE.0, QUERY_EDGE.1);
    let cast_label = format!("sphere cast r = {CAST_RADIUS} m, first hit");
    for ((what, ours_ns, rapier_ns, oh, rh, bad), brute) in [
        (
            edge.as_str(),
            ours_box,
            rapier_box_ns,
            ours_hits,
            rapier_hits,
            box_bad,
        ),
        (
            "ray, closest hit",
            ours_ray,
            rapier_ray,
            ours_rays,
            rapier_rays,
            ray_bad,
        ),
        (
            cast_label.as_str(),
            ours_cast,
            rapier_cast,
            ours_casts,
            rapier_casts,
            cast_bad,
        ),
        (
            "nearest, k = 1",
            ours_nearest,
            rapier_nearest,
            ours_near,
            rapier_near,
            near_bad,
        ),
    ]
    .into_iter()
    .zip(brute_bad)
    {
        println!(
            "| {what} | {QUERY_COUNT} | {ours_ns:.1} | {rapier_ns:.1} | {:.2} | {oh} | {rh} | {checked} | {bad} | {brute} |",
            rapier_ns / ours_ns
        );
    }
    println!();
    box_bad + ray_bad + cast_bad + near_bad + brute_bad.iter().sum::<usize>()
}
