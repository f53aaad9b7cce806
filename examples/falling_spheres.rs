//! The demo: a few thousand spheres fall into a box and settle, driven by `broadleaf::fixtures::sim`.
//! It prints a progress bar and a summary table, and writes an animated GIF: a side view
//! (x–y) with every sphere coloured by the octree level it lives at and the occupied octree
//! cells outlined.
//!
//! ```text
//! cargo run --release --example falling_spheres
//! cargo run --release --example falling_spheres -- --n 2000 --steps 300 --index bvh --verify
//! ```

use broadleaf::fixtures::cli::{self, Flags, Stop};
use broadleaf::fixtures::sim::{DropConfig, IndexKind, World};
use broadleaf::octree::Placement;
use broadleaf::{Aabb, Pair, Vec3, brute};
use indicatif::{ProgressBar, ProgressStyle};
use std::collections::BTreeSet;
use std::fs::File;
use std::io::BufWriter;
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

const USAGE: &str = "\
usage: falling_spheres [--n N] [--steps S] [--index octree|bvh] [--placement strict|loose]
                       [--skin S] [--verify] [--out PATH] [--png PATH] [--frames F] [--seed SEED]
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
  --seed SEED    seed of the start positions' jitter (default 1)";

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
            let (spheres, cells) = octree_view(&world);
            view.draw(&mut canvas, &world, &spheres, &cells, step);
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
    bp_ns.sort_by(f64::total_cmp);
    let median = bp_ns.get(bp_ns.len() / 2).copied().unwrap_or(0.0);
    step_ms.sort_by(f64::total_cmp);
    let median_step = step_ms.get(step_ms.len() / 2).copied().unwrap_or(0.0);
    let rows = [
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
        ("median broadphase", format!("{median:.0} ns/object/step")),
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

/// A sphere with no octree level (it lives in the BVH).
const NO_LEVEL: u32 = u32::MAX;

/// A sphere as the renderer sees it: centre, radius, octree level (or [`NO_LEVEL`]).
type SphereView = (Vec3, f32, u32);
/// An occupied octree cell: its level and its box.
type CellView = (u32, Aabb);

/// Each sphere as `(centre, radius, octree level)` and the occupied octree cells as
/// `(level, cell box)`, read from the broadphase's own octree (`BroadPhase::octree`): the level
/// a sphere lives at is the one the step used.
fn octree_view(world: &World) -> (Vec<SphereView>, Vec<CellView>) {
    let octree = world.broadphase().octree();
    let spheres = world
        .positions()
        .iter()
        .zip(world.radii())
        .zip(world.sphere_keys())
        .map(|((&center, &radius), &key)| {
            (center, radius, octree.level_of(key).unwrap_or(NO_LEVEL))
        })
        .collect();
    let mut cells = Vec::new();
    octree.for_each_occupied_cell(|level, aabb| cells.push((level, aabb)));
    (spheres, cells)
}

// ---------------------------------------------------------------------------------------------
// The picture: an indexed-colour canvas, a disc fill, a rectangle outline, a 3×5 digit font.
// ---------------------------------------------------------------------------------------------

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
const BACKGROUND: u8 = 0;
const WALL: u8 = 1;
const TEXT: u8 = 2;
const NEUTRAL_FILL: u8 = 3;
const NEUTRAL_RIM: u8 = 4;
/// Palette index of level `l`'s fill; its rim is `+1`, its cell outline `+2`.
fn level_index(level: u32) -> u8 {
    if level == NO_LEVEL {
        return NEUTRAL_FILL;
    }
    5 + 3 * level.min(LEVEL_COLOURS.len() as u32 - 1) as u8
}

/// The GIF's global palette: background, wall, text, the BVH colour, then per level its fill,
/// a darker rim and a dim cell outline.
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

    /// Writes `text` (digits, `L`, `B`, `V`, `H`, space) in a 3×5 font scaled by `scale`.
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

    fn draw(
        &self,
        canvas: &mut Canvas,
        world: &World,
        spheres: &[SphereView],
        cells: &[CellView],
        step: usize,
    ) {
        canvas.pixels.fill(BACKGROUND);
        // Back to front: the camera looks along −z, so larger z is nearer.
        let mut order: Vec<usize> = (0..spheres.len()).collect();
        order.sort_by(|&a, &b| spheres[a].0.z.total_cmp(&spheres[b].0.z));
        for &k in &order {
            let (c, r, level) = spheres[k];
            let fill = level_index(level);
            let rim = if level == NO_LEVEL {
                NEUTRAL_RIM
            } else {
                fill + 1
            };
            canvas.disc(self.px(c.x), self.py(c.y), r * self.scale, fill, rim);
        }
        // Cells over the spheres, coarse last so their outlines stay visible.
        let mut drawn = BTreeSet::new();
        let mut sorted: Vec<&CellView> = cells.iter().collect();
        sorted.sort_by_key(|(level, _)| std::cmp::Reverse(*level));
        for &&(level, cell) in &sorted {
            let rect = (
                self.px(cell.min.x).round() as i32,
                self.py(cell.max.y).round() as i32,
                self.px(cell.max.x).round() as i32,
                self.py(cell.min.y).round() as i32,
            );
            if drawn.insert(rect) {
                canvas.outline(rect.0, rect.1, rect.2, rect.3, level_index(level) + 2);
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
        // Legend: the levels present, and the step number.
        let levels: BTreeSet<u32> = spheres.iter().map(|s| s.2).collect();
        let mut x = 8;
        for level in levels.iter().filter(|&&l| l != NO_LEVEL) {
            canvas.fill_rect(x, 8, x + 9, 17, level_index(*level));
            canvas.text(x + 14, 8, 2, &format!("L{level}"), TEXT);
            x += 48;
        }
        if levels.contains(&NO_LEVEL) {
            canvas.fill_rect(x, 8, x + 9, 17, NEUTRAL_FILL);
            canvas.text(x + 14, 8, 2, "BVH", TEXT);
        }
        let label = step.to_string();
        let w = label.len() as i32 * 8;
        canvas.text(i32::from(self.width) - 8 - w, 8, 2, &label, TEXT);
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
