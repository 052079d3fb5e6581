//! Side-by-side A/B of `CanopyBroadPhase`: the working tree's (`new`) against a git revision's
//! (`old`), both linked into this one program (built by `tools/ab/run.sh`, which renames the old
//! crates). Each standard scene is recorded once with Rapier's own broadphase; then every
//! broadphase replays the recorded updates, each update on fresh copies of the recorded sets
//! (as `canopy_scenes::harness` does for the criterion bench), and only the `update` calls are
//! timed.
//!
//! By default the broadphases take turns update by update (new and old swapping places every
//! step, so that neither always runs first): between two updates of one broadphase the others
//! run, as the narrow phase and the solver run between two broadphase updates inside a
//! physics step. With `BLOCK=1` each broadphase replays the whole sequence back to back, as
//! criterion does, new first in even runs and old first in odd ones (always new first, the
//! order of earlier versions, favoured new by a few percent in some runs). `RAPIER=1` adds Rapier's `BroadPhaseBvh`; `AabbFloor` always runs.
//!
//! Arguments: `SCENE[,SCENE...] STEPS [REPS]`. Prints ms per step for each and old / new (above
//! 1: the working tree is faster), then the median of the runs and the range of their middle
//! half.
use canopy_rapier::CanopyBroadPhase as New;
use canopy_rapier_old::CanopyBroadPhase as Old;
use canopy_scenes::harness::{record, AabbFloor, RecordedUpdate};
use canopy_scenes::{scene, Size};
use rapier3d::geometry::{BroadPhase, BroadPhaseBvh};

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (Some(scenes), Some(steps)) = (args.first(), args.get(1).and_then(|s| s.parse().ok()))
    else {
        eprintln!("usage: SCENE[,SCENE...] STEPS [REPS]");
        std::process::exit(2);
    };
    let reps: usize = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(3);
    let with_rapier = std::env::var_os("RAPIER").is_some();
    let block = std::env::var_os("BLOCK").is_some();
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("pool");
    for name in scenes.split(',') {
        let Some(s) = scene(name, Size::Full) else {
            eprintln!("unknown scene {name}");
            std::process::exit(2);
        };
        let updates = record(s, steps);
        let (first, rest) = updates.split_first().expect("one update at least");
        let per_step = |secs: f64| secs * 1000.0 / (rest.len() as f64 / 2.0);
        let mut ratios = Vec::new();
        for run in 0..reps {
            let (mut new, mut old) = (New::new(), Old::new());
            let (mut floor, mut rapier) = (AabbFloor::default(), BroadPhaseBvh::new());
            let mut bps: Vec<&mut dyn BroadPhase> = vec![&mut new, &mut old, &mut floor];
            if with_rapier {
                bps.push(&mut rapier);
            }
            let secs = pool.install(|| replay(&mut bps, first, rest, block, run % 2 == 1));
            let [n, o, f] = [0, 1, 2].map(|k| per_step(secs[k]));
            ratios.push(o / n);
            print!("{name}: new {n:.3} old {o:.3} floor {f:.3}");
            if with_rapier {
                let r = per_step(secs[3]);
                print!(
                    " rapier {r:.3} ms/step; rapier/new {:.3} rapier/old {:.3};",
                    r / n,
                    r / o
                );
            } else {
                print!(" ms/step;");
            }
            println!(" old/new {:.3}", o / n);
        }
        ratios.sort_by(f64::total_cmp);
        // The middle half of the runs too: on this VM one median of 20 runs moves by about
        // 1.5% from one invocation to the next, so a median inside the other's range is noise.
        let quartile = |q: usize| ratios[(ratios.len() * q / 4).min(ratios.len() - 1)];
        println!(
            "{name}: median old/new {:.3} (middle half {:.3} to {:.3}, {} runs)",
            quartile(2),
            quartile(1),
            quartile(3),
            ratios.len()
        );
    }
}

/// Seconds each broadphase spent in its `update` calls over `rest` (after `first`, untimed),
/// each call on fresh copies of the recorded sets; with `block`, old replays before new when
/// `old_first`.
fn replay(
    bps: &mut [&mut dyn BroadPhase],
    first: &RecordedUpdate,
    rest: &[RecordedUpdate],
    block: bool,
    old_first: bool,
) -> Vec<f64> {
    let mut events = Vec::new();
    for bp in bps.iter_mut() {
        first.apply(*bp, &mut events);
    }
    let mut secs = vec![0.0; bps.len()];
    let mut time = |k: usize, u: &RecordedUpdate, bps: &mut [&mut dyn BroadPhase]| {
        events.clear();
        secs[k] += u.apply_timed_on_copies(bps[k], &mut events).as_secs_f64();
    };
    if block {
        let mut order: Vec<usize> = (0..bps.len()).collect();
        if old_first {
            order.swap(0, 1);
        }
        for k in order {
            for u in rest {
                time(k, u, bps);
            }
        }
    } else {
        for (i, u) in rest.iter().enumerate() {
            // Two updates per step: new and old swap places every step, not every update.
            let mut order: Vec<usize> = (0..bps.len()).collect();
            if (i / 2) % 2 == 1 {
                order.swap(0, 1);
            }
            for k in order {
                time(k, u, bps);
            }
        }
    }
    secs
}
