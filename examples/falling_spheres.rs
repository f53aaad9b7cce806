//! The demo: a few thousand spheres fall into a box and settle, driven by `broadleaf::fixtures::sim`.
//! It prints a progress bar and a summary table, and writes an animated GIF: a side view
//! (x–y) of the octree at work. Under the default loose placement every sphere lives at the
//! level its radius picks: each is a grey disc whose centre dot has the colour of the cell
//! holding it there (cells side by side in the view never share a colour), and the occupied
//! cells are outlined. Under `--placement strict` each sphere is coloured by its level, with a
//! legend, and the occupied cells are outlined in their level's colour.
//!
//! `--vs-rapier` also runs the same drop (same spheres, start positions, container and steps)
//! in rapier3d (dynamic balls, fixed walls, default parameters, sleeping on) and prints its
//! broad-phase time per sphere per step, from rapier's own counters, beside broadleaf's. It
//! needs rapier's timers, which the crate's `profiler` feature turns on; without it the flag
//! says how to enable it.
//!
//! ```text
//! cargo run --release --example falling_spheres
//! cargo run --release --example falling_spheres -- --n 2000 --steps 300 --index bvh --verify
//! cargo run --release --features profiler --example falling_spheres -- --vs-rapier
//! ```

use broadleaf::fixtures::cli::{self, Flags, Stop};
use broadleaf::fixtures::sim::{DropConfig, IndexKind, World};
use broadleaf::octree::Placement;
use broadleaf::{Aabb, Pair, Vec3, brute};
use indicatif::{ProgressBar, ProgressStyle};
use std::collections::{BTreeMap, BTreeSet};
use std::fs::File;
use std::io::BufWriter;
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

const USAGE: &str = "\
usage: falling_spheres [--n N] [--steps S] [--index octree|bvh] [--placement strict|loose]
                       [--skin S] [--verify] [--out PATH] [--png PATH] [--frames F] [--seed SEED]
                       [--vs-rapier]
  --n N          spheres to drop (default 4000)
  --steps S      steps of 1/60 s (default 480)
  --index KIND   where the spheres live: octree (default) or, as dynamic bodies, the BVH
  --placement P  the octree's placement: loose (the Config default) or strict (RTCD 7.3)
  --skin S       a fixed fat-box margin in metres (Config::skin; default 0: adaptive)
  --verify       check every step's pairs against brute force over the spheres and walls
                 the world handed the broadphase
  --out PATH     animated GIF to write (default falling_spheres.gif)
  --png PATH     also write the last frame as a PNG
  --frames F     frames in the GIF (default 60)
  --seed SEED    seed of the start positions' jitter (default 1)
  --vs-rapier    also run the same drop in rapier3d and print its broad-phase time beside
                 broadleaf's; needs the feature profiler:
                 cargo run --release --features profiler --example falling_spheres -- --vs-rapier";

/// What `--vs-rapier` says in a build without rapier's timers.
const VS_RAPIER_NEEDS: &str = "--vs-rapier needs rapier3d with its timers (the feature \
                               profiler): cargo run --release --features profiler --example \
                               falling_spheres -- --vs-rapier";

/// Radius of every sphere, in metres.
const RADIUS: f32 = 0.5;
/// Time step, in seconds.
const DT: f32 = 1.0 / 60.0;
/// Target width of the picture in pixels (the height follows the container's shape).
const IMAGE_WIDTH: f32 = 420.0;
/// Height of the strip above the scene that holds the legend and the step number, in pixels.
const HEADER: f32 = 26.0;

struct Args {
    n: usize,
    steps: usize,
    index: IndexKind,
    placement: Option<Placement>,
    skin: f32,
    verify: bool,
    out: PathBuf,
    png: Option<PathBuf>,
    frames: usize,
    seed: u64,
    vs_rapier: bool,
}

fn parse_args(argv: impl IntoIterator<Item = String>) -> Result<Args, Stop> {
    let mut args = Args {
        n: 4000,
        steps: 480,
        index: IndexKind::Octree,
        placement: None,
        skin: 0.0,
        verify: false,
        out: PathBuf::from("falling_spheres.gif"),
        png: None,
        frames: 60,
        seed: 1,
        vs_rapier: false,
    };
    let mut flags = Flags::new(argv);
    while let Some(flag) = flags.next_flag()? {
        match flag.as_str() {
            "--n" => args.n = flags.parse(&flag)?,
            "--steps" => args.steps = flags.parse(&flag)?,
            "--frames" => args.frames = flags.parse::<usize>(&flag)?.max(1),
            "--seed" => args.seed = flags.parse(&flag)?,
            "--index" => {
                let kinds = [("octree", IndexKind::Octree), ("bvh", IndexKind::Bvh)];
                args.index = flags.choice(&flag, &kinds)?;
            }
            "--placement" => {
                let placements = [("strict", Placement::Strict), ("loose", Placement::Loose)];
                args.placement = Some(flags.choice(&flag, &placements)?);
            }
            "--verify" => args.verify = true,
            "--vs-rapier" if cfg!(feature = "profiler") => args.vs_rapier = true,
            "--vs-rapier" => return Err(Stop::Error(VS_RAPIER_NEEDS.into())),
            "--skin" => {
                args.skin = flags.parse(&flag)?;
                if !(args.skin.is_finite() && args.skin >= 0.0) {
                    return Err(Stop::Error(format!("--skin {}: a length >= 0", args.skin)));
                }
            }
            "--out" => args.out = PathBuf::from(flags.value(&flag)?),
            "--png" => args.png = Some(PathBuf::from(flags.value(&flag)?)),
            _ => return Err(Stop::unknown(&flag)),
        }
    }
    Ok(args)
}

fn main() -> ExitCode {
    let args = cli::or_exit(USAGE, parse_args(std::env::args().skip(1)));
    match run(&args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}

fn run(args: &Args) -> Result<(), Box<dyn std::error::Error>> {
    let mut config = DropConfig::new(args.n, RADIUS, args.seed);
    config.world.index = args.index;
    config.world.broadphase.skin = args.skin;
    if let Some(placement) = args.placement {
        config.world.broadphase.octree_placement = placement;
    }
    let scene = config.build()?;
    let mut world = scene.world;
    let colouring = Colouring::of(world.broadphase().octree().placement(), args.index);
    let view = View::new(&world, scene.interior);
    println!(
        "dropping {} spheres (r = {RADIUS} m) into a {:.1} × {:.1} m box, {} steps of 1/60 s, \
         spheres in the {}",
        args.n,
        scene.interior.extent().x,
        scene.interior.extent().z,
        args.steps,
        match (args.index, world.broadphase().octree().placement()) {
            (IndexKind::Octree, Placement::Strict) => "octree (strict placement)",
            (IndexKind::Octree, Placement::Loose) => "octree (loose placement)",
            (IndexKind::Bvh, _) => "dynamic BVH",
        }
    );

    let mut gif = gif::Encoder::new(
        BufWriter::new(File::create(&args.out)?),
        view.width,
        view.height,
        &palette(),
    )?;
    gif.set_repeat(gif::Repeat::Infinite)?;
    let frame_every = args.steps.div_ceil(args.frames).max(1);
    let mut canvas = Canvas::new(view.width, view.height);

    let bar = ProgressBar::new(args.steps as u64);
    bar.set_style(ProgressStyle::with_template(
        "{bar:40.cyan/blue} {pos}/{len} steps  {per_sec}  eta {eta}",
    )?);
    let potential_start = world.potential_energy();
    let mut bp_ns = Vec::with_capacity(args.steps);
    let mut step_ms = Vec::with_capacity(args.steps);
    let (mut peak_energy, mut peak_step, mut verified) = (0.0f64, 0, 0);
    let mut worst_overlap = 0.0f32;
    let start = Instant::now();
    let mut centers = Vec::new();
    for step in 0..args.steps {
        if args.verify {
            centers.clear();
            centers.extend_from_slice(world.positions());
        }
        let stats = world.step(DT)?;
        bp_ns.push(stats.broadphase_time.as_nanos() as f64 / world.len().max(1) as f64);
        step_ms.push(stats.total_time.as_secs_f64() * 1e3);
        worst_overlap = worst_overlap.max(stats.max_penetration);
        if stats.kinetic_energy > peak_energy {
            (peak_energy, peak_step) = (stats.kinetic_energy, step);
        }
        if args.verify {
            let expected = brute_pairs(&world, &centers);
            if world.pairs() != expected.as_slice() {
                bar.abandon();
                return Err(format!(
                    "step {step}: broadphase gave {} pairs, brute force {}",
                    world.pairs().len(),
                    expected.len()
                )
                .into());
            }
            verified += 1;
        }
        if step % frame_every == 0 || step + 1 == args.steps {
            let (spheres, cells) = octree_view(&world, colouring);
            view.draw(&mut canvas, &world, &spheres, &cells, step, colouring);
            let last = step + 1 == args.steps;
            let mut frame = gif::Frame::from_indexed_pixels(
                view.width,
                view.height,
                canvas.pixels.as_slice(),
                None,
            );
            frame.delay = if last { 300 } else { 5 };
            gif.write_frame(&frame)?;
        }
        bar.inc(1);
    }
    let elapsed = start.elapsed();
    bar.finish();
    drop(gif);
    if let Some(path) = &args.png {
        write_png(path, &canvas)?;
    }

    let stats = *world.stats();
    let (median, mean) = median_and_mean(&mut bp_ns);
    step_ms.sort_by(f64::total_cmp);
    let median_step = step_ms.get(step_ms.len() / 2).copied().unwrap_or(0.0);
    let rapier = if args.vs_rapier {
        Some(rapier_broad_phase(&config, args.steps)?)
    } else {
        None
    };
    let mut rows = vec![
        (
            "objects",
            format!("{} spheres + {} boxes", world.len(), world.boxes().len()),
        ),
        (
            "steps",
            format!("{} ({:.1} s simulated)", args.steps, args.steps as f32 * DT),
        ),
        (
            "wall time",
            format!(
                "{:.2} s, {:.0} steps/s",
                elapsed.as_secs_f64(),
                args.steps as f64 / elapsed.as_secs_f64()
            ),
        ),
        (
            "median broadphase",
            format!("{median:.0} ns/object/step (mean {mean:.0})"),
        ),
        ("median step", format!("{median_step:.2} ms (World::step)")),
        ("pairs (last step)", stats.pairs.to_string()),
        (
            "contacts (last step)",
            format!("{} ({} touching)", stats.contacts, stats.touching),
        ),
        (
            "kinetic energy",
            format!(
                "start 0 J, peak {peak_energy:.3e} J (step {peak_step}), end {:.3e} J",
                stats.kinetic_energy
            ),
        ),
        (
            "potential energy",
            format!(
                "start {potential_start:.3e} J, end {:.3e} J",
                world.potential_energy()
            ),
        ),
        (
            "deepest overlap",
            format!(
                "last step {:.1} % of r, worst step {:.1} % of r",
                100.0 * stats.max_penetration / RADIUS,
                100.0 * worst_overlap / RADIUS
            ),
        ),
    ];
    if let Some((rapier_median, rapier_mean)) = rapier {
        rows.insert(
            4,
            (
                "rapier broadphase",
                format!(
                    "{rapier_median:.0} ns/object/step (mean {rapier_mean:.0}), the same drop in \
                     rapier3d, from its counters"
                ),
            ),
        );
        rows.insert(
            5,
            (
                "speed-up",
                format!(
                    "{:.2}× (rapier's median over broadleaf's)",
                    rapier_median / median
                ),
            ),
        );
    }
    println!();
    for (name, value) in rows {
        println!("  {name:<22} {value}");
    }
    if args.verify {
        println!("verified {verified} steps: pairs == brute force");
    }
    println!("wrote {}", args.out.display());
    if let Some(path) = &args.png {
        println!("wrote {}", path.display());
    }
    Ok(())
}

/// The brute-force pair set of the step just taken, from the demo's own record of what the
/// world handed its broadphase: each sphere at its centre from before the step (`centers`) with
/// radius `radii()[i] + growth()[i]`, as a sphere (octree) or as that sphere's box (BVH); every
/// wall as the static box it is. Each box is grown by the margin here; nothing is read from
/// the broadphase.
fn brute_pairs(world: &World, centers: &[Vec3]) -> Vec<Pair> {
    let margin = world.config().broadphase.margin;
    let grown = |b: Aabb| Aabb::new(b.min - Vec3::splat(margin), b.max + Vec3::splat(margin));
    let spheres = world.sphere_keys().iter().enumerate().map(|(i, &key)| {
        let radius = world.radii()[i] + world.growth()[i];
        let aabb = match world.config().index {
            IndexKind::Octree => Aabb::from_center_radius(centers[i], radius + margin),
            IndexKind::Bvh => grown(Aabb::from_center_radius(centers[i], radius)),
        };
        brute::Proxy {
            key,
            aabb,
            is_static: false,
        }
    });
    let walls = world
        .box_keys()
        .iter()
        .zip(world.boxes())
        .map(|(&key, &b)| brute::Proxy {
            key,
            aabb: grown(b),
            is_static: true,
        });
    brute::sweep_pairs(&spheres.chain(walls).collect::<Vec<_>>())
}

/// `(median, mean)` of `v` (sorted in place); zeros when empty.
fn median_and_mean(v: &mut [f64]) -> (f64, f64) {
    v.sort_by(f64::total_cmp);
    let mean = v.iter().sum::<f64>() / v.len().max(1) as f64;
    (v.get(v.len() / 2).copied().unwrap_or(0.0), mean)
}

/// `--vs-rapier`: the drop of `config` (its spheres, start positions and container) in
/// rapier3d for `steps` steps, and rapier's broad-phase time per sphere per step from its
/// counters, as `(median, mean)`.
#[cfg(feature = "profiler")]
fn rapier_broad_phase(
    config: &DropConfig,
    steps: usize,
) -> Result<(f64, f64), Box<dyn std::error::Error>> {
    println!(
        "running the same drop in rapier3d (dynamic balls, fixed walls, default parameters, \
         sleeping on)"
    );
    let rec = broadleaf::fixtures::rapier_world::record_fall(config, steps)?;
    let per_sphere = rec.balls().max(1) as f64;
    let mut ns: Vec<f64> = rec
        .broad_phase_time
        .iter()
        .map(|t| t.as_nanos() as f64 / per_sphere)
        .collect();
    Ok(median_and_mean(&mut ns))
}

/// Without rapier's timers there is nothing to compare with (`parse_args` refuses the flag).
#[cfg(not(feature = "profiler"))]
fn rapier_broad_phase(
    _config: &DropConfig,
    _steps: usize,
) -> Result<(f64, f64), Box<dyn std::error::Error>> {
    Err(VS_RAPIER_NEEDS.into())
}

/// How the picture colours the spheres.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Colouring {
    /// Loose placement puts every sphere of one radius at one level: each sphere gets the
    /// colour of its cell there, and the occupied cells are outlined.
    Cells,
    /// Strict placement spreads the spheres over levels: each gets its level's colour.
    Levels,
    /// The spheres live in the BVH: one colour.
    Bvh,
}

impl Colouring {
    fn of(placement: Placement, index: IndexKind) -> Self {
        match (index, placement) {
            (IndexKind::Bvh, _) => Colouring::Bvh,
            (IndexKind::Octree, Placement::Loose) => Colouring::Cells,
            (IndexKind::Octree, Placement::Strict) => Colouring::Levels,
        }
    }
}

/// A sphere with no octree level (it lives in the BVH).
const NO_LEVEL: u32 = u32::MAX;

/// A sphere as the renderer sees it: centre, radius, octree level (or [`NO_LEVEL`]) and the
/// palette index of its fill (its rim is the next index).
type SphereView = (Vec3, f32, u32, u8);
/// An occupied octree cell: its level, the box to outline and the outline's palette index.
type CellView = (u32, Aabb, u8);

/// Each sphere as its [`SphereView`] and the occupied octree cells, read from the broadphase's
/// own octree (`BroadPhase::octree`, public API only): the level a sphere lives at (the one
/// the step used), and under loose placement the cell its held centre falls in at that level
/// (a loose octree places a sphere by its centre). Loose cells are outlined as the cells
/// themselves, not their loose bounds (twice as wide), which would overlap their neighbours.
fn octree_view(world: &World, colouring: Colouring) -> (Vec<SphereView>, Vec<CellView>) {
    let octree = world.broadphase().octree();
    let bounds = octree.bounds();
    let spheres = world
        .positions()
        .iter()
        .zip(world.radii())
        .zip(world.sphere_keys())
        .map(|((&center, &radius), &key)| {
            let level = octree.level_of(key).unwrap_or(NO_LEVEL);
            let fill = match colouring {
                Colouring::Bvh => NEUTRAL_FILL,
                Colouring::Levels => level_index(level),
                Colouring::Cells => {
                    let held = octree.sphere(key).map_or(center, |(c, _)| c);
                    cell_index(held, level, &bounds)
                }
            };
            (center, radius, level, fill)
        })
        .collect();
    let mut cells = Vec::new();
    octree.for_each_occupied_cell(|level, reach| match colouring {
        Colouring::Cells => {
            // The loose bounds are the cell grown by half its size on every side.
            let quarter = 0.25 * reach.extent();
            let cell = Aabb::new(reach.min + quarter, reach.max - quarter);
            cells.push((level, cell, CELL_OUTLINE));
        }
        _ => cells.push((level, reach, level_index(level) + 2)),
    });
    (spheres, cells)
}

/// The palette index of the cell that holds `center` at `level` of a tree over `bounds`: the
/// parities of the cell's x and y coordinates (the side view's axes) pick one of
/// [`CELL_COLOURS`], so the cells the picture shows side by side, even at a corner, never
/// share a colour, and a column of cells along z (one square of the view) has one. The root
/// and spheres outside the region get the root's level colour.
fn cell_index(center: Vec3, level: u32, bounds: &Aabb) -> u8 {
    if level == 0 || level == NO_LEVEL {
        return level_index(0);
    }
    let size = bounds.extent() / (1u32 << level.min(31)) as f32;
    let xyz = ((center - bounds.min) / size).floor();
    let parity = |v: f32| (v.rem_euclid(2.0) as u8) & 1;
    CELL_BASE + 3 * (parity(xyz.x) | parity(xyz.y) << 1)
}

/// Levels with a colour of their own; deeper levels reuse the last one.
const LEVEL_COLOURS: [[u8; 3]; 8] = [
    [230, 57, 70],   // 0: the root, red
    [244, 140, 6],   // 1: orange
    [255, 209, 102], // 2: yellow
    [6, 214, 160],   // 3: green
    [17, 138, 178],  // 4: blue
    [131, 56, 236],  // 5: violet
    [255, 0, 110],   // 6: pink
    [200, 200, 200], // 7+: grey
];
/// The colours of the loose cells, by the parities of the cell's x and y coordinates (bit 0,
/// 1): x neighbours alternate warm and cool, y neighbours light and dark.
const CELL_COLOURS: [[u8; 3]; 4] = [
    [255, 209, 102], // yellow
    [6, 214, 160],   // green
    [239, 71, 111],  // rose
    [17, 138, 178],  // blue
];
const BACKGROUND: u8 = 0;
const WALL: u8 = 1;
const TEXT: u8 = 2;
const NEUTRAL_FILL: u8 = 3;
/// Palette index of level 0's fill; each colour is a triple: fill, darker rim, dim outline.
const LEVEL_BASE: u8 = 5;
/// Palette index of the first cell colour's fill (triples as the levels').
const CELL_BASE: u8 = LEVEL_BASE + 3 * LEVEL_COLOURS.len() as u8;
/// Palette index of a sphere's disc under loose placement (its rim is the next index), after
/// the cell colours; then the cells' outline.
const CELL_DISC: u8 = CELL_BASE + 3 * CELL_COLOURS.len() as u8;
const CELL_OUTLINE: u8 = CELL_DISC + 2;
/// Radius of a sphere's centre dot under loose placement, as a fraction of its radius.
const CENTRE_DOT: f32 = 0.5;

/// Palette index of level `l`'s fill; its rim is `+1`, its cell outline `+2`.
fn level_index(level: u32) -> u8 {
    if level == NO_LEVEL {
        return NEUTRAL_FILL;
    }
    LEVEL_BASE + 3 * level.min(LEVEL_COLOURS.len() as u32 - 1) as u8
}

/// The GIF's global palette: background, wall, text, the BVH colour and its rim, then per
/// level its fill, a darker rim and a dim outline, then per cell colour its fill, a darker
/// rim and a dim outline; then the loose spheres' neutral disc, its rim and the cells'
/// outline.
fn palette() -> Vec<u8> {
    let background = [16u8, 20, 31];
    let mut p = vec![];
    p.extend(background);
    p.extend([92u8, 100, 120]);
    p.extend([235u8, 235, 235]);
    p.extend([120u8, 170, 220]);
    p.extend([60u8, 85, 110]);
    let mix = |c: [u8; 3], t: f32| -> [u8; 3] {
        std::array::from_fn(|k| (f32::from(c[k]) * t + f32::from(background[k]) * (1.0 - t)) as u8)
    };
    for c in LEVEL_COLOURS {
        p.extend(c);
        p.extend(mix(c, 0.55));
        p.extend(mix(c, 0.8));
    }
    for c in CELL_COLOURS {
        p.extend(c);
        p.extend(mix(c, 0.55));
        p.extend(mix(c, 0.8));
    }
    p.extend([72u8, 80, 98]);
    p.extend([44u8, 50, 64]);
    p.extend([225u8, 228, 235]);
    p
}

struct Canvas {
    width: u16,
    height: u16,
    pixels: Vec<u8>,
}

impl Canvas {
    fn new(width: u16, height: u16) -> Self {
        Self {
            width,
            height,
            pixels: vec![BACKGROUND; usize::from(width) * usize::from(height)],
        }
    }

    fn set(&mut self, x: i32, y: i32, colour: u8) {
        if x >= 0 && y >= 0 && x < i32::from(self.width) && y < i32::from(self.height) {
            self.pixels[y as usize * usize::from(self.width) + x as usize] = colour;
        }
    }

    /// Fills the disc of radius `r` pixels around `(cx, cy)`; pixels within 1 px of the edge
    /// get `rim`.
    fn disc(&mut self, cx: f32, cy: f32, r: f32, fill: u8, rim: u8) {
        let (x0, x1) = ((cx - r).floor() as i32, (cx + r).ceil() as i32);
        let (y0, y1) = ((cy - r).floor() as i32, (cy + r).ceil() as i32);
        for y in y0..=y1 {
            for x in x0..=x1 {
                let (dx, dy) = (x as f32 + 0.5 - cx, y as f32 + 0.5 - cy);
                let d = (dx * dx + dy * dy).sqrt();
                if d <= r {
                    self.set(x, y, if d > r - 1.0 { rim } else { fill });
                }
            }
        }
    }

    /// Outlines the pixel rectangle `[x0, x1] × [y0, y1]`.
    fn outline(&mut self, x0: i32, y0: i32, x1: i32, y1: i32, colour: u8) {
        for x in x0..=x1 {
            self.set(x, y0, colour);
            self.set(x, y1, colour);
        }
        for y in y0..=y1 {
            self.set(x0, y, colour);
            self.set(x1, y, colour);
        }
    }

    fn fill_rect(&mut self, x0: i32, y0: i32, x1: i32, y1: i32, colour: u8) {
        for y in y0..=y1 {
            for x in x0..=x1 {
                self.set(x, y, colour);
            }
        }
    }

    /// Writes `text` (digits, `A`, `B`, `C`, `E`, `H`, `L`, `S`, `T`, `V`, space) in a 3×5
    /// font scaled by `scale`.
    fn text(&mut self, x: i32, y: i32, scale: i32, text: &str, colour: u8) {
        for (k, ch) in text.chars().enumerate() {
            let glyph: [u8; 5] = match ch {
                '0' => [7, 5, 5, 5, 7],
                '1' => [2, 6, 2, 2, 7],
                '2' => [7, 1, 7, 4, 7],
                '3' => [7, 1, 7, 1, 7],
                '4' => [5, 5, 7, 1, 1],
                '5' => [7, 4, 7, 1, 7],
                '6' => [7, 4, 7, 5, 7],
                '7' => [7, 1, 1, 1, 1],
                '8' => [7, 5, 7, 5, 7],
                '9' => [7, 5, 7, 1, 7],
                'L' => [4, 4, 4, 4, 7],
                'B' => [6, 5, 6, 5, 6],
                'V' => [5, 5, 5, 5, 2],
                'H' => [5, 5, 7, 5, 5],
                'A' => [7, 5, 7, 5, 5],
                'C' => [7, 4, 4, 4, 7],
                'E' => [7, 4, 6, 4, 7],
                'S' => [7, 4, 7, 1, 7],
                'T' => [7, 2, 2, 2, 2],
                _ => [0; 5],
            };
            let ox = x + k as i32 * 4 * scale;
            for (row, bits) in glyph.iter().enumerate() {
                for col in 0..3 {
                    if bits & (4 >> col) != 0 {
                        let (px, py) = (ox + col * scale, y + row as i32 * scale);
                        self.fill_rect(px, py, px + scale - 1, py + scale - 1, colour);
                    }
                }
            }
        }
    }
}

/// The side view: world x → right, world y → up, looking along −z.
struct View {
    width: u16,
    height: u16,
    /// World rectangle shown, in the x–y plane.
    min: (f32, f32),
    max: (f32, f32),
    /// The container's inside along z: boxes entirely outside it are not drawn.
    z_range: (f32, f32),
    scale: f32,
}

impl View {
    fn new(world: &World, interior: Aabb) -> Self {
        let bounds = world.broadphase().config().bounds.unwrap_or(interior);
        let pad = 2.0 * RADIUS;
        let min = (bounds.min.x - pad, bounds.min.y - pad);
        let max = (bounds.max.x + pad, interior.max.y + pad);
        let scale = IMAGE_WIDTH / (max.0 - min.0);
        let width = IMAGE_WIDTH.round() as u16;
        let height = ((max.1 - min.1) * scale + HEADER).round() as u16;
        Self {
            width,
            height,
            min,
            max,
            z_range: (interior.min.z, interior.max.z),
            scale,
        }
    }

    fn px(&self, x: f32) -> f32 {
        (x - self.min.0) * self.scale
    }

    fn py(&self, y: f32) -> f32 {
        (self.max.1 - y) * self.scale + HEADER
    }

    /// The pixel rectangle `(x0, y0, x1, y1)` of a box's x–y face.
    fn rect(&self, b: &Aabb) -> (i32, i32, i32, i32) {
        (
            self.px(b.min.x).round() as i32,
            self.py(b.max.y).round() as i32,
            self.px(b.max.x).round() as i32,
            self.py(b.min.y).round() as i32,
        )
    }

    fn draw(
        &self,
        canvas: &mut Canvas,
        world: &World,
        spheres: &[SphereView],
        cells: &[CellView],
        step: usize,
        colouring: Colouring,
    ) {
        canvas.pixels.fill(BACKGROUND);
        // Back to front: the camera looks along −z, so larger z is nearer.
        let mut order: Vec<usize> = (0..spheres.len()).collect();
        order.sort_by(|&a, &b| spheres[a].0.z.total_cmp(&spheres[b].0.z));
        for &k in &order {
            let (c, r, _, fill) = spheres[k];
            let (x, y, r) = (self.px(c.x), self.py(c.y), r * self.scale);
            if colouring == Colouring::Cells {
                // A loose octree places a sphere by its centre: the disc is neutral, the
                // centre's dot has the colour of its cell.
                canvas.disc(x, y, r, CELL_DISC, CELL_DISC + 1);
                canvas.disc(x, y, CENTRE_DOT * r, fill, fill);
            } else {
                canvas.disc(x, y, r, fill, fill + 1);
            }
        }
        // Cells over the spheres, coarse last so their outlines stay visible.
        let mut drawn = BTreeSet::new();
        let mut sorted: Vec<&CellView> = cells.iter().collect();
        sorted.sort_by_key(|(level, _, _)| std::cmp::Reverse(*level));
        for &&(_, cell, colour) in &sorted {
            let rect = self.rect(&cell);
            if drawn.insert(rect) {
                canvas.outline(rect.0, rect.1, rect.2, rect.3, colour);
            }
        }
        // A cutaway: the walls in front of and behind the spheres (outside the inside's z
        // range) are left out, the floor and the side walls drawn.
        let cutaway = |b: &&Aabb| b.max.z > self.z_range.0 && b.min.z < self.z_range.1;
        for b in world.boxes().iter().filter(cutaway) {
            canvas.fill_rect(
                self.px(b.min.x).round() as i32,
                self.py(b.max.y).round() as i32,
                self.px(b.max.x).round() as i32 - 1,
                self.py(b.min.y).round() as i32 - 1,
                WALL,
            );
        }
        self.legend(canvas, spheres, colouring);
        let label = step.to_string();
        let w = label.len() as i32 * 8;
        canvas.text(i32::from(self.width) - 8 - w, 8, 2, &label, TEXT);
    }

    /// The legend: under [`Colouring::Cells`] the cell colours and the level whose cells they
    /// are (the one holding the most spheres), plus the root's colour if a sphere is there;
    /// otherwise the levels present and the BVH's colour.
    fn legend(&self, canvas: &mut Canvas, spheres: &[SphereView], colouring: Colouring) {
        let levels: BTreeSet<u32> = spheres.iter().map(|s| s.2).collect();
        let mut x = 8;
        if colouring == Colouring::Cells {
            let mut count = BTreeMap::new();
            for s in spheres.iter().filter(|s| s.2 != 0) {
                *count.entry(s.2).or_insert(0usize) += 1;
            }
            if let Some((&level, _)) = count.iter().max_by_key(|&(_, n)| *n) {
                for k in 0..CELL_COLOURS.len() as u8 {
                    canvas.fill_rect(x, 8, x + 5, 17, CELL_BASE + 3 * k);
                    x += 7;
                }
                let text = format!("CELLS AT L{level}");
                canvas.text(x + 6, 8, 2, &text, TEXT);
                x += 6 + text.len() as i32 * 8 + 12;
            }
            if levels.contains(&0) {
                canvas.fill_rect(x, 8, x + 9, 17, level_index(0));
                canvas.text(x + 14, 8, 2, "L0", TEXT);
            }
            return;
        }
        for level in levels.iter().filter(|&&l| l != NO_LEVEL) {
            canvas.fill_rect(x, 8, x + 9, 17, level_index(*level));
            canvas.text(x + 14, 8, 2, &format!("L{level}"), TEXT);
            x += 48;
        }
        if levels.contains(&NO_LEVEL) {
            canvas.fill_rect(x, 8, x + 9, 17, NEUTRAL_FILL);
            canvas.text(x + 14, 8, 2, "BVH", TEXT);
        }
    }
}

fn write_png(path: &PathBuf, canvas: &Canvas) -> Result<(), Box<dyn std::error::Error>> {
    let mut encoder = png::Encoder::new(
        BufWriter::new(File::create(path)?),
        u32::from(canvas.width),
        u32::from(canvas.height),
    );
    encoder.set_color(png::ColorType::Indexed);
    encoder.set_depth(png::BitDepth::Eight);
    encoder.set_palette(palette());
    let mut writer = encoder.write_header()?;
    writer.write_image_data(&canvas.pixels)?;
    Ok(())
}
