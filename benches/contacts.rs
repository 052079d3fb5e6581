//! Contacts benchmark: one update of a `canopy_parry::CollisionWorld` (canopy-core broad phase,
//! parry manifolds kept across updates; and with `Coherence::Fresh`) against brute-force parry
//! (`contact_manifolds` called fresh on every pair) on the same world, at 1k and 10k objects.
//!
//! The world: mixed convex shapes (balls, cuboids, capsules, cylinders, cones, convex hulls) on a
//! jittered grid, one compound and one triangle-mesh patch per hundred objects, every object
//! moving a little each update. Both sides run on the same rayon pool (all cores).
//!
//! `cargo bench --bench contacts [-- FILTER]`, e.g. `-- 1000/`. The brute force at 10k calls
//! parry on 50M pairs per update: expect minutes.

use std::time::Duration;

use canopy_parry::{brute_force, Coherence, CollisionWorld, ObjectHandle};
use criterion::{criterion_group, criterion_main, Criterion, SamplingMode};
use nalgebra::{Isometry3, Point3, Vector3};
use parry3d::shape::SharedShape;

const PREDICTION: f32 = 0.02;

/// SplitMix64, seeded.
struct SeedRng(u64);

impl SeedRng {
    fn next(&mut self) -> f32 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 40) as f32 / (1u64 << 24) as f32
    }
    fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * self.next()
    }
}

fn shape(rng: &mut SeedRng, k: usize) -> SharedShape {
    let mut s = || rng.range(0.2, 0.5);
    if k % 100 == 50 {
        let parts = (0..3)
            .map(|i| {
                let pose = Isometry3::translation(0.3 * i as f32, 0.0, 0.0);
                (pose, SharedShape::cuboid(0.2, 0.3, 0.2))
            })
            .collect();
        return SharedShape::compound(parts);
    }
    if k % 100 == 99 {
        let n = 8;
        let mut vertices = Vec::new();
        for i in 0..=n {
            for j in 0..=n {
                let (x, z) = (i as f32 * 0.4 - 1.6, j as f32 * 0.4 - 1.6);
                vertices.push(Point3::new(x, 0.1 * (x * 3.0).sin() * (z * 2.0).cos(), z));
            }
        }
        let w = n + 1;
        let mut indices = Vec::new();
        for i in 0..n {
            for j in 0..n {
                let a = i * w + j;
                indices.push([a, a + 1, a + w]);
                indices.push([a + 1, a + w + 1, a + w]);
            }
        }
        return SharedShape::trimesh(vertices, indices).expect("grid mesh");
    }
    match k % 6 {
        0 => SharedShape::ball(s()),
        1 => SharedShape::cuboid(s(), s(), s()),
        2 => SharedShape::capsule_y(s(), s() * 0.5),
        3 => SharedShape::cylinder(s(), s()),
        4 => SharedShape::cone(s(), s()),
        _ => {
            let pts: Vec<Point3<f32>> = (0..10)
                .map(|_| Point3::new(s() - 0.35, s() - 0.35, s() - 0.35) * 2.0)
                .collect();
            SharedShape::convex_hull(&pts).unwrap_or_else(|| SharedShape::ball(0.3))
        }
    }
}

/// `n` objects on a jittered grid of spacing 1 (neighbours often touch).
fn scene(n: usize) -> Vec<(Isometry3<f32>, SharedShape)> {
    let mut rng = SeedRng(42);
    let side = (n as f32).cbrt().ceil() as usize;
    (0..n)
        .map(|k| {
            let (x, y, z) = (k % side, (k / side) % side, k / (side * side));
            let t = Vector3::new(x as f32, y as f32, z as f32)
                + Vector3::repeat(0.3) * rng.range(-1.0, 1.0);
            let r = Vector3::new(
                rng.range(-3.0, 3.0),
                rng.range(-3.0, 3.0),
                rng.range(-3.0, 3.0),
            );
            (Isometry3::new(t, r), shape(&mut rng, k))
        })
        .collect()
}

/// Pose of object `k` at update `t`: a small oscillation around its base pose.
fn moved(base: &Isometry3<f32>, k: usize, t: usize) -> Isometry3<f32> {
    let phase = 0.3 * t as f32 + k as f32;
    Isometry3::new(
        Vector3::new(phase.sin(), phase.cos(), 0.0) * 0.02,
        Vector3::new(0.0, phase.sin() * 0.05, 0.0),
    ) * base
}

fn bench(c: &mut Criterion) {
    for n in [1_000, 10_000] {
        let base = scene(n);
        let mut group = c.benchmark_group(format!("contacts/{n}"));
        group.sampling_mode(SamplingMode::Flat);
        group.sample_size(10);
        group.warm_up_time(Duration::from_millis(500));
        group.measurement_time(Duration::from_secs(if n > 1_000 { 20 } else { 5 }));

        for (name, coherence) in [
            ("world", Coherence::Persistent),
            ("world_fresh", Coherence::Fresh),
        ] {
            let mut world = CollisionWorld::with_coherence(coherence);
            let handles: Vec<ObjectHandle> = base
                .iter()
                .map(|(pose, shape)| {
                    world
                        .insert(shape.clone(), *pose, ())
                        .expect("valid object")
                })
                .collect();
            world.update(PREDICTION).expect("update");
            let mut t = 0;
            group.bench_function(name, |b| {
                b.iter(|| {
                    t += 1;
                    for (k, h) in handles.iter().enumerate() {
                        world.set_pose(*h, moved(&base[k].0, k, t)).expect("pose");
                    }
                    world.update(PREDICTION).expect("update");
                    world.stats().contact_pairs
                })
            });
            let s = world.stats();
            println!(
                "contacts/{n}/{name}: {} candidates, {} contact pairs; broad {:?}, narrow {:?}",
                s.candidate_pairs, s.contact_pairs, s.broad_phase, s.narrow_phase
            );
        }

        let mut objects = base.clone();
        let mut t = 0;
        group.bench_function("brute_force", |b| {
            b.iter(|| {
                t += 1;
                for (k, o) in objects.iter_mut().enumerate() {
                    o.0 = moved(&base[k].0, k, t);
                }
                brute_force::par_contact_pairs(&objects, PREDICTION).len()
            })
        });
        group.finish();
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
