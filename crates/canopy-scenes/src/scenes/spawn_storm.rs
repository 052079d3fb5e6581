//! `spawn_storm`: canopy's own churn scene (no Rapier counterpart).
//!
//! A fixed ground (half-extents 100 × 0.1 × 100, top face at `y = 0`) and a
//! constant population of dynamic bodies, a deterministic mix of balls
//! (radius 0.5), cubes (half-extent 0.5) and capsules (half-height 0.3,
//! radius 0.4), randomly oriented. The scene starts with the whole population
//! in a jittered grid of layers above the ground (cells of 2 units over a
//! `side × side` square). Before every step the hook removes `churn` bodies
//! picked at random among the live ones (with their colliders) and then
//! inserts `churn` new bodies at random positions in the air above the square
//! (8 to 16 units above the initial grid), moving down at 5 units/s. Rapier's
//! arenas hand freed slots out again, so the new colliders reuse the indices
//! of the removed ones (with a new generation). The population, and the
//! collider count, stay constant: a steady state of bodies raining onto a
//! pile, from which random bodies vanish.
//!
//! Full size: 4,000 bodies (20 × 20 cells, 10 layers), 20 replaced per step.
//! Small size: 200 bodies (6 × 6 cells, 6 layers), 2 replaced per step.
//! Both plus the ground.

use super::{add_ground, mixed_shape};
use crate::rng::XorShift;
use crate::scene::{HookCtx, Scene, Size};
use rapier3d::dynamics::{RigidBodyBuilder, RigidBodyHandle, RigidBodySet};
use rapier3d::geometry::ColliderSet;
use rapier3d::math::{Real, Vector};

const SEED: u64 = 0x7370_6177_6e73_746d; // "spawnstm"
const CELL: Real = 2.0;

/// The sizes of the scene.
pub(crate) struct Params {
    /// Dynamic bodies alive at any time.
    pub num_bodies: usize,
    /// Bodies removed, and bodies added, before each step.
    pub churn: usize,
    /// Cells per side of the square the bodies start over.
    pub side: usize,
}

pub(crate) fn params(size: Size) -> Params {
    size.pick(
        Params {
            num_bodies: 4000,
            churn: 20,
            side: 20,
        },
        Params {
            num_bodies: 200,
            churn: 2,
            side: 6,
        },
    )
}

pub(crate) fn expected_bodies(size: Size) -> usize {
    params(size).num_bodies + 1
}

fn spawn(
    rng: &mut XorShift,
    bodies: &mut RigidBodySet,
    colliders: &mut ColliderSet,
    position: Vector<Real>,
    linvel: Vector<Real>,
) -> RigidBodyHandle {
    let pi: Real = std::f32::consts::PI;
    let rotation = Vector::new(rng.range(-pi, pi), rng.range(-pi, pi), rng.range(-pi, pi));
    let shape = mixed_shape(rng.below(3));
    let body = RigidBodyBuilder::dynamic()
        .translation(position)
        .rotation(rotation)
        .linvel(linvel);
    let handle = bodies.insert(body);
    colliders.insert_with_parent(shape, handle, bodies);
    handle
}

/// A steady storm: a constant population of dynamic bodies (4,000 at full
/// size, 200 at small size) falling onto a ground, of which a few (20 / 2)
/// are removed and as many added, at random, before every step. Has a hook.
pub fn spawn_storm(size: Size) -> Scene {
    let mut scene = Scene::empty("spawn_storm");
    let (bodies, colliders) = (&mut scene.bodies, &mut scene.colliders);
    let mut rng = XorShift::new(SEED);
    let Params {
        num_bodies,
        churn,
        side,
    } = params(size);

    add_ground(
        bodies,
        colliders,
        Vector::zeros(),
        Vector::new(100.0, 0.1, 100.0),
    );

    // The initial population: a jittered grid, layer after layer.
    let half_width = side as Real * CELL / 2.0;
    let per_layer = side * side;
    let mut live = Vec::with_capacity(num_bodies);
    for n in 0..num_bodies {
        let layer = n / per_layer;
        let (i, k) = ((n % per_layer) / side, n % side);
        let jitter = 0.25 * CELL;
        let position = Vector::new(
            (i as Real + 0.5) * CELL - half_width + rng.range(-jitter, jitter),
            (layer as Real + 0.75) * CELL + rng.range(-jitter, jitter),
            (k as Real + 0.5) * CELL - half_width + rng.range(-jitter, jitter),
        );
        live.push(spawn(
            &mut rng,
            bodies,
            colliders,
            position,
            Vector::zeros(),
        ));
    }

    // New bodies appear above the initial grid.
    let layers = num_bodies.div_ceil(per_layer);
    let spawn_low = layers as Real * CELL + 8.0;
    let spawn_high = spawn_low + 8.0;

    scene.hook = Some(Box::new(move |ctx: &mut HookCtx<'_>| {
        for _ in 0..churn.min(live.len()) {
            let victim = live.swap_remove(rng.below(live.len()));
            ctx.bodies.remove(
                victim,
                ctx.islands,
                ctx.colliders,
                ctx.impulse_joints,
                ctx.multibody_joints,
                true,
            );
        }
        for _ in 0..churn {
            let position = Vector::new(
                rng.range(-half_width, half_width),
                rng.range(spawn_low, spawn_high),
                rng.range(-half_width, half_width),
            );
            let linvel = Vector::new(rng.range(-1.0, 1.0), -5.0, rng.range(-1.0, 1.0));
            live.push(spawn(&mut rng, ctx.bodies, ctx.colliders, position, linvel));
        }
    }));
    scene
}
