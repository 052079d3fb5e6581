//! Deformable self-collision against the brute-force triangle pairs: for a random cloth whose
//! vertices move every update, the world's self-contacts (refit BVH, non-adjacent triangle
//! pairs) are exactly those of parry's convex-convex code on all non-adjacent pairs.

mod common;

use canopy_parry::{brute_force, CollisionWorld};
use common::*;
use nalgebra::Isometry3;
use proptest::prelude::*;

fn run(seed: u64, n: usize, steps: usize, prediction: f32, motion: f32) -> usize {
    let mut rng = SeedRng::new(seed);
    let (mut v, i) = grid_mesh(&mut rng, n, 2.0, 0.1);
    let mut world = CollisionWorld::new();
    let cloth = world
        .insert_deformable(v.clone(), i.clone(), Isometry3::identity(), ())
        .unwrap();
    let mut seen = 0;
    for step in 0..steps {
        if step > 0 {
            for p in &mut v {
                p.coords += rng.vec3(-motion, motion);
            }
            world.set_vertices(cloth, &v).unwrap();
        }
        world.update(prediction).unwrap();
        let mine: Vec<(u32, u32, f32)> = world
            .self_contacts()
            .iter()
            .map(|c| {
                let d = canopy_parry::min_distance(std::slice::from_ref(&c.manifold)).unwrap();
                (c.triangle1, c.triangle2, d)
            })
            .collect();
        let truth: Vec<(u32, u32, f32)> = brute_force::self_contacts(&v, &i, prediction)
            .expect("the world accepted the mesh")
            .iter()
            .map(|(a, b, m)| {
                (
                    *a,
                    *b,
                    canopy_parry::min_distance(std::slice::from_ref(m)).unwrap(),
                )
            })
            .collect();
        assert_eq!(mine, truth, "seed {seed} step {step}");
        seen += truth.len();
    }
    seen
}

#[test]
fn flat_cloth_has_no_self_contact() {
    assert_eq!(run(1, 8, 1, 0.01, 0.0), 0);
}

#[test]
fn crumpled_cloth_has_self_contacts() {
    let seen: usize = (0..4).map(|s| run(s, 6, 4, 0.02, 0.3)).sum();
    assert!(seen > 20, "only {seen} self-contacts");
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(32))]

    #[test]
    fn self_contacts_equal_brute_force(
        seed in any::<u64>(),
        n in 1usize..8,
        steps in 1usize..6,
        prediction in prop_oneof![Just(0.0f32), 0.0f32..0.1],
        motion in 0.0f32..0.5,
    ) {
        run(seed, n, steps, prediction, motion);
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    /// Bad input gets an error, never a panic (parry's GJK asserted finite bounds on a
    /// vertex at `f32::MAX`), and exactly where the world refuses the same mesh and
    /// prediction (`insert_deformable`, then `update`); where both accept it, the same
    /// self-contacts, and `triangle_pair_manifold` on each pair found gives its manifold.
    #[test]
    fn self_contacts_refuse_what_the_world_refuses(
        vertices in prop::collection::vec(prop::array::uniform3(extreme_coordinate()), 3..9),
        indices in prop::collection::vec(prop::array::uniform3(0u32..10), 0..6),
        prediction in any_prediction(),
    ) {
        let v: Vec<nalgebra::Point3<f32>> = vertices.iter().map(|&p| p.into()).collect();
        let truth = brute_force::self_contacts(&v, &indices, prediction);
        let mut world = CollisionWorld::new();
        let accepted = world
            .insert_deformable(v.clone(), indices.clone(), Isometry3::identity(), ())
            .and_then(|_| world.update(prediction));
        prop_assert_eq!(truth.is_ok(), accepted.is_ok(), "{:?} against {:?}", truth.as_ref().err(), accepted);
        if let Ok(truth) = truth {
            let mine: Vec<(u32, u32)> = world
                .self_contacts()
                .iter()
                .map(|c| (c.triangle1, c.triangle2))
                .collect();
            let keys: Vec<(u32, u32)> = truth.iter().map(|c| (c.0, c.1)).collect();
            prop_assert_eq!(&mine, &keys);
            for (t1, t2, _) in &truth {
                let m = canopy_parry::triangle_pair_manifold(&v, &indices, *t1, *t2, prediction);
                prop_assert!(m.is_some());
            }
        }
        // Any pair of any triangles, valid or not: an answer, no panic.
        for t1 in 0..indices.len() as u32 + 1 {
            for t2 in 0..indices.len() as u32 + 1 {
                let _ = canopy_parry::triangle_pair_manifold(&v, &indices, t1, t2, prediction);
            }
        }
    }
}
