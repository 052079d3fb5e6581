//! `many_kinematics`: Rapier's `benchmarks3d/many_kinematics3.rs`.
//!
//! A `num^3` grid of velocity-based kinematic balls of radius 1 at spacing 7,
//! centred on the origin, each with a random linear velocity whose components
//! are uniform in `[-15, 15)` (Rapier: `(rand - 0.5) × 30`; here from a
//! fixed-seed [`XorShift`]). No ground, no dynamic body. Before every step the
//! hook does what Rapier's testbed callback does: for every body and axis, if
//! the body is past `±7 num / 2` on that axis and still moving outwards, the
//! velocity component is negated (`set_linvel(.., false)`), so the balls
//! bounce forever inside a box. Every body moves every step. `num` is 30 at
//! full size (27,000 bodies) and 6 at small size (216 bodies).

use crate::rng::XorShift;
use crate::scene::{HookCtx, Scene, Size};
use rapier3d::dynamics::{RigidBodyBuilder, RigidBodyType};
use rapier3d::geometry::ColliderBuilder;
use rapier3d::math::{Real, Vector};

const SEED: u64 = 0x6b69_6e65_6d61_7469; // "kinemati"

fn num(size: Size) -> usize {
    size.pick(30, 6)
}

pub(crate) fn expected_bodies(size: Size) -> usize {
    num(size).pow(3)
}

/// Rapier's `many_kinematics3` benchmark: `30^3` = 27,000 velocity-based
/// kinematic balls bouncing inside a box at full size, `6^3` = 216 at small
/// size. Has a hook (the bounce).
pub fn many_kinematics(size: Size) -> Scene {
    let mut scene = Scene::empty("many_kinematics");
    let (bodies, colliders) = (&mut scene.bodies, &mut scene.colliders);
    let mut rng = XorShift::new(SEED);

    let num = num(size);
    let rad: Real = 1.0;
    let shift = rad * 6.0 + 1.0;
    let centerx = shift * (num as Real) / 2.0;
    let centery = shift * (num as Real) / 2.0;
    let centerz = shift * (num as Real) / 2.0;

    for i in 0..num {
        for j in 0..num {
            for k in 0..num {
                let x = i as Real * shift - centerx;
                let y = j as Real * shift - centery;
                let z = k as Real * shift - centerz;
                let velocity = Vector::new(
                    rng.next_f32() - 0.5,
                    rng.next_f32() - 0.5,
                    rng.next_f32() - 0.5,
                ) * 30.0;
                let body = RigidBodyBuilder::new(RigidBodyType::KinematicVelocityBased)
                    .translation(Vector::new(x, y, z))
                    .linvel(velocity);
                let handle = bodies.insert(body);
                colliders.insert_with_parent(ColliderBuilder::ball(rad), handle, bodies);
            }
        }
    }

    let bound = (shift * num as Real) / 2.0;
    scene.hook = Some(Box::new(move |ctx: &mut HookCtx<'_>| {
        for (_, rb) in ctx.bodies.iter_mut() {
            let mut linvel = *rb.linvel();
            for dim in 0..3 {
                if (linvel[dim] > 0.0 && rb.translation()[dim] > bound)
                    || (linvel[dim] < 0.0 && rb.translation()[dim] < -bound)
                {
                    linvel[dim] = -linvel[dim];
                }
            }
            rb.set_linvel(linvel, false);
        }
    }));
    scene
}
