//! The main job: every standard scene stepped with Rapier's built-in `BroadPhaseBvh` and with
//! `CanopyBroadPhase`, in the same process, on a single thread by default. Prints per scene the
//! broadphase time per step of both and their ratio, the whole step time of both, the live
//! pairs of both, and canopy's missing pairs (needed pairs, checked against parry's own BVH,
//! that canopy did not report: always 0). Writes the same figures as an SVG chart under
//! `target/canopy/`.
//!
//! ```text
//! cargo run --release --example compare [-- --scene NAME] [--steps N] [--size small|full]
//!                                          [--threads N] [--verify-every N]
//! ```

use canopy::rapier::CanopyBroadPhase;
use canopy::scenes::harness::Instrumented;
use canopy::scenes::{scene, standard_steps, Size, World, SCENE_NAMES};
use plotters::prelude::*;
use rapier3d::geometry::BroadPhaseBvh;
use std::path::PathBuf;
use std::time::Instant;

struct Args {
    scenes: Vec<String>,
    steps: Option<usize>,
    size: Size,
    threads: usize,
    verify_every: Option<usize>,
}

fn usage() -> ! {
    eprintln!(
        "usage: compare [--scene NAME] [--steps N] [--size small|full] [--threads N] [--verify-every N]\n\
         scenes: {}",
        SCENE_NAMES.join(", ")
    );
    std::process::exit(2)
}

fn parse_args() -> Args {
    let mut args = Args {
        scenes: SCENE_NAMES.iter().map(|s| s.to_string()).collect(),
        steps: None,
        size: Size::Full,
        threads: 1,
        verify_every: None,
    };
    let mut it = std::env::args().skip(1);
    while let Some(a) = it.next() {
        let mut value = || it.next().unwrap_or_else(|| usage());
        match a.as_str() {
            "--scene" => {
                let v = value();
                if !SCENE_NAMES.contains(&v.as_str()) {
                    eprintln!("unknown scene {v:?}");
                    usage();
                }
                args.scenes = vec![v];
            }
            "--steps" => args.steps = Some(value().parse().unwrap_or_else(|_| usage())),
            "--threads" => args.threads = value().parse().unwrap_or_else(|_| usage()),
            "--verify-every" => {
                args.verify_every = Some(value().parse().unwrap_or_else(|_| usage()))
            }
            "--size" => {
                args.size = match value().as_str() {
                    "small" => Size::Small,
                    "full" => Size::Full,
                    _ => usage(),
                }
            }
            "-h" | "--help" => usage(),
            _ => usage(),
        }
    }
    args
}

/// Steps per scene at full size, chosen so that the whole run stays under five minutes on a
/// 2-core machine while each scene runs long enough to reach its steady state.
struct Row {
    name: String,
    colliders: usize,
    steps: usize,
    rapier_first_ms: f64,
    canopy_first_ms: f64,
    rapier_bp_ms: f64,
    canopy_bp_ms: f64,
    rapier_step_ms: f64,
    canopy_step_ms: f64,
    rapier_pairs: usize,
    canopy_pairs: usize,
    checked_updates: usize,
    needed_pairs: usize,
    missing: usize,
    /// Canopy's time per phase (feature `phase-times`; empty without it).
    phases: String,
}

fn run_scene(name: &str, size: Size, steps: usize, verify_every: usize) -> Row {
    let build = || scene(name, size).expect("known scene");
    let s = build();
    let colliders = s.num_colliders();
    let mut rapier = World::new(s, Instrumented::new(BroadPhaseBvh::new(), 0));
    let mut canopy = World::new(
        build(),
        Instrumented::new(CanopyBroadPhase::new(), verify_every),
    );
    // Per step: (rapier bp, canopy bp, rapier step, canopy step), seconds.
    let mut per_step = Vec::with_capacity(steps);
    for _ in 0..steps {
        // Interleaved, so that machine noise hits both alike.
        let rapier_bp = rapier.broad_phase.meter.total_secs;
        let t = Instant::now();
        rapier.step();
        let rapier_step = t.elapsed().as_secs_f64();
        let (canopy_bp, verify) = (
            canopy.broad_phase.meter.total_secs,
            canopy.broad_phase.meter.verify_secs,
        );
        let t = Instant::now();
        canopy.step();
        // The truth check runs inside the step; it is not canopy's time.
        let canopy_step =
            t.elapsed().as_secs_f64() - (canopy.broad_phase.meter.verify_secs - verify);
        per_step.push((
            rapier.broad_phase.meter.total_secs - rapier_bp,
            canopy.broad_phase.meter.total_secs - canopy_bp,
            rapier_step,
            canopy_step,
        ));
        #[cfg(feature = "phase-times")]
        if per_step.len() == 1 {
            // The first step is left out of the phases too.
            canopy.broad_phase.inner.take_phase_times();
        }
    }
    // The first step inserts every collider: reported on its own, the mean is over the rest.
    let first = per_step[0];
    let rest = &per_step[1.min(per_step.len() - 1)..];
    let mean = |f: fn(&(f64, f64, f64, f64)) -> f64| {
        rest.iter().map(f).sum::<f64>() * 1000.0 / rest.len() as f64
    };
    #[cfg(feature = "phase-times")]
    let phases = phase_line(&canopy.broad_phase.inner.take_phase_times(), rest.len());
    #[cfg(not(feature = "phase-times"))]
    let phases = String::new();
    let cm = &canopy.broad_phase.meter;
    Row {
        name: name.to_string(),
        colliders,
        steps,
        rapier_first_ms: first.0 * 1000.0,
        canopy_first_ms: first.1 * 1000.0,
        rapier_bp_ms: mean(|s| s.0),
        canopy_bp_ms: mean(|s| s.1),
        rapier_step_ms: mean(|s| s.2),
        canopy_step_ms: mean(|s| s.3),
        rapier_pairs: rapier.broad_phase.live.len(),
        canopy_pairs: canopy.broad_phase.live.len(),
        checked_updates: cm.verified_updates,
        needed_pairs: cm.needed_pairs,
        missing: cm.missing_pairs,
        phases,
    }
}

/// Canopy's phases, ms per step over `steps` steps (feature `phase-times`).
#[cfg(feature = "phase-times")]
fn phase_line(t: &canopy::rapier::PhaseTimes, steps: usize) -> String {
    let ms = |d: std::time::Duration| d.as_secs_f64() * 1000.0 / steps.max(1) as f64;
    let phases: Vec<String> = t
        .named()
        .iter()
        .map(|&(name, d)| format!("{name} {:.3}", ms(d)))
        .collect();
    format!(
        "{} (ms per step); moved per step {:.0}",
        phases.join(", "),
        t.moved as f64 / steps.max(1) as f64
    )
}

/// The ratio column: Rapier's broadphase time over canopy's, or "idle" when both took under a
/// microsecond per step (nothing moves: the ratio of two timer readings would be noise).
fn ratio_label(r: &Row) -> String {
    if r.rapier_bp_ms < 1.0e-3 && r.canopy_bp_ms < 1.0e-3 {
        "idle".to_string()
    } else {
        format!("{:.2}x", r.rapier_bp_ms / r.canopy_bp_ms)
    }
}

fn print_table(rows: &[Row], threads: usize) {
    println!(
        "\n{:<16} {:>7} {:>5} | {:>9} {:>9} {:>7} | {:>9} {:>9} | {:>9} {:>9} | {:>8} {:>8} | {:>7}",
        "scene", "collid.", "steps", "rapier bp", "canopy bp", "ratio", "rapier st", "canopy st",
        "rapier 1st", "canopy 1st", "rapier pr", "canopy pr", "missing"
    );
    println!("{}", "-".repeat(137));
    for r in rows {
        println!(
            "{:<16} {:>7} {:>5} | {:>9.3} {:>9.3} {:>7} | {:>9.2} {:>9.2} | {:>10.1} {:>10.1} | {:>8} {:>8} | {:>7}",
            r.name,
            r.colliders,
            r.steps,
            r.rapier_bp_ms,
            r.canopy_bp_ms,
            ratio_label(r),
            r.rapier_step_ms,
            r.canopy_step_ms,
            r.rapier_first_ms,
            r.canopy_first_ms,
            r.rapier_pairs,
            r.canopy_pairs,
            r.missing
        );
    }
    println!(
        "\nms per step, single thread unless --threads. bp: BroadPhase::update (both calls of a step), \
         mean over the steps after the first; ratio: rapier bp / canopy bp (target >= 3x); st: whole \
         PhysicsPipeline::step;\n1st: broadphase time of the first step, which inserts every \
         collider; pr: live pairs at the end; missing: pairs the narrow phase needed that canopy did \
         not report,\nchecked on {} updates against parry's BVH ({} needed pairs seen). rayon \
         threads: {threads}.",
        rows.iter().map(|r| r.checked_updates).sum::<usize>(),
        rows.iter().map(|r| r.needed_pairs).sum::<usize>(),
    );
    for r in rows.iter().filter(|r| !r.phases.is_empty()) {
        println!("canopy phases, {}: {}", r.name, r.phases);
    }
}

fn out_dir() -> PathBuf {
    let target = std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("target"));
    target.join("canopy")
}

fn write_chart(rows: &[Row], path: &std::path::Path) -> Result<(), Box<dyn std::error::Error>> {
    let width = 160 + 110 * rows.len() as u32;
    let root = SVGBackend::new(path, (width, 520)).into_drawing_area();
    root.fill(&WHITE)?;
    let max = rows
        .iter()
        .map(|r| r.rapier_bp_ms.max(r.canopy_bp_ms))
        .fold(0.0, f64::max)
        * 1.15;
    let n = rows.len() as f64;
    let mut chart = ChartBuilder::on(&root)
        .caption(
            "Broadphase time per step: Rapier BroadPhaseBvh vs CanopyBroadPhase",
            ("sans-serif", 20),
        )
        .margin(15)
        .x_label_area_size(60)
        .y_label_area_size(70)
        .build_cartesian_2d(0.0..n, 0.0..max.max(1e-3))?;
    chart
        .configure_mesh()
        .disable_x_mesh()
        .x_labels(rows.len() * 2 + 1)
        .x_label_formatter(&|x| {
            let i = x.floor() as usize;
            if (x - x.floor() - 0.5).abs() < 1e-6 && i < rows.len() {
                rows[i].name.clone()
            } else {
                String::new()
            }
        })
        .y_desc("ms per step (single thread)")
        .draw()?;
    let rapier_color = RGBColor(200, 90, 60);
    let canopy_color = RGBColor(40, 120, 80);
    for (i, r) in rows.iter().enumerate() {
        let x = i as f64;
        chart.draw_series([
            Rectangle::new(
                [(x + 0.1, 0.0), (x + 0.48, r.rapier_bp_ms)],
                rapier_color.filled(),
            ),
            Rectangle::new(
                [(x + 0.52, 0.0), (x + 0.9, r.canopy_bp_ms)],
                canopy_color.filled(),
            ),
        ])?;
        chart.draw_series(std::iter::once(Text::new(
            format!("{:.1}x", r.rapier_bp_ms / r.canopy_bp_ms),
            (x + 0.3, r.rapier_bp_ms.max(r.canopy_bp_ms) + max * 0.02),
            ("sans-serif", 14),
        )))?;
    }
    chart
        .draw_series(std::iter::once(Rectangle::new(
            [(0.0, 0.0), (0.0, 0.0)],
            rapier_color.filled(),
        )))?
        .label("Rapier BroadPhaseBvh")
        .legend(move |(x, y)| Rectangle::new([(x, y - 5), (x + 12, y + 5)], rapier_color.filled()));
    chart
        .draw_series(std::iter::once(Rectangle::new(
            [(0.0, 0.0), (0.0, 0.0)],
            canopy_color.filled(),
        )))?
        .label("CanopyBroadPhase")
        .legend(move |(x, y)| Rectangle::new([(x, y - 5), (x + 12, y + 5)], canopy_color.filled()));
    chart
        .configure_series_labels()
        .border_style(BLACK)
        .background_style(WHITE)
        .draw()?;
    root.present()?;
    Ok(())
}

fn main() {
    let args = parse_args();
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(args.threads.max(1))
        .build()
        .expect("thread pool");
    let started = Instant::now();
    let rows: Vec<Row> = pool.install(|| {
        args.scenes
            .iter()
            .map(|name| {
                let steps = args
                    .steps
                    .unwrap_or_else(|| standard_steps(name, args.size));
                // The truth check costs more than a step on the big scenes: a few checks each.
                let verify = args.verify_every.unwrap_or(steps.div_ceil(4).max(1));
                eprint!("{name:<16} {steps} steps ... ");
                let t = Instant::now();
                let row = run_scene(name, args.size, steps, verify);
                eprintln!("{:.1} s", t.elapsed().as_secs_f64());
                row
            })
            .collect()
    });
    print_table(&rows, args.threads.max(1));
    let dir = out_dir();
    let path = dir.join("compare.svg");
    match std::fs::create_dir_all(&dir)
        .map_err(Into::into)
        .and_then(|_| write_chart(&rows, &path))
    {
        Ok(()) => println!("chart: {}", path.display()),
        Err(e) => eprintln!("could not write the chart to {}: {e}", path.display()),
    }
    println!("total: {:.1} s", started.elapsed().as_secs_f64());
    if rows.iter().any(|r| r.missing > 0) {
        eprintln!("MISSING PAIRS: canopy failed to report pairs the narrow phase needed");
        std::process::exit(1);
    }
}
