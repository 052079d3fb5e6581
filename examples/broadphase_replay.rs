//! Profiling aid: records a standard scene's broadphase inputs (stepped with Rapier's own
//! broadphase), then replays them into a fresh broadphase and prints the time per update.
//! Run it under `valgrind --tool=callgrind --toggle-collect='*harness*replay*'` for stable
//! instruction counts of the replay alone. In the `rapier` and `canopy` modes, `REPLAYS=N`
//! replays N times, for `perf record`'s samples: the first N - 1 each on a fresh broadphase and
//! fresh copies of the sets (as the criterion bench does), the last one timed as without it.
//!
//! `cargo run --release --example broadphase_replay -- SCENE rapier|canopy|ab|split [STEPS] [small|full]`
//! (canopy's margin and velocity stretch can be overridden with `CANOPY_MARGIN` and
//! `CANOPY_VELOCITY_STEPS`, `CANOPY_LIVE_PAIR_SKIN`, `CANOPY_PENDING_FRACTION`,
//! `CANOPY_DEAD_FRACTION`, `CANOPY_COST_GROWTH`, and `CANOPY_MOVING_SAH` to build moving trees
//! with binned SAH).
//!
//! `ab` times, in one process on one recording, canopy with the default configuration (A)
//! against canopy with the overrides above (B) and `AabbFloor`, update by update, each on a
//! fresh copy of the sets (as the criterion bench does), A and B swapping turns every step so
//! that neither always runs second. On this noisy 2-core VM two runs of separate processes
//! differ by 10 to 20%; A against an identical B mostly agrees within 2 to 4% (once 8% apart).
//!
//! `split` times Rapier's `BroadPhaseBvh` and canopy (with the overrides above) side by side,
//! update by update on fresh copies of the sets, taking turns, five times over; it takes each
//! update's median time and sums them by kind of canopy update: none moved, few moved (one
//! query per moved proxy), many moved (marked pair walks: `BroadPhaseStats::walked`), and
//! those with a tree rebuild; and again by which of the step's two calls it is (the user's
//! changes, or the positions after the integration), and by tenth of the recording (how the
//! ratio evolves through the scene). It shows where canopy's time goes against
//! Rapier's, which the totals of `ab` and of the criterion bench hide (`spawn_storm`: the
//! updates where the first layers fall together cost canopy more than Rapier). Built with
//! `--features phase-times`, `split` also prints canopy's phase timers by kind of update and by
//! call (the mean over the five runs, µs per update).

use canopy::rapier::{CanopyBroadPhase, CanopyBroadPhaseConfig};
use canopy::scenes::harness::{record, replay, replay_timed, AabbFloor, RecordedUpdate};
use canopy::scenes::{scene, Size};
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
    let updates = record(s, steps);
    let (first, rest) = updates.split_first().expect("one update at least");
    // The configuration with the overrides, for canopy and for `split` and `ab`; the
    // broadphase `which` names, made anew for each replay.
    let config = config_from_env();
    let make = || -> Box<dyn BroadPhase> {
        match which {
            "rapier" => Box::new(BroadPhaseBvh::new()),
            _ => Box::new(CanopyBroadPhase::with_config(config).unwrap_or_else(|e| {
                eprintln!("{e}");
                std::process::exit(2)
            })),
        }
    };
    let mut bp = make();
    if which == "split" {
        split(name, config, first, rest);
        return;
    }
    if which == "ab" {
        let mut a = CanopyBroadPhase::new();
        let mut b = CanopyBroadPhase::with_config(config).expect("validated above");
        let mut floor = AabbFloor::default();
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .expect("pool");
        let ms = pool.install(|| compare_ab([&mut a, &mut b, &mut floor], first, rest));
        let steps = rest.len() as f64 / 2.0;
        let [a, b, floor] = ms.map(|s| s * 1000.0 / steps);
        println!(
            "{name}: A {a:.3}  B {b:.3}  floor {floor:.3} ms per step (two updates); B / A = {:.3}",
            b / a
        );
        return;
    }
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("pool");
    // `REPLAYS=N`: N - 1 untimed replays first, for a profiler's samples (module comment).
    let replays: usize = std::env::var("REPLAYS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(1);
    pool.install(|| {
        for _ in 1..replays {
            let mut fresh = make();
            first.apply(fresh.as_mut(), &mut Vec::new());
            replay_timed(fresh.as_mut(), rest);
        }
        first.apply(bp.as_mut(), &mut Vec::new());
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

/// Canopy's configuration with the tuning overrides of the environment (module comment).
fn config_from_env() -> CanopyBroadPhaseConfig {
    let mut config = CanopyBroadPhaseConfig::default();
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
    if let Some(v) = var("CANOPY_LIVE_PAIR_SKIN") {
        config.live_pair_skin = v;
    }
    config
}

/// Seconds each broadphase spent in its `update` calls over `rest` (after `first`, untimed),
/// each call on a fresh copy of the recorded sets, the first two taking turns step by step.
fn compare_ab(
    mut bps: [&mut dyn BroadPhase; 3],
    first: &RecordedUpdate,
    rest: &[RecordedUpdate],
) -> [f64; 3] {
    let mut events = Vec::new();
    for bp in bps.iter_mut() {
        first.apply(*bp, &mut events);
    }
    let mut secs = [0.0; 3];
    for (i, u) in rest.iter().enumerate() {
        // Two updates per step: swap A and B every step, not every update.
        let order = if (i / 2) % 2 == 0 {
            [0, 1, 2]
        } else {
            [1, 0, 2]
        };
        for k in order {
            events.clear();
            secs[k] += u.apply_timed_on_copies(bps[k], &mut events).as_secs_f64();
        }
    }
    secs
}

/// The `split` mode: see the module comment.
fn split(
    name: &str,
    config: CanopyBroadPhaseConfig,
    first: &RecordedUpdate,
    rest: &[RecordedUpdate],
) {
    const REPS: usize = 5;
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("pool");
    // Per repetition and update: Rapier's seconds, canopy's seconds, canopy's kind of update,
    // and canopy's phases (with the `phase-times` feature).
    let runs: Vec<Vec<(f64, f64, usize, Phases)>> = pool.install(|| {
        (0..REPS)
            .map(|_| {
                let mut rapier = BroadPhaseBvh::new();
                let mut canopy = CanopyBroadPhase::with_config(config).expect("validated above");
                let mut events = Vec::new();
                first.apply(&mut rapier, &mut events);
                first.apply(&mut canopy, &mut events);
                // The first update's phases are not one of the timed updates'.
                #[cfg(feature = "phase-times")]
                canopy.take_phase_times();
                rest.iter()
                    .enumerate()
                    .map(|(i, u)| {
                        let rebuilds = canopy.stats().rebuilds;
                        let mut time = |bp: &mut dyn BroadPhase| {
                            events.clear();
                            u.apply_timed_on_copies(bp, &mut events).as_secs_f64()
                        };
                        let (r, c) = if (i / 2) % 2 == 0 {
                            let r = time(&mut rapier);
                            (r, time(&mut canopy))
                        } else {
                            let c = time(&mut canopy);
                            (time(&mut rapier), c)
                        };
                        let s = canopy.stats();
                        let kind = if s.rebuilds > rebuilds {
                            3
                        } else if s.moved == 0 {
                            0
                        } else if s.walked {
                            2
                        } else {
                            1
                        };
                        #[cfg(feature = "phase-times")]
                        let phases = canopy.take_phase_times();
                        #[cfg(not(feature = "phase-times"))]
                        let phases = ();
                        (r, c, kind, phases)
                    })
                    .collect()
            })
            .collect()
    });
    const KINDS: [&str; 4] = ["none moved", "few moved", "many moved", "tree rebuilt"];
    const CALLS: [&str; 2] = ["user changes", "integrated"];
    let mut sums = [(0usize, 0.0f64, 0.0f64); 4];
    // By which of the step's two calls it is: the recording's update `i + 1`, whose call within
    // its step is `(i + 1) % 2` (0: the user's changes, 1: after the integration).
    let mut by_call = [(0usize, 0.0f64, 0.0f64); 2];
    // By tenth of the recording: how the ratio evolves through the scene.
    let mut by_tenth = [(0usize, 0.0f64, 0.0f64); 10];
    for i in 0..rest.len() {
        let median = |k: fn(&(f64, f64, usize, Phases)) -> f64| {
            let mut v: Vec<f64> = runs.iter().map(|r| k(&r[i])).collect();
            v.sort_by(f64::total_cmp);
            v[REPS / 2]
        };
        let (r, c) = (median(|x| x.0), median(|x| x.1));
        // The kind is the same in every repetition (the updates are deterministic).
        for s in [
            &mut sums[runs[0][i].2],
            &mut by_call[(i + 1) % 2],
            &mut by_tenth[i * 10 / rest.len()],
        ] {
            s.0 += 1;
            s.1 += r;
            s.2 += c;
        }
    }
    let (rapier, canopy) = sums.iter().fold((0.0, 0.0), |a, s| (a.0 + s.1, a.1 + s.2));
    println!("{name}: medians of {REPS} runs, {} updates", rest.len());
    let rows = |labels: &[&str], sums: &[(usize, f64, f64)]| {
        for (label, s) in labels.iter().zip(sums).filter(|(_, s)| s.0 > 0) {
            println!(
                "  {label:>12}: {:4} updates, rapier {:8.2} ms, canopy {:8.2} ms ({:4.1}% of canopy's), ratio {:5.2}",
                s.0,
                s.1 * 1e3,
                s.2 * 1e3,
                100.0 * s.2 / canopy,
                s.1 / s.2
            );
        }
    };
    rows(&KINDS, &sums);
    println!("  by call:");
    rows(&CALLS, &by_call);
    println!("  by tenth of the recording:");
    const TENTHS: [&str; 10] = [
        "1st", "2nd", "3rd", "4th", "5th", "6th", "7th", "8th", "9th", "10th",
    ];
    rows(&TENTHS, &by_tenth);
    println!(
        "  {:>12}: rapier {:8.2} ms, canopy {:8.2} ms, ratio {:5.2}",
        "all",
        rapier * 1e3,
        canopy * 1e3,
        rapier / canopy
    );
    #[cfg(feature = "phase-times")]
    {
        print_phases_by_group("kind", &KINDS, &runs, |_, u| u.2);
        print_phases_by_group("call", &CALLS, &runs, |i, _| (i + 1) % 2);
    }
}

/// Canopy's phases when timed (feature `phase-times`); nothing otherwise.
#[cfg(feature = "phase-times")]
type Phases = canopy::rapier::PhaseTimes;
#[cfg(not(feature = "phase-times"))]
type Phases = ();

/// With the `phase-times` feature, `split` also prints canopy's phases by group of updates
/// (`group` gives an update's group from its index and record; `kinds` names the groups, `what`
/// what they group by): the mean over the repetitions, in µs per update of that group (the
/// timers' own cost, a clock read per phase, is included).
#[cfg(feature = "phase-times")]
fn print_phases_by_group(
    what: &str,
    kinds: &[&str],
    runs: &[Vec<(f64, f64, usize, Phases)>],
    group: impl Fn(usize, &(f64, f64, usize, Phases)) -> usize,
) {
    println!(
        "  canopy's phases by {what} (µs per update, mean of {} runs):",
        runs.len()
    );
    for (k, label) in kinds.iter().enumerate() {
        let mut sum = Phases::default();
        let mut updates = 0usize;
        let of_group = runs
            .iter()
            .flat_map(|r| r.iter().enumerate())
            .filter(|(i, u)| group(*i, u) == k);
        for (_, (_, _, _, t)) in of_group {
            updates += 1;
            sum += *t;
        }
        if updates == 0 {
            continue;
        }
        let phases: Vec<String> = sum
            .named()
            .iter()
            .map(|&(name, d)| format!("{name} {:6.1}", d.as_secs_f64() * 1e6 / updates as f64))
            .collect();
        println!("  {label:>12}: {}", phases.join(", "));
    }
}
