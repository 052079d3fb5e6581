//! Tests of the scenes: every scene builds at both sizes with the expected
//! bodies, steps with Rapier's `BroadPhaseBvh`, is deterministic, and the
//! hook-driven scenes do what they promise (churn, handle reuse, teleports).

use canopy_scenes::rapier3d::geometry::BroadPhaseBvh;
use canopy_scenes::rapier3d::math::{Real, Vector};
use canopy_scenes::rapier3d::prelude::{ColliderHandle, RigidBodyHandle};
use canopy_scenes::scenes::expected_bodies;
use canopy_scenes::{scene, Scene, Size, World, SCENE_NAMES};
use std::collections::{HashMap, HashSet};

fn world(name: &str, size: Size) -> World<BroadPhaseBvh> {
    World::new(scene(name, size).unwrap(), BroadPhaseBvh::new())
}

fn positions(scene: &Scene) -> Vec<(RigidBodyHandle, Vector<Real>)> {
    scene
        .bodies
        .iter()
        .map(|(h, b)| (h, *b.translation()))
        .collect()
}

#[test]
fn names_are_complete_and_ordered() {
    assert_eq!(
        SCENE_NAMES,
        [
            "balls",
            "boxes",
            "pyramid",
            "many_pyramids",
            "many_static",
            "many_sleep",
            "many_kinematics",
            "keva_tower",
            "spawn_storm",
            "teleport"
        ]
    );
    assert!(scene("nope", Size::Small).is_none());
    assert!(expected_bodies("nope", Size::Small).is_none());
}

#[test]
fn small_scenes_build_and_step() {
    for &name in SCENE_NAMES {
        let s = scene(name, Size::Small).unwrap();
        assert_eq!(s.name, name);
        let n = s.num_bodies();
        assert_eq!(Some(n), expected_bodies(name, Size::Small), "{name}");
        assert!(n <= 300, "{name}: {n} bodies is not small");
        assert_eq!(s.num_colliders(), n, "{name}: one collider per body");

        let mut w = World::new(s, BroadPhaseBvh::new());
        for _ in 0..10 {
            w.step();
        }
        assert_eq!(w.steps(), 10);
        assert!(w.step_ms_last_step() > 0.0, "{name}");
        assert_eq!(w.scene.num_bodies(), n, "{name}: population changed");
        for (h, p) in positions(&w.scene) {
            assert!(p.iter().all(|c| c.is_finite()), "{name}: {h:?} at {p:?}");
        }
    }
}

#[test]
fn small_scenes_have_the_expected_kinds_of_bodies() {
    let s = scene("balls", Size::Small).unwrap();
    assert_eq!((s.num_fixed(), s.num_dynamic()), (25, 100));
    assert!(s.hook.is_none());

    let s = scene("many_static", Size::Small).unwrap();
    assert_eq!((s.num_fixed(), s.num_dynamic()), (180, 36));

    let s = scene("many_sleep", Size::Small).unwrap();
    assert_eq!((s.num_fixed(), s.num_dynamic()), (36, 180));
    assert_eq!(s.num_sleeping(), 216);

    let s = scene("many_kinematics", Size::Small).unwrap();
    assert_eq!(s.num_kinematic(), 216);
    assert!(s.hook.is_some());
    assert!(s.bodies.iter().all(|(_, b)| b.linvel().norm() > 0.0));

    for name in [
        "boxes",
        "pyramid",
        "many_pyramids",
        "keva_tower",
        "spawn_storm",
    ] {
        let s = scene(name, Size::Small).unwrap();
        assert_eq!(s.num_fixed(), 1, "{name}: one ground");
        assert_eq!(s.num_dynamic(), s.num_bodies() - 1, "{name}");
    }
    let s = scene("teleport", Size::Small).unwrap();
    assert_eq!((s.num_fixed(), s.num_dynamic()), (4, 192));
    assert!(s.hook.is_some());
}

#[test]
fn many_sleep_stays_asleep() {
    let mut w = world("many_sleep", Size::Small);
    let before = positions(&w.scene);
    w.step_n(10);
    assert_eq!(w.scene.num_sleeping(), 216);
    assert!(w.islands.active_dynamic_bodies().is_empty());
    assert_eq!(positions(&w.scene), before);
}

#[test]
fn many_kinematics_moves_every_body_every_step() {
    let mut w = world("many_kinematics", Size::Small);
    let bound = 7.0 * 6.0 / 2.0;
    for _ in 0..200 {
        let before: HashMap<_, _> = positions(&w.scene).into_iter().collect();
        w.step();
        for (h, p) in positions(&w.scene) {
            assert_ne!(p, before[&h], "{h:?} did not move");
            // At most 15 * sqrt(3) / 60 per step past the bound.
            assert!(p.amax() < bound + 1.0, "{h:?} escaped to {p:?}");
        }
    }
}

#[test]
fn spawn_storm_churns_and_reuses_handles() {
    let mut w = world("spawn_storm", Size::Small);
    let n = w.scene.num_colliders();
    let mut seen: HashMap<u32, u32> = w
        .scene
        .colliders
        .iter()
        .map(|(h, _)| h.into_raw_parts())
        .collect();
    let mut reused = 0;
    let mut max_index = 0;
    for _ in 0..20 {
        let before: HashSet<ColliderHandle> = w.scene.colliders.iter().map(|(h, _)| h).collect();
        w.step();
        let after: HashSet<ColliderHandle> = w.scene.colliders.iter().map(|(h, _)| h).collect();
        assert_eq!(after.len(), n, "collider count must stay constant");
        assert_eq!(w.scene.num_bodies(), n);
        assert!(before.difference(&after).count() >= 2, "nothing removed");
        for h in after.difference(&before) {
            let (index, generation) = h.into_raw_parts();
            max_index = max_index.max(index);
            if let Some(old) = seen.insert(index, generation) {
                assert_ne!(old, generation);
                reused += 1;
            }
        }
    }
    assert!(reused > 0, "no collider index was reused");
    assert!((max_index as usize) < n, "the collider arena grew");
}

#[test]
fn teleport_makes_large_jumps() {
    let mut w = world("teleport", Size::Small);
    for _ in 0..5 {
        let before: HashMap<_, _> = positions(&w.scene).into_iter().collect();
        w.step();
        let jumps = positions(&w.scene)
            .into_iter()
            .filter(|(h, p)| (p - before[h]).norm() > 500.0)
            .count();
        assert!(jumps >= 1, "no body jumped at step {}", w.steps());
        assert!(jumps <= 4);
    }
}

#[test]
fn scenes_are_deterministic() {
    for &name in SCENE_NAMES {
        let a = scene(name, Size::Small).unwrap();
        let b = scene(name, Size::Small).unwrap();
        assert_eq!(positions(&a), positions(&b), "{name}");
        let ca: Vec<_> = a
            .colliders
            .iter()
            .map(|(h, c)| (h, *c.position(), c.shape().shape_type()))
            .collect();
        let cb: Vec<_> = b
            .colliders
            .iter()
            .map(|(h, c)| (h, *c.position(), c.shape().shape_type()))
            .collect();
        assert_eq!(ca, cb, "{name}");
    }
    for name in ["spawn_storm", "teleport"] {
        let mut a = world(name, Size::Small);
        let mut b = world(name, Size::Small);
        a.step_n(10);
        b.step_n(10);
        assert_eq!(positions(&a.scene), positions(&b.scene), "{name}");
    }
}

/// The stacks stand and the balls settle: what the comparisons with other
/// broad-phases rely on. (Hundreds of steps: Rapier unoptimized is about 100
/// times slower, so this runs in release builds only.)
#[test]
#[cfg_attr(debug_assertions, ignore = "slow unoptimized: run with --release")]
fn small_scenes_are_physically_sensible() {
    // Pyramids and towers stand: no cube ends up much lower than it started.
    // In `pyramid` the levels start 0.5 apart (spacing 2.5 for cubes of size
    // 2), so the cube of level `i`, at `y = 1 + 2.5 i`, settles `0.5 i` lower.
    for (name, gaps) in [
        ("pyramid", 0.2),
        ("many_pyramids", 0.0),
        ("keva_tower", 0.0),
    ] {
        let mut w = world(name, Size::Small);
        let before: HashMap<_, _> = positions(&w.scene).into_iter().collect();
        w.step_n(120);
        for (h, p) in positions(&w.scene) {
            let y0 = before[&h].y;
            let drop = y0 - p.y;
            let allowed = 0.1 + gaps * (y0 - 1.0).max(0.0) + 0.01 * y0;
            assert!(drop < allowed, "{name}: {h:?} fell by {drop} from {y0}");
        }
    }
    // The balls land on the balls below and come to rest above them.
    let mut w = world("balls", Size::Small);
    w.step_n(120);
    for (h, b) in w.scene.bodies.iter() {
        assert!(
            b.translation().y > 1.0,
            "{h:?} sank to {:?}",
            b.translation()
        );
        assert!(b.linvel().norm() < 1.0, "{h:?} still moving");
    }
    // Nothing falls through the ground(s).
    for name in ["boxes", "spawn_storm", "teleport"] {
        let mut w = world(name, Size::Small);
        w.step_n(120);
        for (h, b) in w.scene.bodies.iter() {
            assert!(
                b.translation().y > -0.5,
                "{name}: {h:?} at {:?}",
                b.translation()
            );
        }
    }
}

/// The full sizes, as in Rapier's benchmarks: `(name, bodies, fixed, dynamic,
/// kinematic)`; colliders are as many as bodies.
const FULL: [(&str, usize, usize, usize, usize); 10] = [
    ("balls", 8_000, 400, 7_600, 0),
    ("boxes", 1_001, 1, 1_000, 0),
    ("pyramid", 4_901, 1, 4_900, 0),
    ("many_pyramids", 8_401, 1, 8_400, 0),
    ("many_static", 125_000, 122_500, 2_500, 0),
    ("many_sleep", 125_000, 2_500, 122_500, 0),
    ("many_kinematics", 27_000, 0, 0, 27_000),
    ("keva_tower", 5_321, 1, 5_320, 0),
    ("spawn_storm", 4_001, 1, 4_000, 0),
    ("teleport", 4_100, 4, 4_096, 0),
];

#[test]
fn full_sizes_are_rapier_sizes() {
    for (name, n, ..) in FULL {
        assert_eq!(expected_bodies(name, Size::Full), Some(n), "{name}");
    }
}

/// Builds every full-size scene (without stepping it): about 0.3 s optimized
/// but some 15 s unoptimized, so this runs in release builds only.
#[test]
#[cfg_attr(debug_assertions, ignore = "slow unoptimized: run with --release")]
fn full_scenes_have_rapier_sizes() {
    for (name, n, fixed, dynamic, kinematic) in FULL {
        let s = scene(name, Size::Full).unwrap();
        assert_eq!(s.name, name);
        assert_eq!(s.num_bodies(), n, "{name}");
        assert_eq!(s.num_colliders(), n, "{name}");
        assert_eq!(
            (s.num_fixed(), s.num_dynamic(), s.num_kinematic()),
            (fixed, dynamic, kinematic),
            "{name}"
        );
        if name == "many_sleep" {
            assert_eq!(s.num_sleeping(), n);
        }
    }
}
