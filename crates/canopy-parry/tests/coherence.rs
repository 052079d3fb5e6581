//! The default, persistent mode against the truth. parry re-projects a pair's previous
//! contact points instead of recomputing them when the relative motion since the last call is
//! under about 1° and 1e-3 (`ContactManifold::try_update_contacts`), so the depths of a world
//! that keeps manifolds (as parry intends) drift from a fresh parry call by up to that motion
//! times the shape size. Checked here, through many small and larger motions: the same pairs
//! have contact points (except pairs within `TOL` of the prediction boundary, where a kept
//! point may legitimately survive or not), and their deepest distances agree within `TOL`.

mod common;

use std::collections::BTreeMap;

use canopy_parry::{CollisionWorld, ObjectHandle};
use common::*;
use proptest::prelude::*;

const TOL: f32 = 1.0e-2;

fn deepest(summary: &Summary) -> BTreeMap<(usize, usize), f32> {
    summary
        .iter()
        .map(|(k, v)| (*k, v.iter().map(|m| m.2).fold(f32::MAX, f32::min)))
        .collect()
}

fn run(seed: u64, n: usize, steps: usize, prediction: f32) {
    let mut rng = SeedRng::new(seed);
    let extent = 2.2 * (n as f32).cbrt();
    let mut world: CollisionWorld = CollisionWorld::new();
    for _ in 0..n {
        let pose = random_pose(&mut rng, extent);
        world.insert(random_shape(&mut rng, 0.7), pose, ()).unwrap();
    }
    for step in 0..steps {
        let handles: Vec<ObjectHandle> = world.handles().collect();
        for &h in &handles {
            let pose = *world.pose(h).unwrap();
            let size = [0.0, 0.0005, 0.005, 0.05][rng.below(4)];
            world.set_pose(h, jitter(&mut rng, &pose, size)).unwrap();
        }
        if rng.below(3) == 0 {
            let h = handles[rng.below(handles.len())];
            world.remove(h).unwrap();
            let pose = random_pose(&mut rng, extent);
            world.insert(random_shape(&mut rng, 0.7), pose, ()).unwrap();
        }
        world.update(prediction).unwrap();
        let (handles, objects) = truth_objects(&world);
        let truth = deepest(&truth_summary(&objects, prediction));
        let mine = deepest(&world_summary(&world, &handles, prediction));
        let near_boundary = |d: f32| (d - prediction).abs() <= TOL;
        for (k, d) in &truth {
            match mine.get(k) {
                Some(w) => assert!(
                    (w - d).abs() <= TOL,
                    "seed {seed} step {step} pair {k:?}: {w} vs truth {d}"
                ),
                None => assert!(
                    near_boundary(*d),
                    "seed {seed} step {step}: missing {k:?} ({d})"
                ),
            }
        }
        for (k, w) in &mine {
            assert!(
                truth.contains_key(k) || near_boundary(*w),
                "seed {seed} step {step}: extra pair {k:?} ({w})"
            );
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    #[test]
    fn persistent_world_tracks_brute_force(
        seed in any::<u64>(),
        n in 2usize..40,
        steps in 1usize..16,
        prediction in prop_oneof![Just(0.0f32), 0.0f32..0.1],
    ) {
        run(seed, n, steps, prediction);
    }
}
