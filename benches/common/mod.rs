//! Shared helpers of the `core_build` and `core_queries` benches: deterministic inputs (a
//! SplitMix64 generator, random boxes at constant density, long random rays), conversion to
//! parry3d types, the SAH cost of a parry3d tree computed with canopy's formula, and running
//! code on a one-thread rayon pool.
//!
//! Scene: `n` boxes with centres uniform in `[0, L]^3`, `L = n^(1/3)` (one box per unit of
//! volume at every size), half-extents uniform in `[0.05, 0.5]` on each axis. Two boxes overlap
//! when their centres are closer than the sum of their half-extents on every axis, so a box
//! overlaps on average `density * E[2 (h1 + h2)]^3 = 1 * 1.1^3 ~ 1.33` others (a bit fewer near
//! the scene's faces).

// Each bench uses a subset of these helpers.
#![allow(dead_code)]

use canopy::core::nalgebra::{Point3, Vector3};
use canopy::core::{Aabb, Ray};
use parry3d::partitioning::{Bvh as ParryBvh, TraversalAction};

/// Sizes every bench runs at.
pub const SIZES: [usize; 3] = [10_000, 100_000, 1_000_000];

/// A short name for a size: `10k`, `100k`, `1M`.
pub fn size_label(n: usize) -> String {
    if n >= 1_000_000 && n % 1_000_000 == 0 {
        format!("{}M", n / 1_000_000)
    } else if n >= 1_000 && n % 1_000 == 0 {
        format!("{}k", n / 1_000)
    } else {
        n.to_string()
    }
}

/// SplitMix64 (Steele, Lea, Flood 2014): tiny, fast, and good enough for benchmark inputs.
#[derive(Clone, Debug)]
pub struct SplitMix64(u64);

impl SplitMix64 {
    /// A generator seeded with `seed`.
    pub fn new(seed: u64) -> Self {
        Self(seed)
    }

    /// The next 64 random bits.
    #[inline]
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    /// Uniform in `[0, 1)`, 24 random bits.
    #[inline]
    pub fn next_f32(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 * (1.0 / (1u64 << 24) as f32)
    }

    /// Uniform in `[lo, hi)`.
    #[inline]
    pub fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * self.next_f32()
    }

    /// A uniformly distributed unit vector (rejection sampling in the unit ball).
    pub fn unit_vector(&mut self) -> Vector3<f32> {
        loop {
            let v = Vector3::new(
                self.range(-1.0, 1.0),
                self.range(-1.0, 1.0),
                self.range(-1.0, 1.0),
            );
            let n2 = v.norm_squared();
            if n2 > 1e-4 && n2 <= 1.0 {
                return v / n2.sqrt();
            }
        }
    }
}

/// Side of the cube holding the box centres for `n` boxes: `n^(1/3)`, one box per unit volume.
pub fn scene_side(n: usize) -> f32 {
    (n as f64).cbrt() as f32
}

/// `n` random boxes at constant density (see the module comment), the same for the same seed.
pub fn random_boxes(n: usize, seed: u64) -> Vec<Aabb> {
    let mut rng = SplitMix64::new(seed);
    let side = scene_side(n);
    (0..n)
        .map(|_| {
            let c = Point3::new(
                rng.range(0.0, side),
                rng.range(0.0, side),
                rng.range(0.0, side),
            );
            let h = Vector3::new(
                rng.range(0.05, 0.5),
                rng.range(0.05, 0.5),
                rng.range(0.05, 0.5),
            );
            Aabb::from_center_half_extents(c, h)
        })
        .collect()
}

/// The smallest box holding every box of `boxes`.
pub fn bounds_of(boxes: &[Aabb]) -> Aabb {
    boxes.iter().fold(Aabb::EMPTY, |acc, b| acc.merge(b))
}

/// Length of the diagonal of `bounds`: the `t_max` of the long rays (unit directions).
pub fn diagonal(bounds: &Aabb) -> f32 {
    bounds.extents().norm()
}

/// `n` "long rays": origins uniform inside `bounds`, uniformly random unit directions. Cast them
/// with `t_max = diagonal(bounds)`, which reaches across the whole scene.
pub fn random_rays(n: usize, seed: u64, bounds: &Aabb) -> Vec<Ray> {
    let mut rng = SplitMix64::new(seed);
    (0..n)
        .map(|_| {
            let o = Point3::new(
                rng.range(bounds.min.x, bounds.max.x),
                rng.range(bounds.min.y, bounds.max.y),
                rng.range(bounds.min.z, bounds.max.z),
            );
            Ray::new(o, rng.unit_vector())
        })
        .collect()
}

/// The same boxes as parry3d boxes.
pub fn to_parry(boxes: &[Aabb]) -> Vec<parry3d::bounding_volume::Aabb> {
    boxes
        .iter()
        .map(|b| parry3d::bounding_volume::Aabb::new(b.min, b.max))
        .collect()
}

/// The same rays as parry3d rays.
pub fn rays_to_parry(rays: &[Ray]) -> Vec<parry3d::query::Ray> {
    rays.iter()
        .map(|r| parry3d::query::Ray::new(r.origin, r.dir))
        .collect()
}

/// Surface area in `f64`, as canopy computes it.
fn parry_area(b: &parry3d::bounding_volume::Aabb) -> f64 {
    let d = [
        (b.maxs.x as f64 - b.mins.x as f64).max(0.0),
        (b.maxs.y as f64 - b.mins.y as f64).max(0.0),
        (b.maxs.z as f64 - b.mins.z as f64).max(0.0),
    ];
    2.0 * (d[0] * d[1] + d[1] * d[2] + d[2] * d[0])
}

/// SAH cost of a parry3d tree with canopy's formula and unit costs (see
/// `canopy::core::Bvh::sah_cost`): `sum over interior nodes of A(n)/A(root)` plus `sum over
/// leaves of A(l)/A(root) * count(l)`.
///
/// parry stores the root implicitly, as the two nodes of wide node 0: with two or more leaves it
/// counts as one interior node of ratio 1. `Bvh::traverse` then visits every `BvhNode` (each half
/// of each wide node); a leaf (`is_leaf()`, i.e. `leaf_count() == 1`) holds exactly one
/// primitive, so leaves and interior nodes alike add their area ratio. With a single leaf,
/// `traverse` visits only that leaf (the root), which adds 1.
pub fn parry_sah_cost(bvh: &ParryBvh) -> f64 {
    if bvh.is_empty() {
        return 0.0;
    }
    let ra = parry_area(&bvh.root_aabb());
    let ratio = |b: &parry3d::bounding_volume::Aabb| {
        if ra > 0.0 {
            parry_area(b) / ra
        } else {
            1.0
        }
    };
    let mut cost = if bvh.leaf_count() >= 2 { 1.0 } else { 0.0 };
    bvh.traverse(|node| {
        cost += ratio(&node.aabb());
        TraversalAction::Continue
    });
    cost
}

/// Node count (the implicit root included) and depth (longest root-to-leaf path in edges, as in
/// canopy's stats) of a parry3d tree.
pub fn parry_shape(bvh: &ParryBvh) -> (usize, usize) {
    if bvh.is_empty() {
        return (0, 0);
    }
    let mut nodes = if bvh.leaf_count() >= 2 { 1 } else { 0 };
    bvh.traverse(|_| {
        nodes += 1;
        TraversalAction::Continue
    });
    (nodes, bvh.subtree_depth(0) as usize - 1)
}

/// A rayon pool with one thread, for timing the serial paths.
pub fn one_thread_pool() -> rayon::ThreadPool {
    rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("building a one-thread rayon pool")
}

/// Runs `f` on a fresh one-thread rayon pool.
pub fn in_one_thread<R: Send>(f: impl FnOnce() -> R + Send) -> R {
    one_thread_pool().install(f)
}

/// Sample settings per size, so that the whole bench runs in a few minutes on two cores.
pub fn configure_group(
    group: &mut criterion::BenchmarkGroup<'_, criterion::measurement::WallTime>,
    n: usize,
) {
    use criterion::SamplingMode;
    use std::time::Duration;
    if n >= 1_000_000 {
        group
            .sampling_mode(SamplingMode::Flat)
            .sample_size(10)
            .warm_up_time(Duration::from_secs(1))
            .measurement_time(Duration::from_secs(5));
    } else if n >= 100_000 {
        group.sampling_mode(SamplingMode::Flat).sample_size(15);
    } else {
        group.sample_size(30);
    }
}
