//! `keva_tower`: Rapier's `benchmarks3d/keva3.rs`.
//!
//! A tower of KEVA planks (dynamic cuboids of half-extents 0.1 × 0.5 × 2) on a
//! fixed ground (half-extents 50 × 0.1 × 50, top face at `y = 0`). The tower is
//! a stack of blocks, widest at the bottom: block `i` (for `i` from `blocks`
//! down to 1) has `numx = i` planks across, `numz = 3i + 1`, and
//! `numy = [9, 13, 17, 21, 41][i - 1]` layers whose planks alternate in
//! orientation, and is closed by a flat layer of planks on top. Full size
//! builds Rapier's 5 blocks; small size builds only the top block
//! (9 layers of 4 planks and 4 planks on top).

use super::add_ground;
use crate::scene::{Scene, Size};
use rapier3d::dynamics::RigidBodyBuilder;
use rapier3d::geometry::ColliderBuilder;
use rapier3d::math::{Real, Vector};

fn num_blocks(size: Size) -> usize {
    size.pick(5, 1)
}

/// Number of layers of block `i` (1-based). Rapier: "These should only be set
/// to odd values otherwise the blocks won't align in the nicest way."
const NUMY: [usize; 6] = [0, 9, 13, 17, 21, 41];

/// Rapier's `build_block`, emitting `(center, half_extents)` for every plank.
fn build_block(
    half_extents: Vector<Real>,
    shift: Vector<Real>,
    (mut numx, numy, mut numz): (usize, usize, usize),
    emit: &mut impl FnMut(Vector<Real>, Vector<Real>),
) {
    let dimensions = [half_extents.xyz(), half_extents.zyx()];
    let block_width = 2.0 * half_extents.z * numx as Real;
    let block_height = 2.0 * half_extents.y * numy as Real;
    let spacing = (half_extents.z * numx as Real - half_extents.x) / (numz as Real - 1.0);

    for i in 0..numy {
        std::mem::swap(&mut numx, &mut numz);
        let dim = dimensions[i % 2];
        let y = dim.y * i as Real * 2.0;

        for j in 0..numx {
            let x = if i % 2 == 0 {
                spacing * j as Real * 2.0
            } else {
                dim.x * j as Real * 2.0
            };

            for k in 0..numz {
                let z = if i % 2 == 0 {
                    dim.z * k as Real * 2.0
                } else {
                    spacing * k as Real * 2.0
                };
                emit(
                    Vector::new(
                        x + dim.x + shift.x,
                        y + dim.y + shift.y,
                        z + dim.z + shift.z,
                    ),
                    dim,
                );
            }
        }
    }

    // Close the top.
    let dim = half_extents.zxy();
    for i in 0..(block_width / (dim.x * 2.0)) as usize {
        for j in 0..(block_width / (dim.z * 2.0)) as usize {
            emit(
                Vector::new(
                    i as Real * dim.x * 2.0 + dim.x + shift.x,
                    dim.y + shift.y + block_height,
                    j as Real * dim.z * 2.0 + dim.z + shift.z,
                ),
                dim,
            );
        }
    }
}

/// Rapier's `init_world` loop over the blocks, top block last.
fn build_tower(num_blocks: usize, emit: &mut impl FnMut(Vector<Real>, Vector<Real>)) {
    let half_extents = Vector::new(0.02, 0.1, 0.4) / 2.0 * 10.0;
    let mut block_height = 0.0;
    for i in (1..=num_blocks).rev() {
        let numx = i;
        let numy = NUMY[i];
        let numz = numx * 3 + 1;
        let block_width = numx as Real * half_extents.z * 2.0;
        build_block(
            half_extents,
            Vector::new(-block_width / 2.0, block_height, -block_width / 2.0),
            (numx, numy, numz),
            emit,
        );
        block_height += numy as Real * half_extents.y * 2.0 + half_extents.x * 2.0;
    }
}

/// Number of planks in a tower of `num_blocks` blocks.
pub(crate) fn num_planks(num_blocks: usize) -> usize {
    let mut n = 0;
    build_tower(num_blocks, &mut |_, _| n += 1);
    n
}

pub(crate) fn expected_bodies(size: Size) -> usize {
    num_planks(num_blocks(size)) + 1
}

/// Rapier's `keva3` benchmark: a KEVA-plank tower of 5 blocks on a ground at
/// full size; its top block (40 planks) at small size.
pub fn keva_tower(size: Size) -> Scene {
    let mut scene = Scene::empty("keva_tower");
    let (bodies, colliders) = (&mut scene.bodies, &mut scene.colliders);

    let ground_size = 50.0;
    let ground_height = 0.1;
    add_ground(
        bodies,
        colliders,
        Vector::zeros(),
        Vector::new(ground_size, ground_height, ground_size),
    );

    build_tower(num_blocks(size), &mut |center, dim| {
        let handle = bodies.insert(RigidBodyBuilder::dynamic().translation(center));
        colliders.insert_with_parent(ColliderBuilder::cuboid(dim.x, dim.y, dim.z), handle, bodies);
    });
    scene
}
