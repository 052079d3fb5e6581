//! Ray-cast throughput: a batch of rays (`canopy::scenes::ray_batch`: origins spread over the
//! scene, random directions, unbounded, solid) cast into a standard scene after one step, by
//! Rapier's `QueryPipeline` over its `BroadPhaseBvh` and by canopy's scene queries over
//! `CanopyBroadPhase`, side by side in one run. Prints million rays per second for Rapier, for
//! canopy on one thread, for canopy's batched `cast_rays` on every thread, and for Rapier's
//! own pipeline over canopy's mirrored tree (`as_query_pipeline`); checks that every ray hits
//! the same collider at the same time (or a tie) in all of them.
//!
//! ```text
//! cargo run --release --example raycast [-- --scene NAME] [--rays N] [--size small|full]
//!                                          [--repeat N]
//! ```

use canopy::rapier::CanopyBroadPhase;
use canopy::scenes::{ray_batch, scene, Size, World, SCENE_NAMES};
use rapier3d::prelude::*;
use std::time::Instant;

struct Args {
    scene: String,
    rays: usize,
    size: Size,
    repeat: usize,
}

fn usage() -> ! {
    eprintln!(
        "usage: raycast [--scene NAME] [--rays N] [--size small|full] [--repeat N]\nscenes: {}",
        SCENE_NAMES.join(", ")
    );
    std::process::exit(2)
}

fn parse_args() -> Args {
    let mut args = Args {
        scene: "many_static".into(),
        rays: 100_000,
        size: Size::Full,
        repeat: 5,
    };
    let mut it = std::env::args().skip(1);
    while let Some(a) = it.next() {
        let mut value = || it.next().unwrap_or_else(|| usage());
        match a.as_str() {
            "--scene" => {
                args.scene = value();
                if !SCENE_NAMES.contains(&args.scene.as_str()) {
                    usage();
                }
            }
            "--rays" => args.rays = value().parse().unwrap_or_else(|_| usage()),
            "--repeat" => args.repeat = value().parse().unwrap_or_else(|_| usage()),
            "--size" => {
                args.size = match value().as_str() {
                    "small" => Size::Small,
                    "full" => Size::Full,
                    _ => usage(),
                }
            }
            _ => usage(),
        }
    }
    args
}

type Hit = Option<(ColliderHandle, Real)>;

/// A timed variant: best time so far, hits of its last run, and the batch it casts.
type Variant<'a> = (f64, Vec<Hit>, Box<dyn Fn() -> Vec<Hit> + 'a>);

/// Rays whose hits differ (other time, beyond a tie at 1e-5, or hit vs miss).
fn mismatches(a: &[Hit], b: &[Hit]) -> usize {
    a.iter()
        .zip(b)
        .filter(|(x, y)| match (x, y) {
            (None, None) => false,
            (Some((_, s)), Some((_, t))) => (s - t).abs() > 1.0e-5 * t.abs().max(1.0),
            _ => true,
        })
        .count()
}

fn main() {
    let args = parse_args();
    let build = || scene(&args.scene, args.size).expect("known scene");
    let mut rapier = World::new(build(), BroadPhaseBvh::new());
    let mut canopy = World::new(build(), CanopyBroadPhase::new());
    rapier.step();
    canopy.step();
    let rays = ray_batch(rapier.colliders(), args.rays, 7);
    let (max_toi, solid) = (Real::MAX, true);
    let filter = QueryFilter::default();
    let threads = rayon::current_num_threads();

    // The one-thread rows run on this thread (single queries are not parallel); the variants
    // take turns in every round, so that machine noise hits them alike, and each keeps its best.
    canopy
        .broad_phase
        .sync_query_pipeline(&canopy.scene.colliders);
    let rq = rapier.broad_phase.as_query_pipeline(
        rapier.narrow_phase.query_dispatcher(),
        rapier.bodies(),
        rapier.colliders(),
        filter,
    );
    let q = canopy.broad_phase.scene_queries(
        canopy.narrow_phase.query_dispatcher(),
        canopy.bodies(),
        canopy.colliders(),
        filter,
    );
    let mq = canopy.broad_phase.query_pipeline(
        canopy.narrow_phase.query_dispatcher(),
        canopy.bodies(),
        canopy.colliders(),
        filter,
    );
    let one = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("thread pool");
    let (bp, np, bodies, colliders) = (
        &canopy.broad_phase,
        &canopy.narrow_phase,
        canopy.bodies(),
        canopy.colliders(),
    );
    let batch_one = || {
        one.install(|| {
            bp.scene_queries(
                np.query_dispatcher(),
                bodies,
                colliders,
                QueryFilter::default(),
            )
            .cast_rays(&rays, max_toi, solid)
        })
    };
    let mut variants: [Variant; 5] = [
        (
            f64::INFINITY,
            Vec::new(),
            Box::new(|| {
                rays.iter()
                    .map(|r| rq.cast_ray(r, max_toi, solid))
                    .collect()
            }),
        ),
        (
            f64::INFINITY,
            Vec::new(),
            Box::new(|| rays.iter().map(|r| q.cast_ray(r, max_toi, solid)).collect()),
        ),
        (f64::INFINITY, Vec::new(), Box::new(batch_one)),
        (
            f64::INFINITY,
            Vec::new(),
            Box::new(|| q.cast_rays(&rays, max_toi, solid)),
        ),
        (
            f64::INFINITY,
            Vec::new(),
            Box::new(|| {
                rays.iter()
                    .map(|r| mq.cast_ray(r, max_toi, solid))
                    .collect()
            }),
        ),
    ];
    for _ in 0..args.repeat.max(1) {
        for (best, hits, f) in variants.iter_mut() {
            let t = Instant::now();
            *hits = std::hint::black_box(f());
            *best = best.min(t.elapsed().as_secs_f64());
        }
    }
    let [(rapier_s, rapier_hits, _), (canopy_s, canopy_hits, _), (batch1_s, batch1_hits, _), (batch_s, batch_hits, _), (mirror_s, mirror_hits, _)] =
        variants;

    let n = rays.len() as f64;
    let mrays = |s: f64| n / s / 1.0e6;
    let hits = rapier_hits.iter().filter(|h| h.is_some()).count();
    println!(
        "{} ({} colliders), {} rays (unbounded, solid), {} hit; best of {} runs",
        args.scene,
        rapier.colliders().len(),
        rays.len(),
        hits,
        args.repeat
    );
    println!("{:<44} {:>10} {:>10}", "", "Mrays/s", "vs Rapier");
    let rows = [
        ("Rapier QueryPipeline, 1 thread", rapier_s),
        ("canopy scene_queries, 1 thread", canopy_s),
        ("canopy cast_rays (batched), 1 thread", batch1_s),
        ("canopy cast_rays (batched), all threads", batch_s),
        ("Rapier QueryPipeline on canopy's mirror", mirror_s),
    ];
    for (i, (label, s)) in rows.iter().enumerate() {
        let label = if i == 3 {
            format!("canopy cast_rays (batched), {threads} threads")
        } else {
            label.to_string()
        };
        println!("{label:<44} {:>10.2} {:>9.2}x", mrays(*s), rapier_s / s);
    }
    let wrong = mismatches(&canopy_hits, &rapier_hits)
        + mismatches(&batch1_hits, &rapier_hits)
        + mismatches(&batch_hits, &rapier_hits)
        + mismatches(&mirror_hits, &rapier_hits);
    println!("rays answered differently from Rapier: {wrong}");
    if wrong > 0 {
        std::process::exit(1);
    }
}
