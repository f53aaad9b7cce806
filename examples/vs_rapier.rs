//! broadleaf's `BroadPhase` against rapier3d's broad phase on the same seeded scene.
//!
//! ```text
//! cargo run --release --features rapier --example vs_rapier -- --scene gas --n 100000
//!     [--steps 30] [--warmup 5] [--index octree|bvh|auto] [--placement strict|loose] [--seed 1]
//!     [--skin 0]
//! ```
//!
//! `--scene` is `gas`, `clustered`, `bodies`, `churn`, `pile` or `all` (every scene at its
//! default N: gas, clustered and churn 100 000, bodies and pile 10 000; `--n` overrides it for
//! all). `pile` is recorded first from a dynamic rapier run (`broadleaf::fixtures::rapier_world::record_pile`,
//! 240 settling steps, untimed) and then replayed like the others. The scene's frames are
//! generated first; then broadleaf runs all of them, then rapier does (`--interleave`
//! alternates the two per step instead, so each also pays for the other evicting its caches).
//! Each step the scene's motion is fed to both:
//!
//! - broadleaf: the frame's removes, inserts and new positions/boxes, then `step()`; spheres go
//!   in with `insert_sphere` (`--index octree` or `auto`) or as dynamic bodies by their box
//!   (`--index bvh`); boxes always go in as bodies. The octree's placement is `--placement`
//!   (default strict, depth `depth_for`; loose uses `depth_for_loose`), its pair cache's skin
//!   `--skin` (`Config::skin`, default 0: no cache). Timed with `Instant` around all of it.
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
//! Times are medians over the measured steps after the warm-up, in ns per object (every live
//! object, static ones included) per step. The last line is exactly
//! `ratio=<speed-up> missed=<n> extra=<n>`; for `--scene all` the ratio is the worst (smallest)
//! speed-up of the scenes and `missed`/`extra` are summed over them.

use broadleaf::fixtures::rapier_world::{SceneWorld, record_pile};
use broadleaf::fixtures::scene::{Bodies, Churn, Feed, Frame, GAS_RADIUS, Gas, Scene};
use broadleaf::rapier::Comparison;
use broadleaf::{BroadPhase, Config, Passes, Placement, brute};
use std::process::exit;
use std::time::Instant;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Index {
    Octree,
    Bvh,
    Auto,
}

struct Args {
    scene: String,
    n: Option<usize>,
    steps: usize,
    warmup: usize,
    index: Index,
    placement: Placement,
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
}

const USAGE: &str = "usage: vs_rapier [--scene gas|clustered|bodies|churn|pile|all] [--n N] \
                     [--steps 30] [--warmup 5] [--index octree|bvh|auto] \
                     [--placement strict|loose] [--skin 0] [--passes adaptive|full|incremental] [--seed 1] \
                     [--sizes N1,N2,...] [--plot PATH.svg] [--interleave]";

fn parse_args() -> Result<Args, String> {
    let mut args = Args {
        scene: "gas".into(),
        n: None,
        steps: 30,
        warmup: 5,
        index: Index::Auto,
        placement: Placement::Strict,
        skin: 0.0,
        passes: Passes::Adaptive,
        seed: 1,
        sizes: Vec::new(),
        plot: None,
        interleave: false,
    };
    let mut it = std::env::args().skip(1);
    while let Some(flag) = it.next() {
        if flag == "--help" || flag == "-h" {
            println!("{USAGE}");
            exit(0);
        }
        if flag == "--interleave" {
            args.interleave = true;
            continue;
        }
        let value = it.next().ok_or(format!("{flag} needs a value"))?;
        let number = |v: &str| v.parse::<usize>().map_err(|e| format!("{flag} {v}: {e}"));
        match flag.as_str() {
            "--scene" => args.scene = value,
            "--n" => args.n = Some(number(&value)?),
            "--steps" => args.steps = number(&value)?.max(1),
            "--warmup" => args.warmup = number(&value)?,
            "--seed" => args.seed = number(&value)? as u64,
            "--sizes" => {
                args.sizes = value.split(',').map(number).collect::<Result<_, _>>()?;
            }
            "--plot" => args.plot = Some(value),
            "--passes" => {
                args.passes = match value.as_str() {
                    "adaptive" => Passes::Adaptive,
                    "full" => Passes::Full,
                    "incremental" => Passes::Incremental,
                    other => return Err(format!("--passes {other}: adaptive|full|incremental")),
                };
            }
            "--skin" => {
                args.skin = value
                    .parse::<f32>()
                    .map_err(|e| format!("{flag} {value}: {e}"))?;
            }
            "--index" => {
                args.index = match value.as_str() {
                    "octree" => Index::Octree,
                    "bvh" => Index::Bvh,
                    "auto" => Index::Auto,
                    other => return Err(format!("unknown index {other}")),
                }
            }
            "--placement" => {
                args.placement = match value.as_str() {
                    "strict" => Placement::Strict,
                    "loose" => Placement::Loose,
                    other => return Err(format!("unknown placement {other}")),
                }
            }
            other => return Err(format!("unknown flag {other}")),
        }
    }
    Ok(args)
}

/// Unrecorded rapier steps that let the `pile` scene settle before its frames are recorded.
const PILE_SETTLE_STEPS: usize = 240;

fn make_scene(name: &str, n: usize, seed: u64, steps: usize) -> Option<Box<dyn Scene>> {
    Some(match name {
        "pile" => Box::new(record_pile(n, seed, PILE_SETTLE_STEPS, steps + 1)),
        "gas" => Box::new(Gas::new(n, seed)),
        "clustered" => Box::new(Gas::clustered(n, seed)),
        "bodies" => Box::new(Bodies::new(n, seed)),
        "churn" => Box::new(Churn::new(n, seed)),
        _ => return None,
    })
}

fn default_n(scene: &str) -> usize {
    if scene == "bodies" || scene == "pile" {
        10_000
    } else {
        100_000
    }
}

/// broadleaf's side: the broadphase and the key of each scene id.
struct Ours {
    bp: BroadPhase,
    feed: Feed,
}

impl Ours {
    fn new(bounds: broadleaf::Aabb, index: Index, args: &Args) -> Self {
        let placement = args.placement;
        Ours {
            bp: BroadPhase::new(Config {
                bounds,
                octree_depth: placement.depth_for(&bounds, GAS_RADIUS),
                octree_placement: placement,
                skin: args.skin,
                passes: args.passes,
                ..Config::default()
            }),
            feed: Feed::new(index == Index::Bvh),
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
    n: usize,
    ours_ns: f64,
    rapier_ns: f64,
    cmp: Comparison,
}

fn run(name: &str, n: usize, args: &Args) -> Row {
    let mut scene = make_scene(name, n, args.seed, args.warmup + args.steps).expect("known scene");
    let mut ours = Ours::new(scene.bounds(), args.index, args);
    let mut theirs = SceneWorld::new();
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
    // The motion is generated up front, so each engine can run its steps back to back (a
    // real program runs one broadphase, and alternating the two per step makes each pay for
    // the other evicting its caches); `--interleave` alternates them as before.
    let steps = args.warmup + args.steps;
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
    let mut ours_step = |frame: &Frame| {
        let t = Instant::now();
        ours.feed
            .apply(&mut ours.bp, frame)
            .expect("scene frames are valid");
        let pairs = ours.bp.step().pairs;
        let ns = t.elapsed().as_nanos() as f64;
        last_pairs.clear();
        last_pairs.extend_from_slice(pairs);
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
    let mut cmp = Comparison::new(
        &last_pairs,
        &rapier_pairs,
        &exact_pairs(&*scene, &ours.feed),
    );
    cmp.unmapped = unmapped;
    Row {
        scene: name.to_string(),
        n: scene.len(),
        ours_ns: median(&mut ours_ns),
        rapier_ns: median(&mut rapier_ns),
        cmp,
    }
}

/// The brute-force pair set of the scene's objects as the scene says they are now (its own
/// boxes, not the broadphase's), in broadleaf's keys.
fn exact_pairs(scene: &dyn Scene, feed: &Feed) -> Vec<broadleaf::Pair> {
    let mut spawns = Vec::new();
    scene.spawns(&mut spawns);
    let proxies: Vec<brute::Proxy> = spawns
        .iter()
        .map(|s| brute::Proxy {
            key: feed.key(s.id).expect("every live scene object was fed"),
            aabb: s.object.aabb(),
            is_static: s.is_static,
        })
        .collect();
    brute::sweep_pairs(&proxies)
}

fn main() {
    let args = parse_args().unwrap_or_else(|e| {
        eprintln!("{e}\n{USAGE}");
        exit(2);
    });
    let names: Vec<&str> = match args.scene.as_str() {
        "all" => vec!["gas", "clustered", "bodies", "churn", "pile"],
        s if make_scene(s, 0, 0, 0).is_some() => vec![s],
        s => {
            eprintln!("unknown scene {s}\n{USAGE}");
            exit(2);
        }
    };
    println!(
        "index {:?}, octree placement {:?}, skin {}, {} measured steps after {} warm-up, seed {}, \
         {}; times: median ns/object/step",
        args.index,
        args.placement,
        args.skin,
        args.steps,
        args.warmup,
        args.seed,
        if args.interleave {
            "engines alternating per step"
        } else {
            "each engine's steps back to back"
        }
    );
    println!();
    println!(
        "| scene | N | broadleaf ns/object/step | rapier ns/object/step | speed-up | pairs (broadleaf) | pairs (rapier) | exact pairs | missed | extra |"
    );
    println!("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|");
    let mut rows = Vec::new();
    let runs: Vec<(&str, usize)> = if args.sizes.is_empty() {
        names
            .iter()
            .map(|&name| (name, args.n.unwrap_or_else(|| default_n(name))))
            .collect()
    } else {
        names
            .iter()
            .flat_map(|&name| args.sizes.iter().map(move |&n| (name, n)))
            .collect()
    };
    for (name, n) in runs {
        let r = run(name, n, &args);
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
    for r in &rows {
        if !r.cmp.holds() {
            println!(
                "WARNING {}: the cross-check does not hold: {}",
                r.scene, r.cmp
            );
        }
    }
    if let Some(path) = &args.plot {
        match std::fs::write(path, plot_svg(&rows)) {
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

/// One line of the plot: engine name, colour, and which time of a row it draws.
type Engine = (&'static str, &'static str, fn(&Row) -> f64);

/// A log–log SVG plot of ns/object/step against N, one line per engine and scene; drawn by
/// hand (a few dozen SVG elements), so the example needs no plotting dependency.
fn plot_svg(rows: &[Row]) -> String {
    let (w, h, left, right, top, bottom) = (640.0, 400.0, 70.0, 150.0, 30.0, 50.0);
    let xs: Vec<f64> = rows.iter().map(|r| (r.n as f64).log10()).collect();
    let ys: Vec<f64> = rows
        .iter()
        .flat_map(|r| [r.ours_ns.log10(), r.rapier_ns.log10()])
        .collect();
    let (x0, x1) = (
        xs.iter().copied().fold(f64::INFINITY, f64::min).floor(),
        xs.iter()
            .copied()
            .fold(f64::NEG_INFINITY, f64::max)
            .ceil()
            .max(1.0),
    );
    let (y0, y1) = (
        ys.iter().copied().fold(f64::INFINITY, f64::min).floor(),
        ys.iter().copied().fold(f64::NEG_INFINITY, f64::max).ceil(),
    );
    let px = |x: f64| left + (x - x0) / (x1 - x0).max(1e-9) * (w - left - right);
    let py = |y: f64| h - bottom - (y - y0) / (y1 - y0).max(1e-9) * (h - top - bottom);
    let mut svg = format!(
        "<svg xmlns='http://www.w3.org/2000/svg' width='{w}' height='{h}' font-family='sans-serif' font-size='12'>\n<rect width='100%' height='100%' fill='white'/>\n"
    );
    for e in x0 as i32..=x1 as i32 {
        let x = px(f64::from(e));
        svg += &format!(
            "<line x1='{x}' y1='{top}' x2='{x}' y2='{}' stroke='#ddd'/><text x='{x}' y='{}' text-anchor='middle'>1e{e}</text>\n",
            h - bottom,
            h - bottom + 16.0
        );
    }
    for e in y0 as i32..=y1 as i32 {
        let y = py(f64::from(e));
        svg += &format!(
            "<line x1='{left}' y1='{y}' x2='{}' y2='{y}' stroke='#ddd'/><text x='{}' y='{}' text-anchor='end'>1e{e}</text>\n",
            w - right,
            left - 6.0,
            y + 4.0
        );
    }
    svg += &format!(
        "<text x='{}' y='{}' text-anchor='middle'>objects N</text><text x='16' y='{}' transform='rotate(-90 16 {})' text-anchor='middle'>ns / object / step</text>\n",
        (left + w - right) / 2.0,
        h - 10.0,
        (top + h - bottom) / 2.0,
        (top + h - bottom) / 2.0
    );
    let mut scenes: Vec<&str> = rows.iter().map(|r| r.scene.as_str()).collect();
    scenes.dedup();
    let mut legend = 0.0;
    for (k, scene) in scenes.iter().enumerate() {
        let of_scene: Vec<&Row> = rows.iter().filter(|r| r.scene == *scene).collect();
        let engines: [Engine; 2] = [
            ("broadleaf", "#2a9d8f", |r| r.ours_ns),
            ("rapier", "#e76f51", |r| r.rapier_ns),
        ];
        for (engine, colour, value) in engines {
            let dash = if k == 0 {
                ""
            } else {
                " stroke-dasharray='6 3'"
            };
            let points: Vec<String> = of_scene
                .iter()
                .map(|r| {
                    format!(
                        "{:.1},{:.1}",
                        px((r.n as f64).log10()),
                        py(value(r).log10())
                    )
                })
                .collect();
            svg += &format!(
                "<polyline points='{}' fill='none' stroke='{colour}' stroke-width='2'{dash}/>\n",
                points.join(" ")
            );
            for p in &points {
                let (x, y) = p.split_once(',').unwrap_or(("0", "0"));
                svg += &format!("<circle cx='{x}' cy='{y}' r='3' fill='{colour}'/>\n");
            }
            let ly = top + 10.0 + legend * 18.0;
            svg += &format!(
                "<line x1='{}' y1='{ly}' x2='{}' y2='{ly}' stroke='{colour}' stroke-width='2'{dash}/><text x='{}' y='{}'>{engine} {scene}</text>\n",
                w - right + 10.0,
                w - right + 34.0,
                w - right + 40.0,
                ly + 4.0
            );
            legend += 1.0;
        }
    }
    svg + "</svg>\n"
}
