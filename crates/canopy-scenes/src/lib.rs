//! The standard scenes shared by canopy's examples, tests and benchmarks.
//!
//! Eight scenes reproduce the setups of Rapier's own 3D benchmarks (the
//! `benchmarks3d/` folder of the `dimforge/rapier` repository): [`balls`],
//! [`boxes`], [`pyramid`], [`many_pyramids`], [`many_static`], [`many_sleep`],
//! [`many_kinematics`] and [`keva_tower`]. Two more stress the broad-phase in
//! ways those do not: [`spawn_storm`] (bodies removed and added every step, so
//! collider handles get reused) and [`teleport`] (bodies moved by about a
//! kilometre in one step).
//!
//! Every scene is a function of a [`Size`]: [`Size::Full`] is the size of
//! Rapier's benchmark, [`Size::Small`] a few hundred bodies at most, for tests.
//! A scene is a plain [`Scene`]: the Rapier sets, the integration parameters,
//! the gravity and an optional per-step [`StepHook`]. [`World`] adds the rest of
//! Rapier's pipeline state and steps the scene with any
//! [`BroadPhase`](rapier3d::geometry::BroadPhase).
//!
//! Everything is deterministic: the same scene function and size always build
//! the same sets (same handles, same positions, same shapes), and the hooks draw
//! their choices from a fixed-seed [`XorShift`] generator.
//!
//! ```
//! use canopy_scenes::{scene, Size, World};
//! use rapier3d::geometry::BroadPhaseBvh;
//!
//! let mut world = World::new(scene("pyramid", Size::Small).unwrap(), BroadPhaseBvh::new());
//! world.step();
//! assert_eq!(world.steps(), 1);
//! ```
#![deny(missing_docs)]
#![deny(unsafe_code)]

pub mod harness;
mod rays;
mod rng;
mod scene;
pub mod scenes;
mod world;

pub use rays::ray_batch;
pub use rng::XorShift;
pub use scene::{HookCtx, Scene, Size, StepHook};
pub use scenes::{
    balls, boxes, expected_bodies, keva_tower, many_kinematics, many_pyramids, many_sleep,
    many_static, pyramid, spawn_storm, teleport,
};
pub use world::World;

/// Re-export of the exact `rapier3d` this crate builds its scenes with.
pub use rapier3d;

/// The names of all the scenes, in a fixed order; [`scene`] accepts each of them.
pub const SCENE_NAMES: &[&str] = &[
    "balls",
    "boxes",
    "pyramid",
    "many_pyramids",
    "many_static",
    "many_sleep",
    "many_kinematics",
    "keva_tower",
    "spawn_storm",
    "teleport",
];

/// The number of steps the `compare` example runs scene `name` for at `size` (the criterion
/// broadphase bench replays the same steps): enough to pass the scene's transient (falling,
/// settling, the first spawns) into its steady part, fewer for the scenes whose steps are long.
///
/// ```
/// assert_eq!(canopy_scenes::standard_steps("balls", canopy_scenes::Size::Full), 200);
/// ```
pub fn standard_steps(name: &str, size: Size) -> usize {
    match size {
        Size::Small => 100,
        Size::Full => match name {
            "many_static" | "many_sleep" => 60,
            "keva_tower" | "many_pyramids" | "pyramid" => 100,
            _ => 200,
        },
    }
}

/// Builds the scene called `name` (one of [`SCENE_NAMES`]) at `size`, or
/// returns `None` for an unknown name.
pub fn scene(name: &str, size: Size) -> Option<Scene> {
    let build: fn(Size) -> Scene = match name {
        "balls" => balls,
        "boxes" => boxes,
        "pyramid" => pyramid,
        "many_pyramids" => many_pyramids,
        "many_static" => many_static,
        "many_sleep" => many_sleep,
        "many_kinematics" => many_kinematics,
        "keva_tower" => keva_tower,
        "spawn_storm" => spawn_storm,
        "teleport" => teleport,
        _ => return None,
    };
    Some(build(size))
}
