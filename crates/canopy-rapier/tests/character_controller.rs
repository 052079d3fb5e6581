//! Rapier's kinematic character controller on a canopy broadphase: a capsule walks over
//! stairs, up and down slopes, into a wall and past obstacles with autostep and snap-to-ground,
//! in a world stepped with `CanopyBroadPhase` and queried through its `as_query_pipeline`. The
//! same walk in a world stepped with Rapier's `BroadPhaseBvh` and its own `QueryPipeline` is
//! the truth: the capsule must end where it ends there (within 1e-4), and be within that of it
//! at every frame.

use canopy_rapier::CanopyBroadPhase;
use rapier3d::control::{CharacterAutostep, CharacterLength, KinematicCharacterController};
use rapier3d::prelude::*;

/// A course: flat ground, a flight of stairs up to a platform, a slope down, obstacles, a
/// wall at the end, and a kinematic character with a capsule.
struct Course {
    bodies: RigidBodySet,
    colliders: ColliderSet,
    character: RigidBodyHandle,
}

fn course() -> Course {
    let mut bodies = RigidBodySet::new();
    let mut colliders = ColliderSet::new();
    colliders.insert(ColliderBuilder::cuboid(60.0, 0.1, 20.0).translation(vector![0.0, -0.1, 0.0]));
    // Stairs: ten steps of 0.15 up along +x, then a platform.
    for i in 0..10 {
        let h = 0.15 * (i + 1) as f32;
        colliders.insert(
            ColliderBuilder::cuboid(0.2, h / 2.0, 3.0).translation(vector![
                4.0 + 0.4 * i as f32,
                h / 2.0,
                0.0
            ]),
        );
    }
    colliders.insert(ColliderBuilder::cuboid(2.0, 0.75, 3.0).translation(vector![10.0, 0.75, 0.0]));
    // A 20° slope down from the platform.
    let angle = 20.0f32.to_radians();
    let length = 1.5 / angle.sin();
    colliders.insert(
        ColliderBuilder::cuboid(length / 2.0, 0.05, 3.0)
            .rotation(vector![0.0, 0.0, -angle])
            .translation(vector![12.0 + length * angle.cos() / 2.0, 0.75, 0.0]),
    );
    // Small obstacles (autostep) and a few balls lying around, then a wall.
    for i in 0..6 {
        colliders.insert(ColliderBuilder::cuboid(0.1, 0.05, 0.4).translation(vector![
            20.0 + 1.3 * i as f32,
            0.05,
            (i as f32 * 0.7).sin()
        ]));
        colliders.insert(ColliderBuilder::ball(0.3).translation(vector![
            21.0 + 1.7 * i as f32,
            0.3,
            2.0 + (i as f32).cos()
        ]));
    }
    colliders.insert(ColliderBuilder::cuboid(0.2, 2.0, 20.0).translation(vector![30.0, 2.0, 0.0]));
    // Scattered clutter away from the path, so the trees have something to cull.
    for i in 0..300 {
        let (x, z) = ((i % 30) as f32 * 2.0 - 30.0, 8.0 + (i / 30) as f32);
        colliders.insert(ColliderBuilder::cuboid(0.3, 0.3, 0.3).translation(vector![x, 0.3, z]));
    }
    let character = bodies
        .insert(RigidBodyBuilder::kinematic_position_based().translation(vector![0.0, 1.0, 0.0]));
    colliders.insert_with_parent(ColliderBuilder::capsule_y(0.5, 0.3), character, &mut bodies);
    Course {
        bodies,
        colliders,
        character,
    }
}

fn controller() -> KinematicCharacterController {
    KinematicCharacterController {
        autostep: Some(CharacterAutostep {
            max_height: CharacterLength::Absolute(0.2),
            min_width: CharacterLength::Absolute(0.1),
            include_dynamic_bodies: false,
        }),
        snap_to_ground: Some(CharacterLength::Absolute(0.2)),
        max_slope_climb_angle: 30.0f32.to_radians(),
        ..Default::default()
    }
}

/// Walks the course for `frames` frames; returns the character's position after each.
fn walk(use_canopy: bool, frames: usize) -> Vec<Vector<Real>> {
    let Course {
        mut bodies,
        mut colliders,
        character,
    } = course();
    let params = IntegrationParameters::default();
    let mut pipeline = PhysicsPipeline::new();
    let mut islands = IslandManager::new();
    let mut narrow = NarrowPhase::new();
    let mut joints = ImpulseJointSet::new();
    let mut multibody = MultibodyJointSet::new();
    let mut ccd = CCDSolver::new();
    let mut rapier_bp = BroadPhaseBvh::new();
    let mut canopy_bp = CanopyBroadPhase::new();
    let controller = controller();
    let shape = Capsule::new_y(0.5, 0.3);
    let mut path = Vec::new();
    let mut vertical_speed = 0.0f32;
    for frame in 0..frames {
        {
            let bp: &mut dyn BroadPhase = if use_canopy {
                &mut canopy_bp
            } else {
                &mut rapier_bp
            };
            pipeline.step(
                &vector![0.0, -9.81, 0.0],
                &params,
                &mut islands,
                bp,
                &mut narrow,
                &mut bodies,
                &mut colliders,
                &mut joints,
                &mut multibody,
                &mut ccd,
                &(),
                &(),
            );
        }
        // Forward with a little sideways weave, and gravity.
        let dt = params.dt;
        vertical_speed -= 9.81 * dt;
        let side = (frame as f32 * 0.05).sin() * 0.5;
        let desired = vector![4.0 * dt, vertical_speed * dt, side * dt];
        let pos = *bodies[character].position();
        let filter = QueryFilter::default().exclude_rigid_body(character);
        let movement = if use_canopy {
            let queries =
                canopy_bp.as_query_pipeline(narrow.query_dispatcher(), &bodies, &colliders, filter);
            controller.move_shape(dt, &queries, &shape, &pos, desired, |_| {})
        } else {
            let queries =
                rapier_bp.as_query_pipeline(narrow.query_dispatcher(), &bodies, &colliders, filter);
            controller.move_shape(dt, &queries, &shape, &pos, desired, |_| {})
        };
        if movement.grounded {
            vertical_speed = 0.0;
        }
        let next = pos.translation.vector + movement.translation;
        bodies[character].set_next_kinematic_translation(next);
        path.push(next);
    }
    path
}

#[test]
fn character_walks_the_same_course_on_both_broadphases() {
    let frames = 480;
    let truth = walk(false, frames);
    let canopy = walk(true, frames);
    for (i, (a, b)) in canopy.iter().zip(&truth).enumerate() {
        assert!(
            (a - b).norm() <= 1.0e-4,
            "frame {i}: canopy {a:?} vs Rapier {b:?}"
        );
    }
    let end = truth.last().unwrap();
    // The walk really went somewhere: up the stairs, down the slope, stopped by the wall.
    let highest = truth.iter().map(|p| p.y).fold(f32::MIN, f32::max);
    assert!(
        highest > 1.5 + 0.7,
        "never climbed the stairs (highest {highest})"
    );
    assert!(end.x > 25.0 && end.x < 29.8, "ended at {end:?}");
    assert!(end.y < 1.0, "did not come down the slope: {end:?}");
}
