//! `many_sleep`: Rapier's `benchmarks3d/many_sleep3.rs`.
//!
//! The same grid as `balls` (balls of radius 1, density 0.477, spacing 3, the
//! bottom layer fixed, the rest dynamic), but every body is created asleep
//! (`RigidBodyBuilder::sleeping(true)`, as Rapier's scene does, fixed ones
//! included). The balls do not touch (1 unit apart), so nothing wakes them:
//! the dynamic balls hang in the air, asleep, for as long as the scene is
//! stepped. `num` is 50 at full size (125,000 bodies: 2,500 fixed, 122,500
//! dynamic) and 6 at small size (216 bodies).

use super::ball_grid;
use crate::scene::{Scene, Size};
use rapier3d::dynamics::RigidBodyType;

fn num(size: Size) -> usize {
    size.pick(50, 6)
}

pub(crate) fn expected_bodies(size: Size) -> usize {
    num(size).pow(3)
}

/// Rapier's `many_sleep3` benchmark: `50^3` = 125,000 sleeping balls at full
/// size (the bottom layer fixed), `6^3` = 216 at small size.
pub fn many_sleep(size: Size) -> Scene {
    let mut scene = Scene::empty("many_sleep");
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
        true,
    );
    scene
}
