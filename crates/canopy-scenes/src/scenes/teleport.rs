//! `teleport`: canopy's own large-jump scene (no Rapier counterpart).
//!
//! Four square pads (fixed cuboids of half-extents 50 × 0.1 × 50, top faces at
//! `y = 0`) centred at `(±500, 0, ±500)`, each with a grid of dynamic bodies
//! (the same mix of balls, cubes and capsules as `spawn_storm`, randomly
//! oriented, cells of 2 units) resting just above it. Before every step the
//! hook picks `per_step` bodies at random (a deterministic subset: fixed-seed
//! [`XorShift`]) and teleports each to a random point 10 to 25 units above a
//! random *other* pad (within 20 units of its centre) with
//! `set_translation(.., true)`, and zeroes its velocities so it simply falls
//! again. Every such move is at least about 900 units long: the broad-phase
//! sees large instantaneous jumps between far-apart clusters. So that nothing
//! falls forever, the hook also teleports, the same way, any body that rolled
//! off its pad and fell below `y = -20` (rare: only after many steps).
//!
//! Full size: 1,024 bodies per pad (16 × 4 × 16), 4,096 in all, 32 teleported
//! per step. Small size: 48 per pad (4 × 3 × 4), 192 in all, 4 per step. Both
//! plus the 4 pads.
//!
//! [`XorShift`]: crate::XorShift

use super::{add_ground, mixed_shape};
use crate::rng::XorShift;
use crate::scene::{HookCtx, Scene, Size};
use rapier3d::dynamics::RigidBodyBuilder;
use rapier3d::math::{Real, Vector};

const SEED: u64 = 0x7465_6c65_706f_7274; // "teleport"
/// Number of pads (and of fixed bodies).
pub(crate) const NUM_PADS: usize = 4;
/// Distance of the pads' centres from the origin along `x` and `z`.
const PAD_DISTANCE: Real = 500.0;
const PAD_HALF_SIZE: Real = 50.0;
/// Bodies below this height fell off their pad and are teleported back.
const FALLEN_Y: Real = -20.0;
const CELL: Real = 2.0;

/// The sizes of the scene.
pub(crate) struct Params {
    /// The grid of bodies on each pad: `(nx, ny, nz)`.
    pub grid: (usize, usize, usize),
    /// Bodies teleported before each step.
    pub per_step: usize,
}

pub(crate) fn params(size: Size) -> Params {
    size.pick(
        Params {
            grid: (16, 4, 16),
            per_step: 32,
        },
        Params {
            grid: (4, 3, 4),
            per_step: 4,
        },
    )
}

pub(crate) fn expected_bodies(size: Size) -> usize {
    let (nx, ny, nz) = params(size).grid;
    NUM_PADS * (nx * ny * nz + 1)
}

/// Centre of pad `pad` (0 to 3) on the ground plane.
fn pad_center(pad: usize) -> Vector<Real> {
    let sx = if pad & 1 == 0 { -1.0 } else { 1.0 };
    let sz = if pad & 2 == 0 { -1.0 } else { 1.0 };
    Vector::new(sx * PAD_DISTANCE, 0.0, sz * PAD_DISTANCE)
}

/// The pad whose quadrant contains `p`.
fn pad_of(p: &Vector<Real>) -> usize {
    usize::from(p.x > 0.0) | (usize::from(p.z > 0.0) << 1)
}

/// Four far-apart pads of dynamic bodies (4,096 bodies at full size, 192 at
/// small size); before every step a few random bodies (32 / 4) jump to
/// another pad, about a kilometre away. Has a hook.
pub fn teleport(size: Size) -> Scene {
    let mut scene = Scene::empty("teleport");
    let (bodies, colliders) = (&mut scene.bodies, &mut scene.colliders);
    let mut rng = XorShift::new(SEED);
    let Params {
        grid: (nx, ny, nz),
        per_step,
    } = params(size);

    let mut handles = Vec::with_capacity(NUM_PADS * nx * ny * nz);
    let pi: Real = std::f32::consts::PI;
    for pad in 0..NUM_PADS {
        let center = pad_center(pad);
        add_ground(
            bodies,
            colliders,
            center,
            Vector::new(PAD_HALF_SIZE, 0.1, PAD_HALF_SIZE),
        );
        for i in 0..nx {
            for j in 0..ny {
                for k in 0..nz {
                    let position = center
                        + Vector::new(
                            (i as Real - (nx - 1) as Real / 2.0) * CELL,
                            (j as Real + 0.75) * CELL,
                            (k as Real - (nz - 1) as Real / 2.0) * CELL,
                        );
                    let rotation =
                        Vector::new(rng.range(-pi, pi), rng.range(-pi, pi), rng.range(-pi, pi));
                    let body = RigidBodyBuilder::dynamic()
                        .translation(position)
                        .rotation(rotation);
                    let handle = bodies.insert(body);
                    colliders.insert_with_parent(mixed_shape(rng.below(3)), handle, bodies);
                    handles.push(handle);
                }
            }
        }
    }

    scene.hook = Some(Box::new(move |ctx: &mut HookCtx<'_>| {
        // The random subset, then (rarely) the bodies that rolled off a pad.
        let fallen = handles
            .iter()
            .copied()
            .filter(|h| ctx.bodies[*h].translation().y < FALLEN_Y);
        let picks: Vec<_> = (0..per_step)
            .map(|_| handles[rng.below(handles.len())])
            .chain(fallen)
            .collect();
        for handle in picks {
            let Some(rb) = ctx.bodies.get_mut(handle) else {
                continue;
            };
            let from = pad_of(rb.translation());
            let to = (from + 1 + rng.below(NUM_PADS - 1)) % NUM_PADS;
            let target = pad_center(to)
                + Vector::new(
                    rng.range(-20.0, 20.0),
                    rng.range(10.0, 25.0),
                    rng.range(-20.0, 20.0),
                );
            rb.set_translation(target, true);
            rb.set_linvel(Vector::zeros(), true);
            rb.set_angvel(Vector::zeros(), true);
        }
    }));
    scene
}
