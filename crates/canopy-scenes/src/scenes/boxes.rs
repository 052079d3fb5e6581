//! `boxes`: Rapier's `benchmarks3d/boxes3.rs`.
//!
//! A fixed ground (half-extents 200.1 × 0.1 × 200.1, top face at `y = 0`) under
//! a `num^3` stack of dynamic cubes of half-extent 1, touching each other
//! (spacing 2), the bottom layer resting on the ground; each layer is shifted
//! by `-0.05 × (num - 1)` in `x` and `z` relative to the one below, so the stack
//! leans. `num` is 10 at full size (1,000 cubes + ground) and 4 at small size
//! (64 cubes + ground).

use super::add_ground;
use crate::scene::{Scene, Size};
use rapier3d::dynamics::RigidBodyBuilder;
use rapier3d::geometry::ColliderBuilder;
use rapier3d::math::{Real, Vector};

fn num(size: Size) -> usize {
    size.pick(10, 4)
}

pub(crate) fn expected_bodies(size: Size) -> usize {
    num(size).pow(3) + 1
}

/// Rapier's `boxes3` benchmark: `10^3` = 1,000 cubes on a ground at full size,
/// `4^3` = 64 at small size.
pub fn boxes(size: Size) -> Scene {
    let mut scene = Scene::empty("boxes");
    let (bodies, colliders) = (&mut scene.bodies, &mut scene.colliders);

    let ground_size = 200.1;
    let ground_height = 0.1;
    add_ground(
        bodies,
        colliders,
        Vector::zeros(),
        Vector::new(ground_size, ground_height, ground_size),
    );

    let num = num(size);
    let rad: Real = 1.0;
    let shift = rad * 2.0;
    let centerx = shift * (num / 2) as Real;
    let centery = shift / 2.0;
    let centerz = shift * (num / 2) as Real;
    let mut offset = -(num as Real) * (rad * 2.0) * 0.5;

    for j in 0..num {
        for i in 0..num {
            for k in 0..num {
                let x = i as Real * shift - centerx + offset;
                let y = j as Real * shift + centery;
                let z = k as Real * shift - centerz + offset;
                let handle =
                    bodies.insert(RigidBodyBuilder::dynamic().translation(Vector::new(x, y, z)));
                colliders.insert_with_parent(
                    ColliderBuilder::cuboid(rad, rad, rad),
                    handle,
                    bodies,
                );
            }
        }
        offset -= 0.05 * rad * (num as Real - 1.0);
    }
    scene
}
