//! `pyramid`: Rapier's `benchmarks3d/pyramid3.rs`.
//!
//! A fixed ground (half-extents 50 × 0.1 × 50, top face at `y = 0`) under one
//! square pyramid of dynamic cubes of half-extent 1: level `i` (from 0 at the
//! bottom) is a `(h - i)²` grid at spacing 2.5 (gaps of 0.5 between cubes),
//! centred over the level below, at height `1 + 2.5 i`: the bottom level
//! rests on the ground and every other level starts 0.5 above the one below
//! and drops onto it, so the settled pyramid's level `i` is at `1 + 2 i`.
//! `h` is 24 at full size (4,900 cubes + ground) and 7 at small size (140
//! cubes + ground).

use super::add_ground;
use crate::scene::{Scene, Size};
use rapier3d::dynamics::{RigidBodyBuilder, RigidBodySet};
use rapier3d::geometry::{ColliderBuilder, ColliderSet};
use rapier3d::math::{Real, Vector};

fn stack_height(size: Size) -> usize {
    size.pick(24, 7)
}

/// Number of cubes in a pyramid of `stack_height` levels.
pub(crate) fn num_cubes(stack_height: usize) -> usize {
    (1..=stack_height).map(|n| n * n).sum()
}

pub(crate) fn expected_bodies(size: Size) -> usize {
    num_cubes(stack_height(size)) + 1
}

fn create_pyramid(
    bodies: &mut RigidBodySet,
    colliders: &mut ColliderSet,
    offset: Vector<Real>,
    stack_height: usize,
    half_extents: Vector<Real>,
) {
    let shift = half_extents * 2.5;
    for i in 0..stack_height {
        for j in i..stack_height {
            for k in i..stack_height {
                let fi = i as Real;
                let fj = j as Real;
                let fk = k as Real;
                let x = (fi * shift.x / 2.0) + (fk - fi) * shift.x + offset.x
                    - stack_height as Real * half_extents.x;
                let y = fi * shift.y + offset.y;
                let z = (fi * shift.z / 2.0) + (fj - fi) * shift.z + offset.z
                    - stack_height as Real * half_extents.z;
                let handle =
                    bodies.insert(RigidBodyBuilder::dynamic().translation(Vector::new(x, y, z)));
                let collider =
                    ColliderBuilder::cuboid(half_extents.x, half_extents.y, half_extents.z);
                colliders.insert_with_parent(collider, handle, bodies);
            }
        }
    }
}

/// Rapier's `pyramid3` benchmark: one pyramid of 24 levels (4,900 cubes) on a
/// ground at full size, 7 levels (140 cubes) at small size.
pub fn pyramid(size: Size) -> Scene {
    let mut scene = Scene::empty("pyramid");
    let (bodies, colliders) = (&mut scene.bodies, &mut scene.colliders);

    let ground_size = 50.0;
    let ground_height = 0.1;
    add_ground(
        bodies,
        colliders,
        Vector::zeros(),
        Vector::new(ground_size, ground_height, ground_size),
    );

    let cube_size = 1.0;
    let hext = Vector::repeat(cube_size);
    let bottomy = cube_size;
    create_pyramid(
        bodies,
        colliders,
        Vector::new(0.0, bottomy, 0.0),
        stack_height(size),
        hext,
    );
    scene
}
