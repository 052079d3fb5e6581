//! `many_pyramids`: Rapier's `benchmarks3d/many_pyramids3.rs`.
//!
//! A row of 2D pyramids (one cube thick) of dynamic cubes of half-extent 0.5,
//! touching each other, spaced 4 apart along `z`, on a fixed ground of
//! half-extents `50 × 0.1 × (count × 4 / 2 + 50)` (top face at `y = 0`).
//! Full size: 40 pyramids of 20 levels (210 cubes each, 8,400 cubes + ground);
//! small size: 3 pyramids of 6 levels (21 cubes each, 63 cubes + ground).

use super::add_ground;
use crate::scene::{Scene, Size};
use rapier3d::dynamics::{RigidBodyBuilder, RigidBodySet};
use rapier3d::geometry::{ColliderBuilder, ColliderSet};
use rapier3d::math::{Real, Vector};

fn pyramid_count(size: Size) -> usize {
    size.pick(40, 3)
}

fn stack_height(size: Size) -> usize {
    size.pick(20, 6)
}

/// Number of cubes in one pyramid of `stack_height` levels.
pub(crate) fn num_cubes(stack_height: usize) -> usize {
    stack_height * (stack_height + 1) / 2
}

pub(crate) fn expected_bodies(size: Size) -> usize {
    pyramid_count(size) * num_cubes(stack_height(size)) + 1
}

fn create_pyramid(
    bodies: &mut RigidBodySet,
    colliders: &mut ColliderSet,
    offset: Vector<Real>,
    stack_height: usize,
    rad: Real,
) {
    let shift = rad * 2.0;
    for i in 0..stack_height {
        for j in i..stack_height {
            let fj = j as Real;
            let fi = i as Real;
            let x = (fi * shift / 2.0) + (fj - fi) * shift;
            let y = fi * shift;
            let handle = bodies
                .insert(RigidBodyBuilder::dynamic().translation(Vector::new(x, y, 0.0) + offset));
            colliders.insert_with_parent(ColliderBuilder::cuboid(rad, rad, rad), handle, bodies);
        }
    }
}

/// Rapier's `many_pyramids3` benchmark: 40 pyramids of 20 levels (8,400
/// cubes) on a ground at full size, 3 pyramids of 6 levels (63 cubes) at
/// small size.
pub fn many_pyramids(size: Size) -> Scene {
    let mut scene = Scene::empty("many_pyramids");
    let (bodies, colliders) = (&mut scene.bodies, &mut scene.colliders);

    let rad = 0.5;
    let pyramid_count = pyramid_count(size);
    let spacing = 4.0;

    let ground_size = 50.0;
    let ground_height = 0.1;
    add_ground(
        bodies,
        colliders,
        Vector::zeros(),
        Vector::new(
            ground_size,
            ground_height,
            pyramid_count as Real * spacing / 2.0 + ground_size,
        ),
    );

    for pyramid_index in 0..pyramid_count {
        let bottomy = rad;
        create_pyramid(
            bodies,
            colliders,
            Vector::new(
                0.0,
                bottomy,
                (pyramid_index as Real - pyramid_count as Real / 2.0) * spacing,
            ),
            stack_height(size),
            rad,
        );
    }
    scene
}
