//! `balls`: Rapier's `benchmarks3d/balls3.rs`.
//!
//! A cube of `num^3` balls of radius 1 (density 0.477) at spacing 3; the
//! bottom layer (`j == 0`) is fixed and is the floor, all the other balls are
//! dynamic and fall 1 unit onto the ball below them. There is no separate
//! ground. `num` is 20 at full size (8,000 bodies: 400 fixed, 7,600 dynamic)
//! and 5 at small size (125 bodies).

use super::ball_grid;
use crate::scene::{Scene, Size};
use rapier3d::dynamics::RigidBodyType;

fn num(size: Size) -> usize {
    size.pick(20, 5)
}

pub(crate) fn expected_bodies(size: Size) -> usize {
    num(size).pow(3)
}

/// Rapier's `balls3` benchmark: `20^3` = 8,000 balls at full size, whose bottom
/// layer is fixed; `5^3` = 125 at small size.
pub fn balls(size: Size) -> Scene {
    let mut scene = Scene::empty("balls");
    ball_grid(
        &mut scene.bodies,
        &mut scene.colliders,
        num(size),
        |j| {
            if j == 0 {
                RigidBodyType::Fixed
            } else {
                RigidBodyType::Dynamic
            }
        },
        false,
    );
    scene
}
