//! Profiling aid: records a standard scene's broadphase inputs (stepped with Rapier's own
//! broadphase), then replays them into a fresh broadphase and prints the time per update.
//! Run it under `valgrind --tool=callgrind --toggle-collect='*harness*replay*'` for stable
//! instruction counts of the replay alone.
//!
//! `cargo run --release --example broadphase_replay -- SCENE rapier|canopy [STEPS] [small|full]`
//! (canopy's margin and velocity stretch can be overridden with `CANOPY_MARGIN` and
//! `CANOPY_VELOCITY_STEPS`, `CANOPY_PENDING_FRACTION`, `CANOPY_DEAD_FRACTION`,
//! `CANOPY_COST_GROWTH`, and `CANOPY_MOVING_SAH` to build moving trees with binned SAH).

use canopy::rapier::CanopyBroadPhase;
use canopy::scenes::harness::{replay, Recorder};
use canopy::scenes::{scene, Size, World};
use rapier3d::geometry::{BroadPhase, BroadPhaseBvh};
use std::time::Instant;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let name = args.first().map(String::as_str).unwrap_or("balls");
    let which = args.get(1).map(String::as_str).unwrap_or("canopy");
    let steps: usize = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(40);
    let size = if args.get(3).map(String::as_str) == Some("small") {
        Size::Small
    } else {
        Size::Full
    };
    let Some(s) = scene(name, size) else {
        eprintln!("unknown scene {name}");
        std::process::exit(2);
    };
    let mut world = World::new(s, Recorder::new(BroadPhaseBvh::new()));
    world.step_n(steps);
    let updates = world.broad_phase.updates;
    let (first, rest) = updates.split_first().expect("one update at least");
    let mut bp: Box<dyn BroadPhase> = match which {
        "rapier" => Box::new(BroadPhaseBvh::new()),
        _ => {
            // Optional overrides for tuning: CANOPY_MARGIN, CANOPY_VELOCITY_STEPS.
            let mut config = canopy::rapier::CanopyBroadPhaseConfig::default();
            let var = |k: &str| std::env::var(k).ok().and_then(|v| v.parse::<f32>().ok());
            if let Some(m) = var("CANOPY_MARGIN") {
                config.margin = m;
            }
            if let Some(v) = var("CANOPY_VELOCITY_STEPS") {
                config.velocity_steps = v;
            }
            if let Some(v) = var("CANOPY_PENDING_FRACTION") {
                config.rebuild.pending_fraction = v as f64;
            }
            if std::env::var_os("CANOPY_MOVING_SAH").is_some() {
                config.rebuild.moving_builder = canopy::core::Builder::BinnedSah;
            }
            if let Some(v) = var("CANOPY_COST_GROWTH") {
                config.rebuild.max_cost_growth = v as f64;
            }
            if let Some(v) = var("CANOPY_DEAD_FRACTION") {
                config.rebuild.max_dead_fraction = v as f64;
            }
            Box::new(CanopyBroadPhase::with_config(config))
        }
    };
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("pool");
    pool.install(|| {
        let mut events = Vec::new();
        bp.update(
            &first.params,
            &first.colliders,
            &first.bodies,
            &first.modified,
            &first.removed,
            &mut events,
        );
        let t = Instant::now();
        let events = replay(bp.as_mut(), rest);
        let secs = t.elapsed().as_secs_f64();
        println!(
            "{name} {which}: {} updates, {events} events, {:.3} ms per update",
            rest.len(),
            secs * 1000.0 / rest.len() as f64
        );
        if let Some(c) = bp.as_any().downcast_ref::<CanopyBroadPhase>() {
            println!("{:?}", c.stats());
        }
    });
}
