//! Prints, for every scene, its body and collider counts and how long it takes
//! to build and to step with Rapier's `BroadPhaseBvh`.
//!
//! `cargo run -p canopy-scenes --release --example scene_stats -- [full|small] [steps] [names...]`
//! (defaults: `full`, 10 steps, every scene).

use canopy_scenes::rapier3d::geometry::BroadPhaseBvh;
use canopy_scenes::{scene, Size, World, SCENE_NAMES};
use std::time::Instant;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let size = match args.first().map(String::as_str) {
        Some("small") => Size::Small,
        _ => Size::Full,
    };
    let steps: usize = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(10);
    let names: Vec<&str> = if args.len() > 2 {
        args[2..].iter().map(String::as_str).collect()
    } else {
        SCENE_NAMES.to_vec()
    };

    println!(
        "{:<16} {:>8} {:>8} {:>7} {:>7} {:>6} {:>7} {:>9} {:>10} {:>10} {:>8} {:>8} {:>8}",
        "scene",
        "bodies",
        "colliders",
        "fixed",
        "dynamic",
        "kinem",
        "asleep",
        "build ms",
        "step ms",
        "bp ms",
        "min y",
        "max y",
        "asleep'"
    );
    for name in names {
        let start = Instant::now();
        let s = scene(name, size).expect("unknown scene");
        let build_ms = start.elapsed().as_secs_f64() * 1000.0;
        let (bodies, colliders) = (s.num_bodies(), s.num_colliders());
        let (fixed, dynamic, kinematic, asleep) = (
            s.num_fixed(),
            s.num_dynamic(),
            s.num_kinematic(),
            s.num_sleeping(),
        );

        let mut world = World::new(s, BroadPhaseBvh::new());
        let (mut step_ms, mut bp_ms) = (0.0, 0.0);
        for _ in 0..steps {
            world.step();
            step_ms += world.step_ms_last_step();
            bp_ms += world.broad_phase_ms_last_step();
        }
        let min_y = world
            .scene
            .bodies
            .iter()
            .map(|(_, b)| b.translation().y)
            .fold(f32::INFINITY, f32::min);
        let max_y = world
            .scene
            .bodies
            .iter()
            .map(|(_, b)| b.translation().y)
            .fold(f32::NEG_INFINITY, f32::max);
        let n = steps.max(1) as f64;
        println!(
            "{:<16} {:>8} {:>8} {:>7} {:>7} {:>6} {:>7} {:>9.1} {:>10.3} {:>10.3} {:>8.2} {:>8.2} {:>8}",
            name,
            bodies,
            colliders,
            fixed,
            dynamic,
            kinematic,
            asleep,
            build_ms,
            step_ms / n,
            bp_ms / n,
            min_y,
            max_y,
            world.scene.num_sleeping(),
        );
    }
}
