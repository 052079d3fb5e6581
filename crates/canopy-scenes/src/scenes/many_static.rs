//! `many_static`: Rapier's `benchmarks3d/many_static3.rs`.
//!
//! The same grid as `balls` (balls of radius 1, density 0.477, spacing 3), but
//! every layer except the top one (`j < num - 1`) is fixed; only the top layer
//! is dynamic and drops 1 unit onto the fixed balls below. No separate ground.
//! `num` is 50 at full size (125,000 bodies: 122,500 fixed, 2,500 dynamic) and
//! 6 at small size (216 bodies: 180 fixed, 36 dynamic).

use super::ball_grid;
use crate::scene::{Scene, Size};
use rapier3d::dynamics::RigidBodyType;

fn num(size: Size) -> usize {
    size.pick(50, 6)
}

pub(crate) fn expected_bodies(size: Size) -> usize {
    num(size).pow(3)
}

/// Rapier's `many_static3` benchmark: `50^3` = 125,000 balls at full size, all
/// fixed but the top layer of 2,500 dynamic ones; `6^3` = 216 at small size.
pub fn many_static(size: Size) -> Scene {
    let mut scene = Scene::empty("many_static");
    let num = num(size);
    ball_grid(
        &mut scene.bodies,
        &mut scene.colliders,
        num,
        |j| {
            if j < num - 1 {
                RigidBodyType::Fixed
            } else {
                RigidBodyType::Dynamic
            }
        },
        false,
    );
    scene
}
