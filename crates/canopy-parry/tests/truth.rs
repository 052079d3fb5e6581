//! The world against the truth: brute-force parry (`contact_manifolds` called fresh on every
//! pair of objects) through many updates of motion, insertion and removal.
//!
//! What is compared, and why: parry's manifold routines use the previous manifolds of a pair
//! (contact points are re-projected instead of recomputed when the relative motion is tiny,
//! GJK starts from the previous normal), so a world that keeps manifolds across updates can
//! legitimately differ from a fresh parry call in the last digits. The exact comparison is
//! therefore made with [`Coherence::Fresh`], where the world computes every manifold from
//! scratch like the brute force does: the set of pairs with contact points, for each pair the
//! set of (sub-shape, sub-shape) manifolds with points (triangles and compound parts), and
//! each such manifold's smallest point distance (the deepest penetration), within 1e-5. The
//! persistent (default) mode is checked in `coherence.rs` with the tolerance that coherence
//! implies. Contact events are checked against the truth's pair sets of consecutive updates.

mod common;

use std::collections::BTreeSet;

use canopy_parry::{Coherence, CollisionWorld, ContactEvent, ObjectHandle};
use common::*;
use proptest::prelude::*;

const TOL: f32 = 1.0e-5;

/// Runs `steps` updates of a random world of about `n` objects and compares each with the
/// truth. Returns the number of contact pairs seen (to check the scenes are not trivial).
pub fn run_fresh_scenario(
    seed: u64,
    n: usize,
    steps: usize,
    prediction: f32,
    deformable: bool,
) -> usize {
    let mut rng = SeedRng::new(seed);
    let extent = 2.2 * (n as f32).cbrt();
    let mut world: CollisionWorld<usize> = CollisionWorld::with_coherence(Coherence::Fresh);
    for k in 0..n {
        let pose = random_pose(&mut rng, extent);
        world.insert(random_shape(&mut rng, 0.7), pose, k).unwrap();
    }
    let cloth = deformable.then(|| {
        let (v, i) = grid_mesh(&mut rng, 4, 3.0, 0.2);
        world
            .insert_deformable(v, i, random_pose(&mut rng, extent), usize::MAX)
            .unwrap()
    });
    let mut before: BTreeSet<(ObjectHandle, ObjectHandle)> = BTreeSet::new();
    let mut seen = 0;
    for step in 0..steps {
        if step > 0 {
            let handles: Vec<ObjectHandle> = world.handles().collect();
            for &h in &handles {
                let roll = rng.range(0.0, 1.0);
                let pose = *world.pose(h).unwrap();
                if roll < 0.5 {
                    world.set_pose(h, jitter(&mut rng, &pose, 0.1)).unwrap();
                } else if roll < 0.6 {
                    world.set_pose(h, random_pose(&mut rng, extent)).unwrap();
                }
            }
            for _ in 0..rng.below(n / 8 + 2) {
                let live: Vec<ObjectHandle> =
                    world.handles().filter(|h| Some(*h) != cloth).collect();
                if let Some(&h) = live.get(rng.below(live.len().max(1))) {
                    world.remove(h).unwrap();
                    assert!(world.set_pose(h, random_pose(&mut rng, extent)).is_err());
                }
            }
            for _ in 0..rng.below(n / 8 + 2) {
                let pose = random_pose(&mut rng, extent);
                world.insert(random_shape(&mut rng, 0.7), pose, 0).unwrap();
            }
            if let Some(c) = cloth {
                let mut v = world.vertices(c).unwrap().to_vec();
                for p in &mut v {
                    p.coords += rng.vec3(-0.15, 0.15);
                }
                world.set_vertices(c, &v).unwrap();
            }
        }
        world.update(prediction).unwrap();
        let (handles, objects) = truth_objects(&world);
        let truth = truth_summary(&objects, prediction);
        let mine = world_summary(&world, &handles, prediction);
        assert_same(&mine, &truth, TOL, &format!("seed {seed} step {step}"));
        seen += truth.len();

        // Events: exactly the pairs that changed state since the last update.
        let now: BTreeSet<_> = truth
            .iter()
            .map(|((i, j), _)| (handles[*i], handles[*j]))
            .collect();
        let mut expected: Vec<ContactEvent> = now
            .difference(&before)
            .map(|&(a, b)| ContactEvent::Started(a, b))
            .chain(
                before
                    .difference(&now)
                    .map(|&(a, b)| ContactEvent::Stopped(a, b)),
            )
            .collect();
        expected.sort_by_key(|e| e.objects());
        assert_eq!(
            world.events(),
            &expected[..],
            "seed {seed} step {step}: events"
        );
        before = now;
    }
    seen
}

#[test]
fn dense_world_has_contacts_and_matches() {
    let seen = run_fresh_scenario(7, 60, 8, 0.05, true);
    assert!(
        seen > 100,
        "only {seen} contact pairs: the scene is too sparse to test anything"
    );
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(32))]

    #[test]
    fn fresh_world_equals_brute_force(
        seed in any::<u64>(),
        n in 2usize..48,
        steps in 1usize..8,
        prediction in prop_oneof![Just(0.0f32), 0.0f32..0.2],
        deformable in any::<bool>(),
    ) {
        run_fresh_scenario(seed, n, steps, prediction, deformable);
    }
}
