//! [`World`]: a [`Scene`] plus all of Rapier's pipeline state, stepped with
//! any broad-phase.

use crate::scene::{HookCtx, Scene};
use rapier3d::dynamics::{CCDSolver, IntegrationParameters, IslandManager, RigidBodySet};
use rapier3d::geometry::{BroadPhase, ColliderSet, NarrowPhase};
use rapier3d::pipeline::PhysicsPipeline;
use std::time::{Duration, Instant};

/// A scene plus all the Rapier pipeline state, stepped with any broadphase.
///
/// Every field is public, so callers can inspect or change anything between
/// steps (for example compare `narrow_phase` contact pairs across two worlds
/// stepped with different broad-phases).
pub struct World<B: BroadPhase> {
    /// The scene: sets, parameters, gravity and hook.
    pub scene: Scene,
    /// Rapier's island manager (active and sleeping bodies).
    pub islands: IslandManager,
    /// The broad-phase under test (Rapier's `BroadPhaseBvh`, canopy's, ...).
    pub broad_phase: B,
    /// Rapier's narrow-phase.
    pub narrow_phase: NarrowPhase,
    /// Rapier's physics pipeline, with its `counters` enabled.
    pub pipeline: PhysicsPipeline,
    /// Rapier's continuous-collision-detection solver.
    pub ccd: CCDSolver,
    steps: usize,
    last_step: Duration,
}

impl<B: BroadPhase> World<B> {
    /// Wraps `scene` with fresh pipeline state and `broad_phase` (which
    /// should be empty: it will see every collider as new on the first step).
    pub fn new(scene: Scene, broad_phase: B) -> Self {
        let mut pipeline = PhysicsPipeline::new();
        pipeline.counters.enable();
        World {
            scene,
            islands: IslandManager::new(),
            broad_phase,
            narrow_phase: NarrowPhase::new(),
            pipeline,
            ccd: CCDSolver::new(),
            steps: 0,
            last_step: Duration::ZERO,
        }
    }

    /// Runs one step: the scene's hook (if any) with the index of this step,
    /// then `PhysicsPipeline::step` with `&mut self.broad_phase`, no physics
    /// hooks and no event handler.
    pub fn step(&mut self) {
        let Scene {
            bodies,
            colliders,
            impulse_joints,
            multibody_joints,
            params,
            gravity,
            hook,
            ..
        } = &mut self.scene;

        if let Some(hook) = hook.as_mut() {
            hook(&mut HookCtx {
                step: self.steps,
                bodies,
                colliders,
                islands: &mut self.islands,
                impulse_joints,
                multibody_joints,
            });
        }

        let start = Instant::now();
        self.pipeline.step(
            gravity,
            params,
            &mut self.islands,
            &mut self.broad_phase,
            &mut self.narrow_phase,
            bodies,
            colliders,
            impulse_joints,
            multibody_joints,
            &mut self.ccd,
            &(),
            &(),
        );
        self.last_step = start.elapsed();
        self.steps += 1;
    }

    /// Runs `n` steps.
    pub fn step_n(&mut self, n: usize) {
        for _ in 0..n {
            self.step();
        }
    }

    /// Number of steps run so far.
    pub fn steps(&self) -> usize {
        self.steps
    }

    /// Wall-clock milliseconds of the last `PhysicsPipeline::step` (the hook
    /// excluded); 0 before the first step.
    ///
    /// Measured by `World` itself: Rapier's own `pipeline.counters` timers
    /// only tick when rapier3d's `profiler` feature is enabled, which this
    /// crate does not enable (they read 0 otherwise).
    pub fn step_ms_last_step(&self) -> f64 {
        self.last_step.as_secs_f64() * 1000.0
    }

    /// The integration parameters the scene is stepped with.
    pub fn params(&self) -> &IntegrationParameters {
        &self.scene.params
    }

    /// The rigid bodies.
    pub fn bodies(&self) -> &RigidBodySet {
        &self.scene.bodies
    }

    /// The colliders.
    pub fn colliders(&self) -> &ColliderSet {
        &self.scene.colliders
    }

    /// Gives the scene and the broad-phase back.
    pub fn into_parts(self) -> (Scene, B) {
        (self.scene, self.broad_phase)
    }
}
