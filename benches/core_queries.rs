//! Query benchmarks: overlapping pairs within one tree and closest-hit ray casts, canopy against
//! parry3d 0.22's `Bvh`, on 10k, 100k and 1M random boxes at constant density (see
//! `common/mod.rs`). Both trees come from their default binned builder.
//!
//! Benchmarks, per size `n`:
//! * `self_pairs/{n}/parry` (`traverse_bvtt_single_tree::<false>`, counting pairs),
//!   `self_pairs/{n}/canopy` (`self_pairs`, counting, on a one-thread rayon pool) and
//!   `self_pairs/{n}/canopy_par` (`par_self_pairs`, which also collects the pairs in a `Vec`);
//! * `rays/{n}/parry` and `rays/{n}/canopy`: 100k long rays (origins inside the scene, random
//!   directions, `t_max` the scene's diagonal), closest hit, with the exact ray-box test of the
//!   primitive's box in the callback; single thread;
//! * `overlaps/{n}/parry` (`intersect_aabb`) and `overlaps/{n}/canopy` (`for_each_overlap`):
//!   10k box queries, each a box of the set grown to twice its size about its centre (a
//!   broadphase's fat-box query: the box itself and its neighbours), counting the hits; single
//!   thread.
//!
//! Before the timings of each size it checks and prints that both libraries find the same pairs,
//! the same ray hits (same hit count, same nearest time up to a relative 1e-5) and the same
//! primitives for every box query.

mod common;

use canopy::core::{Aabb, BuildOptions, Bvh, Ray};
use common::{
    configure_group, diagonal, in_one_thread, one_thread_pool, random_boxes, random_rays,
    rays_to_parry, size_label, to_parry, SIZES,
};
use criterion::{black_box, criterion_group, criterion_main, Criterion, Throughput};
use parry3d::partitioning::{Bvh as ParryBvh, BvhBuildStrategy, BvhWorkspace};
use parry3d::query::RayCast;

/// Seed of the box sets (the same boxes as in `core_build`).
const SEED: u64 = 0x5eed_0001;
/// Seed of the rays.
const RAY_SEED: u64 = 0x5eed_0002;
/// Rays cast per iteration of the ray benchmarks.
const RAYS: usize = 100_000;
/// Box queries per iteration of the overlap benchmarks.
const BOX_QUERIES: usize = 10_000;

/// Everything the benchmarks of one size need.
struct Scene {
    boxes: Vec<Aabb>,
    pboxes: Vec<parry3d::bounding_volume::Aabb>,
    canopy: Bvh,
    parry: ParryBvh,
    rays: Vec<Ray>,
    prays: Vec<parry3d::query::Ray>,
    t_max: f32,
    /// The box queries (every `n / BOX_QUERIES`-th box, doubled about its centre).
    queries: Vec<Aabb>,
    pqueries: Vec<parry3d::bounding_volume::Aabb>,
}

impl Scene {
    fn new(n: usize) -> Self {
        let boxes = random_boxes(n, SEED);
        let pboxes = to_parry(&boxes);
        let canopy = Bvh::build(&boxes, BuildOptions::default()).expect("canopy build");
        let parry = ParryBvh::from_leaves(BvhBuildStrategy::Binned, &pboxes);
        let bounds = canopy.root_aabb().expect("a non-empty tree");
        let rays = random_rays(RAYS, RAY_SEED, &bounds);
        let prays = rays_to_parry(&rays);
        let step = (n / BOX_QUERIES).max(1);
        let queries: Vec<Aabb> = boxes
            .iter()
            .step_by(step)
            .map(|b| {
                let (c, h) = (b.center(), (b.max - b.min) * 0.5);
                Aabb::new(c - h * 2.0, c + h * 2.0)
            })
            .collect();
        let pqueries = to_parry(&queries);
        Self {
            boxes,
            pboxes,
            canopy,
            parry,
            rays,
            prays,
            t_max: diagonal(&bounds),
            queries,
            pqueries,
        }
    }

    fn parry_overlaps(&self, i: usize) -> impl Iterator<Item = u32> + '_ {
        self.parry.intersect_aabb(&self.pqueries[i])
    }

    fn canopy_overlaps(&self, i: usize, mut f: impl FnMut(u32)) {
        self.canopy.for_each_overlap(&self.queries[i], &mut f);
    }

    fn parry_pair_count(&self, ws: &mut BvhWorkspace) -> usize {
        let mut k = 0usize;
        self.parry
            .traverse_bvtt_single_tree::<false>(ws, &mut |_, _| k += 1);
        k
    }

    fn canopy_pair_count(&self) -> usize {
        let mut k = 0usize;
        self.canopy.self_pairs(|_, _| k += 1);
        k
    }

    fn parry_ray(&self, i: usize) -> Option<(u32, f32)> {
        let ray = &self.prays[i];
        self.parry.cast_ray(ray, self.t_max, |prim, best| {
            self.pboxes[prim as usize].cast_local_ray(ray, best, true)
        })
    }

    fn canopy_ray(&self, i: usize) -> Option<(u32, f32)> {
        let ray = &self.rays[i];
        self.canopy
            .cast_ray(ray, self.t_max, |prim, best| {
                ray.intersect_aabb(&self.boxes[prim as usize], best)
            })
            .map(|h| (h.primitive, h.t))
    }

    /// Checks that both libraries agree, and prints what they found.
    fn check(&self) {
        let n = self.boxes.len();
        let label = size_label(n);

        let mut parry_pairs = Vec::new();
        self.parry
            .traverse_bvtt_single_tree::<false>(&mut BvhWorkspace::default(), &mut |a, b| {
                parry_pairs.push((a.min(b), a.max(b)))
            });
        let mut canopy_pairs = Vec::new();
        in_one_thread(|| self.canopy.self_pairs(|a, b| canopy_pairs.push((a, b))));
        let mut canopy_par_pairs = self.canopy.par_self_pairs();
        println!(
            "{label:>5}: pairs: parry {}, canopy {}, canopy_par {} ({:.3} per box)",
            parry_pairs.len(),
            canopy_pairs.len(),
            canopy_par_pairs.len(),
            2.0 * canopy_pairs.len() as f64 / n as f64
        );
        assert_eq!(parry_pairs.len(), canopy_pairs.len(), "pair counts differ");
        assert_eq!(
            canopy_pairs.len(),
            canopy_par_pairs.len(),
            "par pair count differs"
        );
        parry_pairs.sort_unstable();
        canopy_pairs.sort_unstable();
        canopy_par_pairs.sort_unstable();
        assert!(
            canopy_pairs.windows(2).all(|w| w[0] != w[1]),
            "duplicate canopy pair"
        );
        assert_eq!(
            parry_pairs, canopy_pairs,
            "parry and canopy find different pairs"
        );
        assert_eq!(
            canopy_pairs, canopy_par_pairs,
            "serial and parallel pairs differ"
        );

        let (mut parry_hits, mut canopy_hits, mut both, mut t_mismatch, mut at_zero) =
            (0usize, 0usize, 0usize, 0usize, 0usize);
        for i in 0..self.rays.len() {
            let p = self.parry_ray(i);
            let c = self.canopy_ray(i);
            parry_hits += p.is_some() as usize;
            canopy_hits += c.is_some() as usize;
            if let (Some((_, tp)), Some((_, tc))) = (p, c) {
                both += 1;
                at_zero += (tc == 0.0) as usize;
                if (tp - tc).abs() > 1e-5 * tp.abs().max(tc.abs()) {
                    t_mismatch += 1;
                    if t_mismatch <= 5 {
                        println!("       ray {i}: parry {p:?}, canopy {c:?}");
                    }
                }
            }
        }
        println!(
            "{label:>5}: rays: {} cast, t_max {:.1}; hits: parry {parry_hits}, canopy \
             {canopy_hits}, both {both} ({at_zero} start inside a box); nearest t differs: \
             {t_mismatch}",
            self.rays.len(),
            self.t_max
        );
        let mut hits = 0usize;
        for i in 0..self.queries.len() {
            let mut p: Vec<u32> = self.parry_overlaps(i).collect();
            let mut c = Vec::new();
            self.canopy_overlaps(i, |k| c.push(k));
            p.sort_unstable();
            c.sort_unstable();
            assert_eq!(p, c, "box query {i}: parry and canopy find different boxes");
            hits += c.len();
        }
        println!(
            "{label:>5}: box queries: {}, {:.2} hits each",
            self.queries.len(),
            hits as f64 / self.queries.len() as f64
        );
        assert_eq!(parry_hits, canopy_hits, "ray hit counts differ");
        assert_eq!(both, canopy_hits, "the rays hit differ");
        assert_eq!(t_mismatch, 0, "nearest hit times differ");
    }
}

fn bench_queries(c: &mut Criterion) {
    let pool = one_thread_pool();
    for n in SIZES {
        let scene = Scene::new(n);
        scene.check();

        let mut g = c.benchmark_group(format!("self_pairs/{n}"));
        configure_group(&mut g, n);
        let mut ws = BvhWorkspace::default();
        g.bench_function("parry", |b| {
            b.iter(|| black_box(&scene).parry_pair_count(&mut ws))
        });
        g.bench_function("canopy", |b| {
            pool.install(|| b.iter(|| black_box(&scene).canopy_pair_count()))
        });
        g.bench_function("canopy_par", |b| {
            b.iter(|| black_box(&scene).canopy.par_self_pairs().len())
        });
        g.finish();

        let mut g = c.benchmark_group(format!("rays/{n}"));
        configure_group(&mut g, n);
        g.throughput(Throughput::Elements(RAYS as u64));
        g.bench_function("parry", |b| {
            b.iter(|| {
                let s = black_box(&scene);
                (0..s.rays.len())
                    .filter_map(|i| s.parry_ray(i))
                    .fold((0usize, 0.0f32), |(k, sum), (_, t)| (k + 1, sum + t))
            })
        });
        g.bench_function("canopy", |b| {
            pool.install(|| {
                b.iter(|| {
                    let s = black_box(&scene);
                    (0..s.rays.len())
                        .filter_map(|i| s.canopy_ray(i))
                        .fold((0usize, 0.0f32), |(k, sum), (_, t)| (k + 1, sum + t))
                })
            })
        });
        g.finish();

        let mut g = c.benchmark_group(format!("overlaps/{n}"));
        configure_group(&mut g, n);
        g.throughput(Throughput::Elements(scene.queries.len() as u64));
        g.bench_function("parry", |b| {
            b.iter(|| {
                let s = black_box(&scene);
                (0..s.queries.len())
                    .map(|i| s.parry_overlaps(i).count())
                    .sum::<usize>()
            })
        });
        g.bench_function("canopy", |b| {
            pool.install(|| {
                b.iter(|| {
                    let s = black_box(&scene);
                    let mut k = 0usize;
                    for i in 0..s.queries.len() {
                        s.canopy_overlaps(i, |_| k += 1);
                    }
                    k
                })
            })
        });
        g.finish();
    }
}

criterion_group!(benches, bench_queries);
criterion_main!(benches);
