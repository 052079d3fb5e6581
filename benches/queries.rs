//! Ray-cast throughput on the standard scenes (full size) after one step, the same batch of
//! rays (`canopy::scenes::ray_batch`: 100,000 rays, origins over the scene, random directions,
//! unbounded, solid) for Rapier's `QueryPipeline` over its `BroadPhaseBvh` and for canopy's
//! scene queries over `CanopyBroadPhase`, in the same run: one ray after the other on one
//! thread for both, and canopy's batched `cast_rays` in a one-thread pool. Criterion reports
//! rays per second (throughput); the target is canopy at least twice Rapier on `many_static`.
//!
//! `cargo bench --bench queries [-- SCENE]` (default: many_static, many_pyramids, keva_tower).

use canopy::rapier::CanopyBroadPhase;
use canopy::scenes::{ray_batch, scene, Size, World};
use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use rapier3d::prelude::*;
use std::time::Duration;

const RAYS: usize = 100_000;

fn bench_rays(c: &mut Criterion) {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("pool");
    let filter: Option<String> = std::env::args().skip(1).find(|a| !a.starts_with('-'));
    for name in ["many_static", "many_pyramids", "keva_tower"] {
        if filter.as_ref().is_some_and(|f| !name.contains(f.as_str())) {
            continue;
        }
        let build = || scene(name, Size::Full).expect("known scene");
        let mut rapier = World::new(build(), BroadPhaseBvh::new());
        let mut canopy = World::new(build(), CanopyBroadPhase::new());
        rapier.step();
        pool.install(|| canopy.step());
        let rays = ray_batch(rapier.colliders(), RAYS, 7);
        let (max_toi, solid) = (Real::MAX, true);

        let mut g = c.benchmark_group(format!("raycast/{name}"));
        g.throughput(Throughput::Elements(rays.len() as u64))
            .sample_size(10)
            .warm_up_time(Duration::from_secs(1))
            .measurement_time(Duration::from_secs(4));
        let q = rapier.broad_phase.as_query_pipeline(
            rapier.narrow_phase.query_dispatcher(),
            rapier.bodies(),
            rapier.colliders(),
            QueryFilter::default(),
        );
        g.bench_function("rapier", |b| {
            b.iter(|| {
                rays.iter()
                    .filter(|r| q.cast_ray(r, max_toi, solid).is_some())
                    .count()
            })
        });
        let q = canopy.broad_phase.scene_queries(
            canopy.narrow_phase.query_dispatcher(),
            canopy.bodies(),
            canopy.colliders(),
            QueryFilter::default(),
        );
        g.bench_function("canopy", |b| {
            b.iter(|| {
                rays.iter()
                    .filter(|r| q.cast_ray(r, max_toi, solid).is_some())
                    .count()
            })
        });
        let (bp, np, bodies, colliders) = (
            &canopy.broad_phase,
            &canopy.narrow_phase,
            canopy.bodies(),
            canopy.colliders(),
        );
        g.bench_function("canopy_cast_rays", |b| {
            b.iter(|| {
                pool.install(|| {
                    let q = bp.scene_queries(
                        np.query_dispatcher(),
                        bodies,
                        colliders,
                        QueryFilter::default(),
                    );
                    q.cast_rays(&rays, max_toi, solid).len()
                })
            })
        });
        g.finish();
    }
}

criterion_group!(benches, bench_rays);
criterion_main!(benches);
