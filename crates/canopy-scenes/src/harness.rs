//! Measuring and checking any broadphase inside a running simulation: [`Instrumented`] wraps a
//! `BroadPhase`, times its `update` calls, replays its events into a live pair set, and can
//! count missing pairs against an independent truth (parry's own `Bvh` over the exact collision
//! boxes, filtered with Rapier's narrow-phase rules). [`Recorder`] keeps the inputs of every
//! update so that benchmarks can replay them against a fresh broadphase, and [`AabbFloor`] does
//! only the per-collider work every broadphase does, the floor of any broadphase's time. The `compare`
//! example, the differential tests and the criterion benches share these.

use rapier3d::parry::bounding_volume::BoundingVolume;
use rapier3d::parry::partitioning::{Bvh, BvhBuildStrategy, BvhWorkspace};
use rapier3d::prelude::*;
use std::collections::HashSet;
use std::time::Instant;

/// An unordered pair of collider handles, smaller raw parts first.
pub type HandlePair = (ColliderHandle, ColliderHandle);

/// The pair `(a, b)` in canonical order.
pub fn handle_pair(a: ColliderHandle, b: ColliderHandle) -> HandlePair {
    if a.into_raw_parts() <= b.into_raw_parts() {
        (a, b)
    } else {
        (b, a)
    }
}

/// `true` when Rapier's narrow phase would compute contacts for the two colliders, by the
/// rules of rapier3d 0.27's `NarrowPhase::compute_contacts`: different parents, rigid-body
/// types allowed by either collider's `active_collision_types`, matching collision groups.
pub fn narrow_phase_filter(c1: &Collider, c2: &Collider, bodies: &RigidBodySet) -> bool {
    if c1.parent().is_some() && c1.parent() == c2.parent() {
        return false;
    }
    let ty = |c: &Collider| {
        c.parent()
            .and_then(|h| bodies.get(h))
            .map(|b| b.body_type())
            .unwrap_or(RigidBodyType::Fixed)
    };
    let (t1, t2) = (ty(c1), ty(c2));
    (c1.active_collision_types().test(t1, t2) || c2.active_collision_types().test(t1, t2))
        && c1.collision_groups().test(c2.collision_groups())
}

/// Every pair the narrow phase needs at this instant: enabled colliders whose collision boxes
/// (`compute_collision_aabb(prediction_distance / 2)`) overlap and that pass
/// [`narrow_phase_filter`]. Found with parry's `Bvh`, independent of canopy.
pub fn needed_pairs(
    params: &IntegrationParameters,
    colliders: &ColliderSet,
    bodies: &RigidBodySet,
) -> Vec<HandlePair> {
    let prediction = params.prediction_distance() / 2.0;
    let mut handles = Vec::new();
    let mut boxes = Vec::new();
    for (h, c) in colliders.iter() {
        if !c.is_enabled() {
            continue;
        }
        let aabb = c.compute_collision_aabb(prediction);
        if aabb
            .mins
            .iter()
            .chain(aabb.maxs.iter())
            .all(|v| v.is_finite())
        {
            handles.push(h);
            boxes.push(aabb);
        }
    }
    let mut out = Vec::new();
    if boxes.len() < 2 {
        return out;
    }
    let tree = Bvh::from_leaves(BvhBuildStrategy::Binned, &boxes);
    let mut ws = BvhWorkspace::default();
    tree.traverse_bvtt_single_tree::<false>(&mut ws, &mut |a, b| {
        let (a, b) = (a as usize, b as usize);
        if !boxes[a].intersects(&boxes[b]) {
            return;
        }
        let (ha, hb) = (handles[a], handles[b]);
        if narrow_phase_filter(&colliders[ha], &colliders[hb], bodies) {
            out.push(handle_pair(ha, hb));
        }
    });
    out
}

/// Figures gathered by [`Instrumented`].
#[derive(Clone, Debug, Default)]
pub struct BroadPhaseMeter {
    /// Number of `update` calls.
    pub updates: usize,
    /// Total seconds spent in the wrapped `update`.
    pub total_secs: f64,
    /// Seconds spent in the last `update`.
    pub last_secs: f64,
    /// Updates on which the truth was checked.
    pub verified_updates: usize,
    /// Needed pairs seen across checked updates.
    pub needed_pairs: usize,
    /// Needed pairs that were not live, across checked updates (must be 0).
    pub missing_pairs: usize,
    /// `AddPair` events seen.
    pub added: usize,
    /// `DeletePair` events seen.
    pub deleted: usize,
    /// Seconds spent checking the truth (not part of the broadphase's time).
    pub verify_secs: f64,
}

/// A broadphase wrapped for measurement: times `update`, replays the events into the live pair
/// set, and every `verify_every` updates (0: never) counts the needed pairs that are not live.
pub struct Instrumented<B> {
    /// The wrapped broadphase.
    pub inner: B,
    /// Live pairs, replayed from the events (pairs of removed or disabled colliders dropped).
    pub live: HashSet<HandlePair>,
    /// The figures.
    pub meter: BroadPhaseMeter,
    /// Check the truth on every n-th update (0: never).
    pub verify_every: usize,
}

impl<B: BroadPhase> Instrumented<B> {
    /// Wraps `inner`, checking the truth every `verify_every` updates (0: never).
    pub fn new(inner: B, verify_every: usize) -> Self {
        Self {
            inner,
            live: HashSet::new(),
            meter: BroadPhaseMeter::default(),
            verify_every,
        }
    }
}

impl<B: BroadPhase> BroadPhase for Instrumented<B> {
    fn update(
        &mut self,
        params: &IntegrationParameters,
        colliders: &ColliderSet,
        bodies: &RigidBodySet,
        modified: &[ColliderHandle],
        removed: &[ColliderHandle],
        events: &mut Vec<BroadPhasePairEvent>,
    ) {
        let start = events.len();
        let t0 = Instant::now();
        self.inner
            .update(params, colliders, bodies, modified, removed, events);
        let dt = t0.elapsed().as_secs_f64();
        self.meter.updates += 1;
        self.meter.total_secs += dt;
        self.meter.last_secs = dt;

        if !removed.is_empty() {
            let gone: HashSet<ColliderHandle> = removed.iter().copied().collect();
            self.live
                .retain(|(a, b)| !gone.contains(a) && !gone.contains(b));
        }
        for e in &events[start..] {
            match e {
                BroadPhasePairEvent::AddPair(p) => {
                    self.meter.added += 1;
                    self.live.insert(handle_pair(p.collider1, p.collider2));
                }
                BroadPhasePairEvent::DeletePair(p) => {
                    self.meter.deleted += 1;
                    self.live.remove(&handle_pair(p.collider1, p.collider2));
                }
            }
        }
        if self.verify_every > 0 && (self.meter.updates - 1) % self.verify_every == 0 {
            let t0 = Instant::now();
            let needed = needed_pairs(params, colliders, bodies);
            self.meter.verified_updates += 1;
            self.meter.needed_pairs += needed.len();
            self.meter.missing_pairs += needed.iter().filter(|p| !self.live.contains(p)).count();
            self.meter.verify_secs += t0.elapsed().as_secs_f64();
        }
    }
}

/// The inputs of one `BroadPhase::update` call.
#[derive(Clone)]
pub struct RecordedUpdate {
    /// Integration parameters.
    pub params: IntegrationParameters,
    /// Colliders at the time of the call.
    pub colliders: ColliderSet,
    /// Bodies at the time of the call.
    pub bodies: RigidBodySet,
    /// Modified colliders.
    pub modified: Vec<ColliderHandle>,
    /// Removed colliders.
    pub removed: Vec<ColliderHandle>,
}

impl RecordedUpdate {
    /// Calls `broad_phase.update` with these inputs, appending to `events`.
    pub fn apply(&self, broad_phase: &mut dyn BroadPhase, events: &mut Vec<BroadPhasePairEvent>) {
        broad_phase.update(
            &self.params,
            &self.colliders,
            &self.bodies,
            &self.modified,
            &self.removed,
            events,
        );
    }

    /// Calls `broad_phase.update` with these inputs on fresh copies of the sets (copied
    /// untimed: see [`replay_timed`]); returns the time of the `update` call alone.
    pub fn apply_timed_on_copies(
        &self,
        broad_phase: &mut dyn BroadPhase,
        events: &mut Vec<BroadPhasePairEvent>,
    ) -> std::time::Duration {
        let sets = (self.colliders.clone(), self.bodies.clone());
        let start = Instant::now();
        broad_phase.update(
            &self.params,
            &sets.0,
            &sets.1,
            &self.modified,
            &self.removed,
            events,
        );
        start.elapsed()
    }
}

/// A broadphase wrapper that records the inputs of every update (for replay in benchmarks).
pub struct Recorder<B> {
    /// The wrapped broadphase, which still runs, so the simulation goes on as usual.
    pub inner: B,
    /// One entry per update.
    pub updates: Vec<RecordedUpdate>,
}

impl<B: BroadPhase> Recorder<B> {
    /// Wraps `inner`.
    pub fn new(inner: B) -> Self {
        Self {
            inner,
            updates: Vec::new(),
        }
    }
}

impl<B: BroadPhase> BroadPhase for Recorder<B> {
    fn update(
        &mut self,
        params: &IntegrationParameters,
        colliders: &ColliderSet,
        bodies: &RigidBodySet,
        modified: &[ColliderHandle],
        removed: &[ColliderHandle],
        events: &mut Vec<BroadPhasePairEvent>,
    ) {
        self.updates.push(RecordedUpdate {
            params: *params,
            colliders: colliders.clone(),
            bodies: bodies.clone(),
            modified: modified.to_vec(),
            removed: removed.to_vec(),
        });
        self.inner
            .update(params, colliders, bodies, modified, removed, events);
    }
}

/// The part of an update that every broadphase does, whatever its structure: the collision box
/// of every modified, enabled collider, as Rapier's `BroadPhaseBvh` computes it
/// (`compute_collision_aabb(prediction_distance / 2)`, after reading the parent body's soft-CCD
/// distance), in collider index order (memory order, which the hardware prefetcher streams),
/// and nothing else: no tree, no pairs, no events. Timed beside a broadphase on the same inputs
/// it bounds the ratio any broadphase can reach there: Rapier's time / this time.
#[derive(Clone, Debug, Default)]
pub struct AabbFloor {
    /// Sum of the boxes' lower x bounds, so that the work cannot be optimised away.
    pub checksum: f32,
    /// Reused buffers: a bitmap of the modified handles' indices (all zero between updates)
    /// and their generations.
    order: (Vec<u64>, Vec<u32>),
}

impl BroadPhase for AabbFloor {
    fn update(
        &mut self,
        params: &IntegrationParameters,
        colliders: &ColliderSet,
        bodies: &RigidBodySet,
        modified: &[ColliderHandle],
        _removed: &[ColliderHandle],
        _events: &mut Vec<BroadPhasePairEvent>,
    ) {
        let prediction = params.prediction_distance() / 2.0;
        let mut sum = 0.0;
        // Index order from a bitmap of the modified indices, as canopy reads them (a sort
        // would cost more than some broadphases' whole update).
        let (bits, generations) = &mut self.order;
        for h in modified {
            let (index, generation) = h.into_raw_parts();
            let word = (index / 64) as usize;
            if word >= bits.len() {
                bits.resize(word + 1, 0);
                generations.resize(bits.len() * 64, 0);
            }
            bits[word] |= 1 << (index % 64);
            generations[index as usize] = generation;
        }
        for (w, word) in bits.iter_mut().enumerate() {
            while *word != 0 {
                let index = w as u32 * 64 + word.trailing_zeros();
                *word &= *word - 1;
                let h = ColliderHandle::from_raw_parts(index, generations[index as usize]);
                let Some(c) = colliders.get(h) else {
                    continue;
                };
                if !c.is_enabled() {
                    continue;
                }
                let ccd = c
                    .parent()
                    .and_then(|p| bodies.get(p))
                    .map_or(0.0, |b| b.soft_ccd_prediction());
                sum += c.compute_collision_aabb(prediction).mins.x + ccd;
            }
        }
        self.checksum = std::hint::black_box(sum);
    }
}

/// Replays recorded updates into `broad_phase` and returns the time spent in its `update` calls
/// alone. Before each update (untimed) the recorded sets are copied afresh, as a step's
/// position update writes the colliders just before Rapier's pipeline calls the broadphase:
/// the broadphase then reads sets that were just written, as it does inside a real step,
/// rather than the recording's copies, which were last touched when they were recorded.
pub fn replay_timed(
    broad_phase: &mut dyn BroadPhase,
    updates: &[RecordedUpdate],
) -> std::time::Duration {
    let mut events = Vec::new();
    let mut total = std::time::Duration::ZERO;
    for u in updates {
        events.clear();
        total += u.apply_timed_on_copies(broad_phase, &mut events);
    }
    std::hint::black_box(events.len());
    total
}

/// Steps `scene` for `steps` steps with Rapier's own broadphase and returns the inputs of every
/// broadphase update it made (two per step), for replays into other broadphases.
///
/// ```
/// use canopy_scenes::{harness, scene, Size};
/// let updates = harness::record(scene("boxes", Size::Small).expect("known scene"), 3);
/// assert_eq!(updates.len(), 6);
/// ```
pub fn record(scene: crate::Scene, steps: usize) -> Vec<RecordedUpdate> {
    let mut world = crate::World::new(scene, Recorder::new(BroadPhaseBvh::new()));
    world.step_n(steps);
    world.broad_phase.updates
}

/// Replays recorded updates into `broad_phase`; returns the number of events it produced.
pub fn replay(broad_phase: &mut dyn BroadPhase, updates: &[RecordedUpdate]) -> usize {
    let mut events = Vec::new();
    let mut n = 0;
    for u in updates {
        events.clear();
        u.apply(broad_phase, &mut events);
        n += events.len();
    }
    n
}
