//! One function per scene, each in its own file, plus the helpers they share.
//!
//! The first eight reproduce the scenes of Rapier's `benchmarks3d/` folder
//! (same body layout, shapes, sizes, densities and ground) with the number of
//! bodies per dimension taken from the [`Size`]; the last two are canopy's own.

use crate::scene::Size;
use rapier3d::dynamics::{RigidBodyBuilder, RigidBodyHandle, RigidBodySet, RigidBodyType};
use rapier3d::geometry::{ColliderBuilder, ColliderSet};
use rapier3d::math::{Real, Vector};

mod balls;
mod boxes;
mod keva_tower;
mod many_kinematics;
mod many_pyramids;
mod many_sleep;
mod many_static;
mod pyramid;
mod spawn_storm;
mod teleport;

pub use balls::balls;
pub use boxes::boxes;
pub use keva_tower::keva_tower;
pub use many_kinematics::many_kinematics;
pub use many_pyramids::many_pyramids;
pub use many_sleep::many_sleep;
pub use many_static::many_static;
pub use pyramid::pyramid;
pub use spawn_storm::spawn_storm;
pub use teleport::teleport;

/// Adds a fixed cuboid ground of half-extents `(half_x, half_height, half_z)`
/// whose top face is at `y = top_y`, centred on `(x, z)`, as Rapier's scenes do
/// (a fixed body at `y = -ground_height` for a top face at 0).
pub(crate) fn add_ground(
    bodies: &mut RigidBodySet,
    colliders: &mut ColliderSet,
    center: Vector<Real>,
    half_extents: Vector<Real>,
) -> RigidBodyHandle {
    let body = RigidBodyBuilder::fixed().translation(Vector::new(
        center.x,
        center.y - half_extents.y,
        center.z,
    ));
    let handle = bodies.insert(body);
    let collider = ColliderBuilder::cuboid(half_extents.x, half_extents.y, half_extents.z);
    colliders.insert_with_parent(collider, handle, bodies);
    handle
}

/// The `num^3` grid of balls of radius 1 (density 0.477) at spacing 3 shared by
/// Rapier's `balls3.rs`, `many_static3.rs` and `many_sleep3.rs`: body
/// `(i, j, k)` sits at `(3i - 1.5 num, 3j + 1.5, 3k - 1.5 num)` and gets the
/// type `status(j)`; `sleeping` is passed to the body builder.
pub(crate) fn ball_grid(
    bodies: &mut RigidBodySet,
    colliders: &mut ColliderSet,
    num: usize,
    status: impl Fn(usize) -> RigidBodyType,
    sleeping: bool,
) {
    let rad = 1.0;
    let shift = rad * 2.0 + 1.0;
    let centerx = shift * (num as Real) / 2.0;
    let centery = shift / 2.0;
    let centerz = shift * (num as Real) / 2.0;
    let density = 0.477;
    // One collider cloned for every body: cheaper than building each one
    // (the clones share the ball's `SharedShape`).
    let collider = ColliderBuilder::ball(rad).density(density).build();

    for i in 0..num {
        for j in 0..num {
            for k in 0..num {
                let x = i as Real * shift - centerx;
                let y = j as Real * shift + centery;
                let z = k as Real * shift - centerz;
                let body = RigidBodyBuilder::new(status(j))
                    .translation(Vector::new(x, y, z))
                    .sleeping(sleeping);
                let handle = bodies.insert(body);
                colliders.insert_with_parent(collider.clone(), handle, bodies);
            }
        }
    }
}

/// The shapes `spawn_storm` and `teleport` mix: about one unit across each.
pub(crate) fn mixed_shape(kind: usize) -> ColliderBuilder {
    match kind % 3 {
        0 => ColliderBuilder::ball(0.5),
        1 => ColliderBuilder::cuboid(0.5, 0.5, 0.5),
        _ => ColliderBuilder::capsule_y(0.3, 0.4),
    }
}

/// Number of rigid bodies (ground included) that the scene called `name`
/// has when built at `size`, computed without building it; `None` for an
/// unknown name. The scenes with hooks keep this number constant while stepped.
pub fn expected_bodies(name: &str, size: Size) -> Option<usize> {
    Some(match name {
        "balls" => balls::expected_bodies(size),
        "boxes" => boxes::expected_bodies(size),
        "pyramid" => pyramid::expected_bodies(size),
        "many_pyramids" => many_pyramids::expected_bodies(size),
        "many_static" => many_static::expected_bodies(size),
        "many_sleep" => many_sleep::expected_bodies(size),
        "many_kinematics" => many_kinematics::expected_bodies(size),
        "keva_tower" => keva_tower::expected_bodies(size),
        "spawn_storm" => spawn_storm::expected_bodies(size),
        "teleport" => teleport::expected_bodies(size),
        _ => return None,
    })
}
