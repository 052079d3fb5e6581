//! Soft CCD: Rapier's narrow phase makes contacts for a collider whose parent has soft CCD up
//! to `dt` times the (capped) relative velocity away, in every direction, so canopy must keep
//! those pairs live. The truth is Rapier's own narrow phase: the scene is stepped with Rapier's
//! `BroadPhaseBvh`, canopy is fed the same updates, and after every step each pair with an
//! active contact must be live in canopy.

use canopy::rapier::CanopyBroadPhase;
use canopy::scenes::{Scene, World, XorShift};
use rapier3d::prelude::*;

/// Rapier's broadphase drives the simulation; canopy sees the same updates.
struct Twin {
    rapier: BroadPhaseBvh,
    canopy: CanopyBroadPhase,
    events: Vec<BroadPhasePairEvent>,
}

impl BroadPhase for Twin {
    fn update(
        &mut self,
        params: &IntegrationParameters,
        colliders: &ColliderSet,
        bodies: &RigidBodySet,
        modified: &[ColliderHandle],
        removed: &[ColliderHandle],
        events: &mut Vec<BroadPhasePairEvent>,
    ) {
        self.rapier
            .update(params, colliders, bodies, modified, removed, events);
        self.events.clear();
        self.canopy.update(
            params,
            colliders,
            bodies,
            modified,
            removed,
            &mut self.events,
        );
    }
}

/// Thin fixed walls, and fast balls and flat boxes with soft CCD thrown at them (and past
/// each other) from random positions, with random spins and soft-CCD distances.
fn scene(seed: u64) -> Scene {
    let mut s = Scene::empty("soft_ccd");
    let ground = s.bodies.insert(RigidBodyBuilder::fixed());
    s.colliders.insert_with_parent(
        ColliderBuilder::cuboid(50.0, 0.1, 50.0),
        ground,
        &mut s.bodies,
    );
    for k in 0..5 {
        let wall = s
            .bodies
            .insert(RigidBodyBuilder::fixed().translation(vector![
                10.0 + 3.0 * k as f32,
                2.0,
                0.0
            ]));
        s.colliders.insert_with_parent(
            ColliderBuilder::cuboid(0.02, 2.0, 10.0),
            wall,
            &mut s.bodies,
        );
    }
    let mut rng = XorShift::new(seed);
    let mut r = move || rng.next_f32();
    for i in 0..200 {
        let speed = 20.0 + 200.0 * r();
        let body = s.bodies.insert(
            RigidBodyBuilder::dynamic()
                .translation(vector![
                    -5.0 + 4.0 * r(),
                    0.5 + 3.0 * r(),
                    -8.0 + 16.0 * r()
                ])
                .linvel(vector![speed, 10.0 * (r() - 0.5), 10.0 * (r() - 0.5)])
                .angvel(vector![30.0 * r(), 30.0 * r(), 30.0 * r()])
                .soft_ccd_prediction(0.5 + 3.0 * r()),
        );
        let shape = if i % 2 == 0 {
            ColliderBuilder::ball(0.05 + 0.2 * r())
        } else {
            ColliderBuilder::cuboid(0.02 + 0.3 * r(), 0.05, 0.2)
        };
        s.colliders.insert_with_parent(shape, body, &mut s.bodies);
    }
    s
}

#[test]
fn every_soft_ccd_contact_is_a_live_pair() {
    let (mut checked, mut beyond_boxes, mut missing) = (0, 0, Vec::new());
    for seed in 0..4 {
        let twin = Twin {
            rapier: BroadPhaseBvh::new(),
            canopy: CanopyBroadPhase::new(),
            events: Vec::new(),
        };
        let mut w = World::new(scene(seed), twin);
        for step in 0..200 {
            w.step();
            let colliders = &w.scene.colliders;
            let prediction = w.scene.params.prediction_distance() / 2.0;
            for pair in w.narrow_phase.contact_pairs() {
                if !pair.has_any_active_contact {
                    continue;
                }
                checked += 1;
                let (a, b) = (pair.collider1, pair.collider2);
                let (ca, cb) = (&colliders[a], &colliders[b]);
                if !ca
                    .compute_collision_aabb(prediction)
                    .intersects(&cb.compute_collision_aabb(prediction))
                {
                    beyond_boxes += 1;
                }
                if !w.broad_phase.canopy.contains_pair(a, b) {
                    missing.push((seed, step, a, b));
                }
            }
        }
    }
    assert!(
        checked > 10_000,
        "only {checked} contact pairs: the test proves little"
    );
    // Contacts the plain collision boxes do not cover: what soft CCD adds, and what this
    // test is about.
    assert!(
        beyond_boxes > 100,
        "only {beyond_boxes} contacts beyond the collision boxes"
    );
    assert!(
        missing.is_empty(),
        "{} of {checked} contact pairs not live in canopy, first {:?}",
        missing.len(),
        &missing[..missing.len().min(5)]
    );
}
