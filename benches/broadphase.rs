//! Broadphase benchmark, one criterion group per standard scene (full size): Rapier's built-in
//! `BroadPhaseBvh` against `CanopyBroadPhase`, timing `BroadPhase::update` alone over a recorded
//! sequence of steps. The sequence is recorded once per scene from a simulation stepped with
//! Rapier's own broadphase; each measured iteration replays it (after the first update, which
//! inserts every collider and is replayed untimed) into a copy of a broadphase that has already
//! seen that first update, timing only the `update` calls: before each one the recorded sets
//! are copied afresh, untimed (`harness::replay_timed`), as a step's position update writes
//! them just before the pipeline calls the broadphase. Single thread: canopy runs inside a 1-thread rayon pool. A third
//! function, `floor`, replays the same updates into `AabbFloor`, which only computes each
//! modified collider's collision box: the work no broadphase avoids, so Rapier's time over the
//! floor's bounds the ratio any broadphase can reach on that scene.
//!
//! `cargo bench --bench broadphase [-- SCENE]`; the time is for the whole sequence, divide by
//! the number of steps printed for ms per step.

use canopy::rapier::CanopyBroadPhase;
use canopy::scenes::harness::{record, replay, replay_timed, AabbFloor, RecordedUpdate};
use canopy::scenes::{scene, standard_steps, Size, SCENE_NAMES};
use criterion::{criterion_group, criterion_main, Criterion};
use rapier3d::geometry::{BroadPhase, BroadPhaseBvh};
use std::time::Duration;

/// Steps recorded per scene: the steps `compare` runs (`standard_steps`), so that both time the
/// same part of each scene, except where the recording would not fit in memory (each recorded
/// update clones the collider and body sets: ~0.7 KB per collider and update, two updates per
/// step): the 125,000-collider scenes record 8 steps and `many_kinematics` (27,000) 40.
fn recorded_steps(name: &str) -> usize {
    match name {
        "many_static" | "many_sleep" => 8,
        "many_kinematics" => 40,
        _ => standard_steps(name, Size::Full),
    }
}

fn primed<B: BroadPhase>(mut bp: B, first: &RecordedUpdate) -> B {
    replay(&mut bp, std::slice::from_ref(first));
    bp
}

fn bench_scenes(c: &mut Criterion) {
    // The bench's own thread is the pool's one thread, so `install` runs inline: no hand-off to
    // a parked worker inside the timed part (it cost ~0.25 ms per iteration, all of canopy's
    // time on the idle `many_sleep`).
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .use_current_thread()
        .build()
        .expect("pool");
    let filter: Option<String> = std::env::args().skip(1).find(|a| !a.starts_with('-'));
    for &name in SCENE_NAMES {
        if let Some(f) = &filter {
            if !name.contains(f.as_str()) && !f.contains(name) {
                continue;
            }
        }
        let updates = record(
            scene(name, Size::Full).expect("known scene"),
            recorded_steps(name),
        );
        let (first, rest) = updates.split_first().expect("at least one update");
        println!(
            "broadphase/{name}: {} timed steps per iteration",
            rest.len()
        );
        let mut g = c.benchmark_group(format!("broadphase/{name}"));
        g.sample_size(10)
            .warm_up_time(Duration::from_secs(1))
            .measurement_time(Duration::from_secs(4));
        // Each iteration replays the whole sequence into a copy of a primed broadphase (the
        // copy is made outside the timed part) and counts only the `update` calls.
        fn time<B: BroadPhase + Clone>(
            primed: &B,
            rest: &[RecordedUpdate],
            iters: u64,
        ) -> Duration {
            (0..iters)
                .map(|_| {
                    let mut bp = primed.clone();
                    replay_timed(&mut bp, rest)
                })
                .sum()
        }
        let rapier = primed(BroadPhaseBvh::new(), first);
        g.bench_function("rapier", |b| b.iter_custom(|n| time(&rapier, rest, n)));
        let canopy = pool.install(|| primed(CanopyBroadPhase::new(), first));
        g.bench_function("canopy", |b| {
            b.iter_custom(|n| pool.install(|| time(&canopy, rest, n)))
        });
        // The floor: only the collision boxes of the modified colliders, which every broadphase
        // computes; Rapier's time over this is the most any broadphase can gain here.
        let floor = primed(AabbFloor::default(), first);
        g.bench_function("floor", |b| b.iter_custom(|n| time(&floor, rest, n)));
        g.finish();
    }
}

criterion_group!(benches, bench_scenes);
criterion_main!(benches);
