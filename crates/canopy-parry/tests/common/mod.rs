//! Shared test helpers: a seeded generator of random shapes, poses and meshes, the
//! comparison of a world's contacts with brute-force parry, and proptest strategies for bad
//! input.

#![allow(dead_code)]

use canopy_parry::{brute_force, CollisionWorld, ObjectHandle};
use nalgebra::{Isometry3, Point3, Vector3};
use parry3d::shape::{SharedShape, TriMesh};
use proptest::prelude::*;

/// A coordinate from ordinary to extreme, for tests of bad input: NaN, the infinities,
/// `f32::MAX`, values either side of `MAX_COORDINATE`.
pub fn extreme_coordinate() -> impl Strategy<Value = f32> {
    let edge = canopy_parry::MAX_COORDINATE;
    prop_oneof![
        6 => -2.0f32..2.0,
        1 => Just(f32::NAN),
        1 => prop_oneof![Just(f32::INFINITY), Just(f32::NEG_INFINITY)],
        1 => prop_oneof![Just(f32::MAX), Just(-f32::MAX), Just(3.0e38f32)],
        1 => prop_oneof![Just(edge), Just(-edge), Just(edge * 1.5), Just(edge - 1.0)],
    ]
}

/// A prediction distance, valid or not (negative, NaN, infinite, far too large).
pub fn any_prediction() -> impl Strategy<Value = f32> {
    prop_oneof![
        4 => 0.0f32..0.5,
        1 => Just(-1.0f32),
        1 => Just(f32::NAN),
        1 => Just(f32::INFINITY),
        1 => Just(1.0e30f32),
    ]
}

/// SplitMix64: small, seeded, reproducible.
pub struct SeedRng(u64);

impl SeedRng {
    pub fn new(seed: u64) -> Self {
        SeedRng(seed ^ 0x9E37_79B9_7F4A_7C15)
    }
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in `[lo, hi)`.
    pub fn range(&mut self, lo: f32, hi: f32) -> f32 {
        let u = (self.next_u64() >> 40) as f32 / (1u64 << 24) as f32;
        lo + (hi - lo) * u
    }
    pub fn below(&mut self, n: usize) -> usize {
        (self.next_u64() % n as u64) as usize
    }
    pub fn vec3(&mut self, lo: f32, hi: f32) -> Vector3<f32> {
        Vector3::new(self.range(lo, hi), self.range(lo, hi), self.range(lo, hi))
    }
}

/// A random pose in a cube of side `extent`, with a random rotation.
pub fn random_pose(rng: &mut SeedRng, extent: f32) -> Isometry3<f32> {
    let t = rng.vec3(0.0, extent);
    let axis = rng.vec3(-3.2, 3.2);
    Isometry3::new(t, axis)
}

/// A small pose change: translation up to `step`, rotation up to `step` radians.
pub fn jitter(rng: &mut SeedRng, pose: &Isometry3<f32>, step: f32) -> Isometry3<f32> {
    Isometry3::new(rng.vec3(-step, step), rng.vec3(-step, step)) * pose
}

/// A height-field-like grid of `n × n` cells (2n² triangles), side `size`, random heights.
pub fn grid_mesh(
    rng: &mut SeedRng,
    n: usize,
    size: f32,
    bump: f32,
) -> (Vec<Point3<f32>>, Vec<[u32; 3]>) {
    let mut vertices = Vec::new();
    for i in 0..=n {
        for j in 0..=n {
            let x = size * i as f32 / n as f32 - size / 2.0;
            let z = size * j as f32 / n as f32 - size / 2.0;
            vertices.push(Point3::new(x, rng.range(-bump, bump), z));
        }
    }
    let mut indices = Vec::new();
    let w = (n + 1) as u32;
    for i in 0..n as u32 {
        for j in 0..n as u32 {
            let a = i * w + j;
            indices.push([a, a + 1, a + w]);
            indices.push([a + 1, a + w + 1, a + w]);
        }
    }
    (vertices, indices)
}

/// A random convex shape (ball, cuboid, capsule, cylinder, cone, convex hull, round cuboid).
pub fn random_convex(rng: &mut SeedRng, scale: f32) -> SharedShape {
    let s = |rng: &mut SeedRng| rng.range(0.2 * scale, scale);
    match rng.below(7) {
        0 => SharedShape::ball(s(rng)),
        1 => SharedShape::cuboid(s(rng), s(rng), s(rng)),
        2 => SharedShape::capsule_y(s(rng), s(rng) * 0.5),
        3 => SharedShape::cylinder(s(rng), s(rng)),
        4 => SharedShape::cone(s(rng), s(rng)),
        5 => {
            let points: Vec<Point3<f32>> = (0..8).map(|_| rng.vec3(-scale, scale).into()).collect();
            SharedShape::convex_hull(&points).unwrap_or_else(|| SharedShape::ball(scale))
        }
        _ => SharedShape::round_cuboid(s(rng), s(rng), s(rng), 0.1 * scale),
    }
}

/// A random shape: mostly convex, sometimes a compound, a grid mesh or a closed box mesh.
pub fn random_shape(rng: &mut SeedRng, scale: f32) -> SharedShape {
    match rng.below(10) {
        0 => {
            let parts = (0..2 + rng.below(3))
                .map(|_| {
                    let pose = Isometry3::new(rng.vec3(-scale, scale), rng.vec3(-3.0, 3.0));
                    (pose, random_convex(rng, scale * 0.6))
                })
                .collect();
            SharedShape::compound(parts)
        }
        1 => {
            let n = 2 + rng.below(4);
            let (v, i) = grid_mesh(rng, n, 3.0 * scale, 0.3 * scale);
            SharedShape::trimesh(v, i).expect("grid mesh")
        }
        2 => {
            let half = Vector3::new(
                rng.range(0.3, 1.0),
                rng.range(0.3, 1.0),
                rng.range(0.3, 1.0),
            ) * scale;
            let mesh = TriMesh::from(parry3d::shape::Cuboid::new(half));
            SharedShape::new(mesh)
        }
        _ => random_convex(rng, scale),
    }
}

/// Contacts of one pair, reduced to what is compared: each manifold with a point within the
/// prediction distance as `(subshape1, subshape2, smallest distance)`, sorted.
pub type Summary = Vec<((usize, usize), Vec<(u32, u32, f32)>)>;

fn reduce(manifolds: &[canopy_parry::Manifold], prediction: f32) -> Vec<(u32, u32, f32)> {
    let mut out: Vec<(u32, u32, f32)> = manifolds
        .iter()
        .filter_map(|m| {
            canopy_parry::min_distance(std::slice::from_ref(m))
                .filter(|d| *d <= prediction)
                .map(|d| (m.subshape1, m.subshape2, d))
        })
        .collect();
    out.sort_by_key(|m| (m.0, m.1));
    out
}

/// The world's live objects in handle order, as `(pose, shape)` for brute force (a deformable
/// mesh becomes a parry `TriMesh` of its current vertices).
pub fn truth_objects<T>(
    world: &CollisionWorld<T>,
) -> (Vec<ObjectHandle>, Vec<(Isometry3<f32>, SharedShape)>) {
    let handles: Vec<ObjectHandle> = world.handles().collect();
    let objects = handles
        .iter()
        .map(|&h| {
            let pose = *world.pose(h).unwrap();
            let shape = match world.shape(h).unwrap() {
                Some(s) => s.clone(),
                None => SharedShape::trimesh(
                    world.vertices(h).unwrap().to_vec(),
                    world.indices(h).unwrap().to_vec(),
                )
                .unwrap(),
            };
            (pose, shape)
        })
        .collect();
    (handles, objects)
}

/// The world's contact pairs with object positions in `handles`.
pub fn world_summary<T>(
    world: &CollisionWorld<T>,
    handles: &[ObjectHandle],
    prediction: f32,
) -> Summary {
    world
        .contact_pairs()
        .map(|p| {
            let (a, b) = p.objects();
            let i = handles.binary_search(&a).expect("live handle");
            let j = handles.binary_search(&b).expect("live handle");
            ((i, j), reduce(p.manifolds(), prediction))
        })
        .collect()
}

/// Brute-force parry on every pair.
pub fn truth_summary(objects: &[(Isometry3<f32>, SharedShape)], prediction: f32) -> Summary {
    brute_force::par_contact_pairs(objects, prediction)
        .into_iter()
        .map(|(i, j, m)| ((i, j), reduce(&m, prediction)))
        .collect()
}

/// Asserts same pairs, same manifolds with points (by sub-shapes), distances within `tol`.
pub fn assert_same(world: &Summary, truth: &Summary, tol: f32, context: &str) {
    let wp: Vec<_> = world.iter().map(|p| p.0).collect();
    let tp: Vec<_> = truth.iter().map(|p| p.0).collect();
    assert_eq!(wp, tp, "{context}: contact pairs differ");
    for (w, t) in world.iter().zip(truth) {
        let wk: Vec<_> = w.1.iter().map(|m| (m.0, m.1)).collect();
        let tk: Vec<_> = t.1.iter().map(|m| (m.0, m.1)).collect();
        assert_eq!(wk, tk, "{context}: manifolds of pair {:?} differ", w.0);
        for (wm, tm) in w.1.iter().zip(&t.1) {
            assert!(
                (wm.2 - tm.2).abs() <= tol,
                "{context}: pair {:?} sub-shapes ({}, {}): distance {} vs truth {}",
                w.0,
                wm.0,
                wm.1,
                wm.2,
                tm.2
            );
        }
    }
}
