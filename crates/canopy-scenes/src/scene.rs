//! The [`Scene`] type, its [`Size`] and its per-step [`StepHook`].

use rapier3d::dynamics::{
    ImpulseJointSet, IntegrationParameters, IslandManager, MultibodyJointSet, RigidBodySet,
};
use rapier3d::geometry::ColliderSet;
use rapier3d::math::{Real, Vector};
use std::fmt;

/// How big a scene is built.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Size {
    /// A few hundred bodies at most: fast to build and step, even in debug builds.
    Small,
    /// The size of Rapier's own benchmark scene (thousands to 125,000 bodies).
    Full,
}

impl Size {
    /// Both sizes, `Small` first.
    pub const ALL: [Size; 2] = [Size::Small, Size::Full];

    /// Returns `full` for [`Size::Full`] and `small` for [`Size::Small`].
    pub fn pick<T>(self, full: T, small: T) -> T {
        match self {
            Size::Full => full,
            Size::Small => small,
        }
    }
}

/// A per-step callback that drives a scene (spawning, removing, teleporting or
/// steering bodies). [`World::step`](crate::World::step) calls it once before
/// every physics step.
pub type StepHook = Box<dyn FnMut(&mut HookCtx<'_>) + Send>;

/// What a [`StepHook`] gets to see and change: the step index and the sets.
///
/// The hook runs before [`PhysicsPipeline::step`](rapier3d::pipeline::PhysicsPipeline::step),
/// so every change it makes (removals, insertions, new positions or
/// velocities) is seen by the broad-phase in that same step.
pub struct HookCtx<'a> {
    /// Index of the step about to run: 0 before the first step.
    pub step: usize,
    /// The rigid bodies of the scene.
    pub bodies: &'a mut RigidBodySet,
    /// The colliders of the scene.
    pub colliders: &'a mut ColliderSet,
    /// The island manager, needed to remove bodies.
    pub islands: &'a mut IslandManager,
    /// The impulse joints, needed to remove bodies.
    pub impulse_joints: &'a mut ImpulseJointSet,
    /// The multibody joints, needed to remove bodies.
    pub multibody_joints: &'a mut MultibodyJointSet,
}

/// A scene: Rapier's sets plus the parameters to step them with.
///
/// Build one with a scene function ([`balls`](crate::balls), ...) or
/// [`scene`](crate::scene), then step it with a [`World`](crate::World) (or
/// with your own pipeline, calling [`Scene::hook`] before every step).
pub struct Scene {
    /// The scene's name, one of [`SCENE_NAMES`](crate::SCENE_NAMES).
    pub name: &'static str,
    /// The rigid bodies.
    pub bodies: RigidBodySet,
    /// The colliders, each attached to one of `bodies`.
    pub colliders: ColliderSet,
    /// The impulse joints (empty in every scene so far).
    pub impulse_joints: ImpulseJointSet,
    /// The multibody joints (empty in every scene so far).
    pub multibody_joints: MultibodyJointSet,
    /// The integration parameters: Rapier's defaults (`dt` = 1/60 s).
    pub params: IntegrationParameters,
    /// The gravity: `(0, -9.81, 0)`, the Rapier testbed's default.
    pub gravity: Vector<Real>,
    /// Called before every step, for the scenes that need per-step driving
    /// (`many_kinematics`, `spawn_storm`, `teleport`); `None` otherwise.
    pub hook: Option<StepHook>,
}

impl Scene {
    /// An empty scene named `name`, with Rapier's default integration
    /// parameters, the testbed's gravity and no hook.
    pub fn empty(name: &'static str) -> Self {
        Scene {
            name,
            bodies: RigidBodySet::new(),
            colliders: ColliderSet::new(),
            impulse_joints: ImpulseJointSet::new(),
            multibody_joints: MultibodyJointSet::new(),
            params: IntegrationParameters::default(),
            gravity: Vector::new(0.0, -9.81, 0.0),
            hook: None,
        }
    }

    /// Number of rigid bodies (of every kind).
    pub fn num_bodies(&self) -> usize {
        self.bodies.len()
    }

    /// Number of colliders.
    pub fn num_colliders(&self) -> usize {
        self.colliders.len()
    }

    /// Number of dynamic rigid bodies.
    pub fn num_dynamic(&self) -> usize {
        self.bodies.iter().filter(|(_, b)| b.is_dynamic()).count()
    }

    /// Number of fixed rigid bodies.
    pub fn num_fixed(&self) -> usize {
        self.bodies.iter().filter(|(_, b)| b.is_fixed()).count()
    }

    /// Number of kinematic rigid bodies (velocity- or position-based).
    pub fn num_kinematic(&self) -> usize {
        self.bodies.iter().filter(|(_, b)| b.is_kinematic()).count()
    }

    /// Number of sleeping rigid bodies (Rapier's `is_sleeping`, which may
    /// count fixed bodies too).
    pub fn num_sleeping(&self) -> usize {
        self.bodies.iter().filter(|(_, b)| b.is_sleeping()).count()
    }
}

impl fmt::Debug for Scene {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Scene")
            .field("name", &self.name)
            .field("bodies", &self.bodies.len())
            .field("colliders", &self.colliders.len())
            .field("impulse_joints", &self.impulse_joints.len())
            .field("gravity", &self.gravity)
            .field("dt", &self.params.dt)
            .field("hook", &self.hook.is_some())
            .finish()
    }
}
