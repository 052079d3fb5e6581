//! Mesh-vs-mesh pruning against the brute-force triangle pairs: for two random meshes (with
//! and without parry's pseudo-normal constraints) the world's manifolds with points are exactly
//! those of parry's convex-convex code run on all `n1 × n2` triangle pairs, with the same
//! deepest distances (and the same as parry's own mesh-mesh routine on the whole meshes).

mod common;

use canopy_parry::{brute_force, Coherence, CollisionWorld};
use common::*;
use nalgebra::Isometry3;
use parry3d::shape::{SharedShape, TriMesh, TriMeshFlags};
use proptest::prelude::*;

fn random_mesh(rng: &mut SeedRng, fix_edges: bool) -> TriMesh {
    let (v, i) = if rng.below(3) == 0 {
        let half = rng.vec3(0.3, 1.2);
        parry3d::shape::Cuboid::new(half).to_trimesh()
    } else {
        let n = 2 + rng.below(6);
        grid_mesh(rng, n, 3.0, 0.6)
    };
    let flags = if fix_edges {
        TriMeshFlags::FIX_INTERNAL_EDGES
    } else {
        TriMeshFlags::empty()
    };
    TriMesh::with_flags(v, i, flags).expect("valid mesh")
}

fn check(seed: u64, prediction: f32, fix_edges: bool) -> usize {
    let mut rng = SeedRng::new(seed);
    let m1 = random_mesh(&mut rng, fix_edges);
    let m2 = random_mesh(&mut rng, fix_edges);
    let pose1 = random_pose(&mut rng, 0.5);
    let pose2: Isometry3<f32> = random_pose(&mut rng, 0.5);
    let mut world = CollisionWorld::with_coherence(Coherence::Fresh);
    world
        .insert(SharedShape::new(m1.clone()), pose1, ())
        .unwrap();
    world
        .insert(SharedShape::new(m2.clone()), pose2, ())
        .unwrap();
    world.update(prediction).unwrap();
    let mut mine: Vec<(u32, u32, f32)> = world
        .contact_pairs()
        .flat_map(|p| p.manifolds().iter())
        .filter_map(|m| {
            canopy_parry::min_distance(std::slice::from_ref(m))
                .filter(|d| *d <= prediction)
                .map(|d| (m.subshape1, m.subshape2, d))
        })
        .collect();
    mine.sort_by_key(|m| (m.0, m.1));
    let truth = brute_force::mesh_mesh_triangle_pairs(&m1, &pose1, &m2, &pose2, prediction)
        .expect("the world accepted both meshes");
    let keys = |v: &[(u32, u32, f32)]| v.iter().map(|m| (m.0, m.1)).collect::<Vec<_>>();
    assert_eq!(
        keys(&mine),
        keys(&truth),
        "seed {seed}: triangle pairs differ"
    );
    for (a, b) in mine.iter().zip(&truth) {
        assert!((a.2 - b.2).abs() <= 1e-5, "seed {seed}: {a:?} vs {b:?}");
    }
    // And the same as parry's own mesh-mesh routine on the whole meshes.
    let objects = [(pose1, SharedShape::new(m1)), (pose2, SharedShape::new(m2))];
    let mut whole: Vec<(u32, u32, f32)> = brute_force::pair(&objects, 0, 1, prediction)
        .unwrap_or_default()
        .iter()
        .filter_map(|m| {
            canopy_parry::min_distance(std::slice::from_ref(m))
                .filter(|d| *d <= prediction)
                .map(|d| (m.subshape1, m.subshape2, d))
        })
        .collect();
    whole.sort_by_key(|m| (m.0, m.1));
    assert_eq!(whole, truth, "seed {seed}: parry's mesh-mesh routine");
    truth.len()
}

#[test]
fn meshes_do_intersect_in_these_scenes() {
    let total: usize = (0..20).map(|s| check(s, 0.02, false)).sum();
    assert!(total > 50, "only {total} triangle pairs");
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn mesh_mesh_triangle_pairs_equal_brute_force(
        seed in any::<u64>(),
        prediction in prop_oneof![Just(0.0f32), 0.0f32..0.2],
        fix_edges in any::<bool>(),
    ) {
        check(seed, prediction, fix_edges);
    }
}

fn extreme_mesh(vertices: &[[f32; 3]], indices: &[[u32; 3]]) -> Option<TriMesh> {
    let v = vertices.iter().map(|&p| p.into()).collect();
    let n = vertices.len() as u32;
    let i = indices.iter().map(|t| t.map(|k| k % n)).collect();
    TriMesh::new(v, i).ok()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    /// Bad input gets an error, never a panic (parry's GJK asserted finite bounds on a
    /// vertex at `f32::MAX`), and exactly where the world refuses the same two meshes at
    /// these poses and this prediction (`insert`, then `update`).
    #[test]
    fn mesh_mesh_triangle_pairs_refuse_what_the_world_refuses(
        v1 in prop::collection::vec(prop::array::uniform3(extreme_coordinate()), 3..7),
        i1 in prop::collection::vec(prop::array::uniform3(0u32..7), 1..4),
        v2 in prop::collection::vec(prop::array::uniform3(extreme_coordinate()), 3..7),
        i2 in prop::collection::vec(prop::array::uniform3(0u32..7), 1..4),
        t in prop::array::uniform3(extreme_coordinate()),
        r in prop::array::uniform4(prop_oneof![4 => -1.0f32..1.0, 1 => Just(f32::NAN)]),
        prediction in any_prediction(),
    ) {
        use nalgebra::{Quaternion, Translation3, UnitQuaternion};
        let (Some(m1), Some(m2)) = (extreme_mesh(&v1, &i1), extreme_mesh(&v2, &i2)) else {
            return Ok(());
        };
        let q = Quaternion::new(r[0], r[1], r[2], r[3]);
        // Mostly unit rotations; a NaN one stays NaN (`check_pose` refuses it).
        let rotation = if q.norm() > 1e-3 || q.norm().is_nan() {
            UnitQuaternion::new_unchecked(q / q.norm())
        } else {
            UnitQuaternion::identity()
        };
        let pose2 = Isometry3::from_parts(Translation3::new(t[0], t[1], t[2]), rotation);
        let pose1 = Isometry3::identity();
        let truth = brute_force::mesh_mesh_triangle_pairs(&m1, &pose1, &m2, &pose2, prediction);
        let mut world = CollisionWorld::new();
        let accepted = world
            .insert(SharedShape::new(m1), pose1, ())
            .and_then(|_| world.insert(SharedShape::new(m2), pose2, ()))
            .and_then(|_| world.update(prediction));
        prop_assert_eq!(truth.is_ok(), accepted.is_ok(), "{:?} against {:?}", truth.err(), accepted);
    }
}
