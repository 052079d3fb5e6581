//! The Rapier broadphase contract, tested on random worlds under random edits: after every
//! update, every pair the narrow phase needs (collision boxes overlap, not filtered) is live;
//! no live pair involves a removed or disabled collider or is filtered; the event stream
//! replays to exactly the live pair set; the candidate pairs are exactly the pairs of fat boxes
//! that overlap and pass the filter; and the events are the same with 1 and 2 threads.
//!
//! The truth is brute force over all collider pairs, with Rapier's filter rules as restated
//! (independently of `filter.rs`) by the measuring harness's `narrow_phase_filter`. The
//! candidate check (`CanopyBroadPhase::candidate_mismatches`) is brute force over all proxy
//! pairs too, with the broadphase's own filter: it checks the pair search, not the filter.

use canopy_rapier::{CanopyBroadPhase, CanopyBroadPhaseConfig, ConfigError};
use canopy_scenes::harness::{handle_pair, narrow_phase_filter, HandlePair};
use proptest::prelude::*;
use rapier3d::prelude::*;
use std::collections::HashSet;

type Pair = HandlePair;

/// A broadphase wrapper that checks the contract after each update and logs the events.
struct Checked {
    inner: CanopyBroadPhase,
    /// The pair set replayed from the events.
    replay: HashSet<Pair>,
    log: Vec<(bool, Pair)>,
    violations: Vec<String>,
    updates: usize,
    checked_pairs: usize,
}

impl Checked {
    fn new(config: CanopyBroadPhaseConfig) -> Self {
        Self {
            inner: CanopyBroadPhase::with_config(config).expect("valid configuration"),
            replay: HashSet::new(),
            log: Vec::new(),
            violations: Vec::new(),
            updates: 0,
            checked_pairs: 0,
        }
    }
}

fn valid(a: &rapier3d::parry::bounding_volume::Aabb) -> bool {
    a.mins.iter().chain(a.maxs.iter()).all(|c| c.is_finite())
}

/// The box the narrow phase needs covered: Rapier's collision box
/// (`Collider::compute_collision_aabb`), except where its loosening (contact skin plus half the
/// prediction distance) is negative or NaN, where parry panics: there, the shape's own box,
/// which still contains the shape.
fn needed_box(c: &Collider, half_prediction: f32) -> rapier3d::parry::bounding_volume::Aabb {
    if c.contact_skin() + half_prediction >= 0.0 {
        c.compute_collision_aabb(half_prediction)
    } else {
        c.compute_aabb()
    }
}

impl BroadPhase for Checked {
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
        self.inner
            .update(params, colliders, bodies, modified, removed, events);
        self.updates += 1;
        // Replay: removed and disabled colliders lose their pairs silently.
        self.replay.retain(|(a, b)| {
            colliders.get(*a).is_some_and(|c| c.is_enabled())
                && colliders.get(*b).is_some_and(|c| c.is_enabled())
        });
        for e in &events[start..] {
            match e {
                BroadPhasePairEvent::AddPair(p) => {
                    let k = handle_pair(p.collider1, p.collider2);
                    if !self.replay.insert(k) {
                        self.violations.push(format!("AddPair of live pair {k:?}"));
                    }
                    self.log.push((true, k));
                }
                BroadPhasePairEvent::DeletePair(p) => {
                    let k = handle_pair(p.collider1, p.collider2);
                    if !self.replay.remove(&k) {
                        self.violations
                            .push(format!("DeletePair of dead pair {k:?}"));
                    }
                    self.log.push((false, k));
                }
            }
        }
        // Candidates: exactly the pairs whose fat boxes overlap and that the filter passes.
        for (a, b, missing) in self.inner.candidate_mismatches().into_iter().take(4) {
            self.violations.push(format!(
                "update {}: candidate {a:?} {b:?} {}",
                self.updates,
                if missing { "missing" } else { "extra" }
            ));
        }
        let live: HashSet<Pair> = self.inner.pairs().map(|(a, b)| handle_pair(a, b)).collect();
        if live != self.replay {
            self.violations.push(format!(
                "update {}: event replay differs from the live set ({} vs {})",
                self.updates,
                self.replay.len(),
                live.len()
            ));
        }
        let prediction = params.prediction_distance() / 2.0;
        let invalid = colliders
            .iter()
            .filter(|(_, c)| c.is_enabled() && !valid(&needed_box(c, prediction)))
            .count();
        if invalid != self.inner.stats().invalid {
            self.violations.push(format!(
                "update {}: {} invalid colliders, stats say {}",
                self.updates,
                invalid,
                self.inner.stats().invalid
            ));
        }
        let all: Vec<(ColliderHandle, &Collider, _)> = colliders
            .iter()
            .filter(|(_, c)| c.is_enabled())
            .map(|(h, c)| (h, c, needed_box(c, prediction)))
            .collect();
        for (i, (h1, c1, a1)) in all.iter().enumerate() {
            for (h2, c2, a2) in &all[i + 1..] {
                if valid(a1)
                    && valid(a2)
                    && a1.intersects(a2)
                    && narrow_phase_filter(c1, c2, bodies)
                {
                    self.checked_pairs += 1;
                    if !self.inner.contains_pair(*h1, *h2) {
                        self.violations.push(format!(
                            "update {}: missing pair {h1:?} {h2:?}",
                            self.updates
                        ));
                    }
                }
            }
        }
        for (a, b) in &live {
            let (Some(c1), Some(c2)) = (colliders.get(*a), colliders.get(*b)) else {
                self.violations
                    .push(format!("live pair with a removed collider {a:?} {b:?}"));
                continue;
            };
            if !c1.is_enabled() || !c2.is_enabled() || !narrow_phase_filter(c1, c2, bodies) {
                self.violations.push(format!(
                    "live pair that the narrow phase discards {a:?} {b:?}"
                ));
            }
            // A pair ends (`DeletePair`) once the fat boxes separate.
            match (self.inner.fat_aabb(*a), self.inner.fat_aabb(*b)) {
                (Some(fa), Some(fb)) if fa.intersects(&fb) => {}
                (fa, fb) => self.violations.push(format!(
                    "update {}: live pair {a:?} {b:?} with fat boxes apart or missing: {fa:?} {fb:?}",
                    self.updates
                )),
            }
        }
    }
}

#[test]
fn huge_margins_keep_every_collider() {
    // Margins and velocity stretches the configuration accepts (finite) but whose fat boxes
    // overflow `f32` once scaled by the length unit or added to a box: the fat box stops at
    // `f32::MAX` instead of becoming infinite, so no collider is taken for invalid and no
    // pair is lost.
    let mut rng = Rng(4242);
    let sim = new_sim(&mut rng, 80);
    let all: Vec<ColliderHandle> = sim.colliders.iter().map(|(h, _)| h).collect();
    let configs = [
        (1.0e38, 0.0, 6.0, 10.0),
        (f32::MAX, 0.0, 6.0, 1.0),
        (0.1, f32::MAX, 6.0, 1.0),
        (0.1, 1.0e38, 6.0, 10.0),
        (0.1, 0.0, f32::MAX, 1.0),
        (f32::MAX, f32::MAX, f32::MAX, f32::MAX),
    ];
    for (margin, fixed_margin, velocity_steps, length_unit) in configs {
        let config = CanopyBroadPhaseConfig {
            margin,
            fixed_margin,
            velocity_steps,
            ..Default::default()
        };
        let params = IntegrationParameters {
            length_unit,
            ..Default::default()
        };
        let mut bp = Checked::new(config);
        let mut events = Vec::new();
        bp.update(&params, &sim.colliders, &sim.bodies, &all, &[], &mut events);
        bp.update(&params, &sim.colliders, &sim.bodies, &all, &[], &mut events);
        let what = format!("{config:?}, length unit {length_unit}");
        let needed_valid = sim
            .colliders
            .iter()
            .filter(|(_, c)| valid(&needed_box(c, params.prediction_distance() / 2.0)))
            .count();
        assert_eq!(
            needed_valid,
            all.len(),
            "{what}: the needed boxes are finite"
        );
        assert_eq!(
            bp.inner.stats().invalid,
            0,
            "{what}: {:?}",
            bp.inner.stats()
        );
        for &h in &all {
            let fat = bp.inner.fat_aabb(h);
            assert!(
                fat.is_some_and(|f| f.is_valid()),
                "{what}: {h:?} has fat box {fat:?}"
            );
        }
        // Stepped under random edits, through the sparse updates and rebuilds.
        let mut rng = Rng(4243);
        let mut stepped = new_sim(&mut rng, 80);
        stepped.params.length_unit = length_unit;
        let mut bp = Checked::new(config);
        for _ in 0..20 {
            for _ in 0..rng.below(3) {
                random_edit(&mut stepped, &mut rng);
            }
            step(&mut stepped, &mut bp);
        }
        assert_eq!(
            bp.inner.stats().invalid,
            0,
            "{what}: {:?}",
            bp.inner.stats()
        );
        assert!(bp.checked_pairs > 0, "{what}");
        assert!(
            bp.violations.is_empty(),
            "{what}: {:#?}",
            &bp.violations[..bp.violations.len().min(10)]
        );
    }
}

#[test]
fn soft_ccd_near_huge_coordinates_keeps_the_pair() {
    // A soft-CCD body near `f32::MAX` whose reach (`|v| dt`) carries its box past it: the box
    // stops at `f32::MAX`, and the body keeps its pair with a fixed ball at the same place.
    let mut bodies = RigidBodySet::new();
    let mut colliders = ColliderSet::new();
    let at = vector![3.4e38, 0.0, 0.0];
    let fixed = colliders.insert(ColliderBuilder::ball(0.5).translation(at));
    let body = bodies.insert(
        RigidBodyBuilder::dynamic()
            .translation(at)
            .linvel(vector![1.0e38, 0.0, 0.0])
            .soft_ccd_prediction(f32::MAX),
    );
    let fast = colliders.insert_with_parent(ColliderBuilder::ball(0.5), body, &mut bodies);
    let all = [fixed, fast];
    let params = IntegrationParameters::default();
    let mut bp = Checked::new(CanopyBroadPhaseConfig::default());
    bp.update(&params, &colliders, &bodies, &all, &[], &mut Vec::new());
    assert_eq!(bp.inner.stats().invalid, 0, "{:?}", bp.inner.stats());
    assert!(bp.inner.contains_pair(fixed, fast));
    assert!(bp.checked_pairs > 0);
    assert!(bp.violations.is_empty(), "{:#?}", bp.violations);
}

#[test]
fn stale_handles_beside_their_successors_hide_nothing() {
    // A removed collider's handle listed as modified together with the collider that reused
    // its index, in either order: the live collider is examined and gets its pair.
    for stale_last in [false, true] {
        let mut bodies = RigidBodySet::new();
        let mut colliders = ColliderSet::new();
        let mut islands = IslandManager::new();
        let params = IntegrationParameters::default();
        let mut bp = Checked::new(CanopyBroadPhaseConfig::default());
        let old = colliders.insert(ColliderBuilder::ball(0.5).translation(vector![9.0, 0.0, 0.0]));
        let body = bodies.insert(RigidBodyBuilder::dynamic());
        let other = colliders.insert_with_parent(ColliderBuilder::ball(0.5), body, &mut bodies);
        bp.update(
            &params,
            &colliders,
            &bodies,
            &[old, other],
            &[],
            &mut Vec::new(),
        );
        assert!(!bp.inner.contains_pair(old, other));
        colliders.remove(old, &mut islands, &mut bodies, false);
        let new = colliders.insert(ColliderBuilder::ball(0.5).translation(vector![0.5, 0.0, 0.0]));
        assert_eq!(
            new.into_raw_parts().0,
            old.into_raw_parts().0,
            "the index is reused"
        );
        let modified = if stale_last { [new, old] } else { [old, new] };
        bp.update(
            &params,
            &colliders,
            &bodies,
            &modified,
            &[old],
            &mut Vec::new(),
        );
        assert!(
            bp.inner.contains_pair(new, other),
            "stale handle last: {stale_last}"
        );
        assert!(bp.checked_pairs > 0);
        assert!(bp.violations.is_empty(), "{:#?}", bp.violations);
    }
}

/// Small deterministic PRNG for world generation and edits.
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }
    fn f(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * ((self.next() >> 40) as f32 / (1u64 << 24) as f32)
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n as u64) as usize
    }
}

struct Sim {
    bodies: RigidBodySet,
    colliders: ColliderSet,
    islands: IslandManager,
    narrow: NarrowPhase,
    pipeline: PhysicsPipeline,
    joints: ImpulseJointSet,
    multibody: MultibodyJointSet,
    ccd: CCDSolver,
    params: IntegrationParameters,
    /// Bodies whose type the edits changed. Removing such a body can make a later step of
    /// Rapier 0.27 panic (`interpolate_kinematic_velocities` meets a removed handle: the
    /// island manager can keep a body's old entry in its active kinematic list after a type
    /// change), so the edits never remove them.
    retyped: Vec<RigidBodyHandle>,
}

const TYPES: [RigidBodyType; 4] = [
    RigidBodyType::Dynamic,
    RigidBodyType::Fixed,
    RigidBodyType::KinematicPositionBased,
    RigidBodyType::KinematicVelocityBased,
];

thread_local! {
    /// Set by tests whose colliders get negative contact skins: Rapier's narrow phase panics
    /// on a compound shape with a negative contact distance (parry's loosening refuses it).
    static NO_COMPOUNDS: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

fn random_shape(rng: &mut Rng) -> ColliderBuilder {
    let kinds = if NO_COMPOUNDS.get() { 7 } else { 8 };
    match rng.below(kinds) {
        0 | 1 => ColliderBuilder::ball(rng.f(0.2, 1.0)),
        2 | 3 => ColliderBuilder::cuboid(rng.f(0.1, 1.0), rng.f(0.1, 1.0), rng.f(0.1, 1.0)),
        4 | 5 => ColliderBuilder::capsule_y(rng.f(0.1, 0.8), rng.f(0.1, 0.5)),
        // Shapes whose boxes come from parry's own code, in worlds of mixed shapes.
        6 => ColliderBuilder::cylinder(rng.f(0.1, 0.8), rng.f(0.1, 0.6)),
        _ => ColliderBuilder::compound(vec![
            (
                Isometry::translation(rng.f(-0.5, 0.5), 0.0, 0.0),
                SharedShape::ball(rng.f(0.1, 0.5)),
            ),
            (
                Isometry::rotation(vector![0.0, rng.f(0.0, 3.0), 0.0]),
                SharedShape::cuboid(rng.f(0.1, 0.6), 0.2, 0.3),
            ),
        ]),
    }
}

fn random_groups(rng: &mut Rng) -> InteractionGroups {
    if rng.below(3) == 0 {
        InteractionGroups::new(
            Group::from_bits_truncate(1 << rng.below(3)),
            Group::from_bits_truncate(rng.below(8) as u32),
        )
    } else {
        InteractionGroups::all()
    }
}

fn add_body(sim: &mut Sim, rng: &mut Rng) {
    let t = TYPES[rng.below(4)];
    let pos = vector![rng.f(-6.0, 6.0), rng.f(0.0, 8.0), rng.f(-6.0, 6.0)];
    let rb = sim
        .bodies
        .insert(RigidBodyBuilder::new(t).translation(pos).linvel(vector![
            rng.f(-2.0, 2.0),
            rng.f(-2.0, 2.0),
            rng.f(-2.0, 2.0)
        ]));
    for _ in 0..1 + rng.below(2) {
        let mut b = random_shape(rng)
            .translation(vector![
                rng.f(-0.5, 0.5),
                rng.f(-0.5, 0.5),
                rng.f(-0.5, 0.5)
            ])
            .collision_groups(random_groups(rng));
        if rng.below(5) == 0 {
            b = b.active_collision_types(ActiveCollisionTypes::all());
        }
        if rng.below(8) == 0 {
            b = b.sensor(true);
        }
        sim.colliders.insert_with_parent(b, rb, &mut sim.bodies);
    }
}

fn new_sim(rng: &mut Rng, n: usize) -> Sim {
    let mut sim = Sim {
        bodies: RigidBodySet::new(),
        colliders: ColliderSet::new(),
        islands: IslandManager::new(),
        narrow: NarrowPhase::new(),
        pipeline: PhysicsPipeline::new(),
        joints: ImpulseJointSet::new(),
        multibody: MultibodyJointSet::new(),
        ccd: CCDSolver::new(),
        params: IntegrationParameters::default(),
        retyped: Vec::new(),
    };
    sim.colliders
        .insert(ColliderBuilder::cuboid(20.0, 0.2, 20.0));
    for _ in 0..n {
        if rng.below(6) == 0 {
            // Parentless (fixed) collider.
            let b = random_shape(rng).translation(vector![
                rng.f(-6.0, 6.0),
                rng.f(0.0, 6.0),
                rng.f(-6.0, 6.0)
            ]);
            sim.colliders.insert(b);
        } else {
            add_body(&mut sim, rng);
        }
    }
    sim
}

fn random_edit(sim: &mut Sim, rng: &mut Rng) {
    let bodies: Vec<RigidBodyHandle> = sim.bodies.iter().map(|(h, _)| h).collect();
    let colliders: Vec<ColliderHandle> = sim.colliders.iter().map(|(h, _)| h).collect();
    if bodies.is_empty() || colliders.is_empty() {
        add_body(sim, rng);
        return;
    }
    let b = bodies[rng.below(bodies.len())];
    let c = colliders[rng.below(colliders.len())];
    match rng.below(12) {
        0 if !sim.retyped.contains(&b) => {
            sim.bodies.remove(
                b,
                &mut sim.islands,
                &mut sim.colliders,
                &mut sim.joints,
                &mut sim.multibody,
                true,
            );
        }
        1 => add_body(sim, rng),
        2 => {
            // Remove then add in the same step: the new collider reuses the handle index.
            sim.colliders
                .remove(c, &mut sim.islands, &mut sim.bodies, true);
            let parent = bodies[rng.below(bodies.len())];
            if sim.bodies.contains(parent) {
                sim.colliders
                    .insert_with_parent(random_shape(rng), parent, &mut sim.bodies);
            }
        }
        3 => {
            sim.bodies[b].set_body_type(TYPES[rng.below(4)], true);
            sim.retyped.push(b);
        }
        4 => {
            let parent = if rng.below(4) == 0 { None } else { Some(b) };
            sim.colliders.set_parent(c, parent, &mut sim.bodies);
        }
        5 => {
            let g = random_groups(rng);
            sim.colliders[c].set_collision_groups(g);
        }
        6 => {
            let on = !sim.colliders[c].is_enabled();
            sim.colliders[c].set_enabled(on);
        }
        7 => {
            let far = vector![rng.f(-50.0, 50.0), rng.f(0.0, 20.0), rng.f(-50.0, 50.0)];
            sim.bodies[b].set_translation(far, true);
        }
        8 => {
            let t = ActiveCollisionTypes::from_bits_truncate(rng.next() as u16);
            sim.colliders[c].set_active_collision_types(t);
        }
        9 => {
            // Another shape (kind and size) for the same collider.
            let shape = random_shape(rng).build().shared_shape().clone();
            sim.colliders[c].set_shape(shape);
        }
        10 => {
            // The collider moves on its body (or, without one, in the world).
            let t = vector![rng.f(-1.0, 1.0), rng.f(-1.0, 1.0), rng.f(-1.0, 1.0)];
            if sim.colliders[c].parent().is_some() {
                sim.colliders[c].set_translation_wrt_parent(t);
            } else {
                sim.colliders[c].set_translation(t * 5.0);
            }
        }
        _ => {
            let v = vector![rng.f(-5.0, 5.0), rng.f(-5.0, 5.0), rng.f(-5.0, 5.0)];
            sim.bodies[b].set_linvel(v, true);
            // Soft CCD on or off now and then: its boxes must stay valid and cover the rest.
            if rng.below(3) == 0 {
                let soft = if rng.below(2) == 0 {
                    0.0
                } else {
                    rng.f(0.1, 2.0)
                };
                sim.bodies[b].set_soft_ccd_prediction(soft);
            }
        }
    }
}

fn step(sim: &mut Sim, bp: &mut dyn BroadPhase) {
    sim.pipeline.step(
        &vector![0.0, -9.81, 0.0],
        &sim.params,
        &mut sim.islands,
        bp,
        &mut sim.narrow,
        &mut sim.bodies,
        &mut sim.colliders,
        &mut sim.joints,
        &mut sim.multibody,
        &mut sim.ccd,
        &(),
        &(),
    );
}

/// Runs a random world with random edits; returns the event log and the checker.
fn run(
    seed: u64,
    bodies: usize,
    steps: usize,
    edits: usize,
    config: CanopyBroadPhaseConfig,
) -> Checked {
    let mut rng = Rng(seed | 1);
    let mut sim = new_sim(&mut rng, bodies);
    let mut bp = Checked::new(config);
    for _ in 0..steps {
        for _ in 0..rng.below(edits + 1) {
            random_edit(&mut sim, &mut rng);
        }
        step(&mut sim, &mut bp);
    }
    // Every live pair reached the narrow phase.
    for (a, b) in bp.inner.pairs() {
        if sim.narrow.contact_pair(a, b).is_none() && sim.narrow.intersection_pair(a, b).is_none() {
            bp.violations
                .push(format!("live pair {a:?} {b:?} unknown to the narrow phase"));
        }
    }
    bp
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 256, ..ProptestConfig::default() })]

    #[test]
    fn contract_holds_under_random_edits(
        seed in any::<u64>(),
        parallel in any::<bool>(),
        margin in 0.0f32..0.5,
        live_pair_skin in prop_oneof![Just(0.0f32), 0.0f32..0.1, Just(f32::MAX)],
    ) {
        let config = CanopyBroadPhaseConfig { margin, parallel, live_pair_skin, ..Default::default() };
        let bp = run(seed, 60, 40, 4, config);
        prop_assert!(bp.violations.is_empty(), "{:#?}", &bp.violations[..bp.violations.len().min(10)]);
        prop_assert!(bp.checked_pairs > 0, "the world produced no pair to check");
    }
}

#[test]
fn body_type_changes_are_seen_in_large_updates() {
    // Body type changes that only the bodies show (no collider moved), in updates that list
    // more colliders than one chunk of the fast path's refattening (256): changes in every
    // chunk count, not only the last one's. A grid of fixed balls, each overlapping its four
    // neighbours (fixed-fixed pairs are filtered), of which three become dynamic.
    let mut bodies = RigidBodySet::new();
    let mut colliders = ColliderSet::new();
    let mut handles = Vec::new();
    for i in 0..600 {
        let at = vector![(i % 30) as f32 * 0.9, 0.0, (i / 30) as f32 * 0.9];
        let b = bodies.insert(RigidBodyBuilder::fixed().translation(at));
        colliders.insert_with_parent(ColliderBuilder::ball(0.5), b, &mut bodies);
        handles.push(b);
    }
    let all: Vec<ColliderHandle> = colliders.iter().map(|(h, _)| h).collect();
    let params = IntegrationParameters::default();
    let mut bp = Checked::new(CanopyBroadPhaseConfig::default());
    let mut events = Vec::new();
    bp.update(&params, &colliders, &bodies, &all, &[], &mut events);
    assert_eq!(bp.inner.stats().pairs, 0);
    for i in [5, 300, 595] {
        bodies[handles[i]].set_body_type(RigidBodyType::Dynamic, true);
    }
    bp.update(&params, &colliders, &bodies, &all, &[], &mut events);
    assert!(bp.violations.is_empty(), "{:#?}", bp.violations);
    // Each of the three pairs with its two to four neighbours.
    assert!(bp.inner.stats().pairs >= 6, "{:?}", bp.inner.stats());
}

/// 300 balls of radius 0.5 in a 20 x 15 grid at height `y`, `spacing` apart, each on a body
/// from `body` placed at its cell; returns the bodies and colliders.
fn ball_grid(
    sim: &mut Sim,
    spacing: f32,
    y: f32,
    body: impl Fn() -> RigidBodyBuilder,
) -> Vec<(RigidBodyHandle, ColliderHandle)> {
    (0..300)
        .map(|i| {
            let at = vector![(i % 20) as f32 * spacing, y, (i / 20) as f32 * spacing];
            let rb = sim.bodies.insert(body().translation(at));
            let c =
                sim.colliders
                    .insert_with_parent(ColliderBuilder::ball(0.5), rb, &mut sim.bodies);
            (rb, c)
        })
        .collect()
}

#[test]
fn a_tree_moving_together_with_nothing_to_pair_with_keeps_the_contract() {
    // A grid of kinematic balls moving as one, each overlapping its neighbours: every ball
    // leaves its fat box in the same updates, which take the marked pair walks. With Rapier's
    // default collision types no tree may pair with the kinematic one (kinematic-kinematic
    // and kinematic-fixed pairs are filtered), so no walk runs and the walks' marks are not
    // made. Then some balls accept kinematic-kinematic contacts (now the tree may pair with
    // itself) and a dynamic ball falls among them: every pair must be found.
    let mut rng = Rng(4242);
    let mut sim = new_sim(&mut rng, 0);
    let balls: Vec<ColliderHandle> = ball_grid(&mut sim, 0.9, 2.0, || {
        RigidBodyBuilder::kinematic_velocity_based().linvel(vector![1.5, 0.0, 0.5])
    })
    .into_iter()
    .map(|(_, c)| c)
    .collect();
    let mut bp = Checked::new(CanopyBroadPhaseConfig::default());
    let mut most_moved = 0;
    let mut run = |sim: &mut Sim, bp: &mut Checked, steps: usize| {
        for _ in 0..steps {
            step(sim, bp);
            most_moved = most_moved.max(bp.inner.stats().moved);
        }
    };
    run(&mut sim, &mut bp, 40);
    assert!(bp.violations.is_empty(), "{:#?}", bp.violations);
    assert_eq!(bp.inner.stats().pairs, 0);
    for &c in balls.iter().step_by(7) {
        sim.colliders[c].set_active_collision_types(
            ActiveCollisionTypes::default() | ActiveCollisionTypes::KINEMATIC_KINEMATIC,
        );
    }
    run(&mut sim, &mut bp, 40);
    assert!(bp.violations.is_empty(), "{:#?}", bp.violations);
    assert!(bp.inner.stats().pairs > 0, "{:?}", bp.inner.stats());
    let drop = sim.bodies.insert(
        RigidBodyBuilder::dynamic()
            .translation(vector![12.0, 3.0, 6.0])
            .linvel(vector![1.5, 0.0, 0.5]),
    );
    sim.colliders
        .insert_with_parent(ColliderBuilder::ball(0.6), drop, &mut sim.bodies);
    run(&mut sim, &mut bp, 40);
    assert!(bp.violations.is_empty(), "{:#?}", bp.violations);
    assert!(bp.checked_pairs > 0);
    // The grid did leave its boxes together (one proxy in four or more of the 301 before the
    // dynamic ball): those updates took the walks.
    assert!(most_moved >= 100, "at most {most_moved} moved at once");
}

#[test]
fn a_tree_most_of_which_teleports_is_rebuilt_in_that_update() {
    // 300 floating balls (no gravity on them); four steps in a row, two thirds of them jump to
    // random places in a cube a kilometre wide. Each of those updates refits the dynamic tree
    // with most of its members' boxes far from their old ones, which multiplies its SAH cost
    // many times over. The cost is compared at once after such a refit, so the tree is rebuilt
    // in that update rather than kept for up to three more (until the check that runs every
    // few refits).
    let mut rng = Rng(777);
    let mut sim = new_sim(&mut rng, 0);
    let balls: Vec<RigidBodyHandle> = ball_grid(&mut sim, 2.0, 5.0, || {
        RigidBodyBuilder::dynamic().gravity_scale(0.0)
    })
    .into_iter()
    .map(|(b, _)| b)
    .collect();
    let mut bp = Checked::new(CanopyBroadPhaseConfig::default());
    for _ in 0..3 {
        step(&mut sim, &mut bp);
    }
    for round in 0..4 {
        let before = bp.inner.stats().rebuilds;
        for (i, &rb) in balls.iter().enumerate() {
            if i % 3 != round % 3 {
                let to = vector![
                    rng.f(-500.0, 500.0),
                    rng.f(-500.0, 500.0),
                    rng.f(-500.0, 500.0)
                ];
                sim.bodies[rb].set_translation(to, true);
            }
        }
        step(&mut sim, &mut bp);
        assert!(
            bp.inner.stats().rebuilds > before,
            "round {round}: the tree was not rebuilt ({:?})",
            bp.inner.stats()
        );
    }
    assert!(bp.violations.is_empty(), "{:#?}", bp.violations);
}

#[test]
fn rebuild_heavy_policy_keeps_the_contract() {
    // Tiny pending and dead limits force rebuilds nearly every step.
    let mut config = CanopyBroadPhaseConfig::default();
    config.rebuild.min_pending = 0;
    config.rebuild.pending_fraction = 0.0;
    config.rebuild.max_dead_fraction = 0.0;
    config.rebuild.max_cost_growth = 1.0;
    for seed in 1..6 {
        let bp = run(seed * 7919, 80, 40, 6, config);
        assert!(
            bp.violations.is_empty(),
            "{:#?}",
            &bp.violations[..bp.violations.len().min(10)]
        );
        assert!(bp.inner.stats().rebuilds > 40);
    }
}

#[test]
fn events_do_not_depend_on_thread_count() {
    let pool = |n| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build()
            .unwrap()
    };
    for seed in [3u64, 99, 12345] {
        let config = CanopyBroadPhaseConfig::default();
        let one = pool(1).install(|| run(seed, 300, 30, 6, config));
        let two = pool(2).install(|| run(seed, 300, 30, 6, config));
        assert!(
            one.log.len() > 100,
            "too few events to compare: {}",
            one.log.len()
        );
        assert_eq!(one.log, two.log);
    }
}

#[test]
fn invalid_boxes_are_skipped_counted_and_come_back() {
    let mut rng = Rng(77);
    let mut sim = new_sim(&mut rng, 0);
    let ball = sim
        .colliders
        .insert(ColliderBuilder::ball(0.5).translation(vector![0.0, 0.5, 0.0]));
    let body = sim
        .bodies
        .insert(RigidBodyBuilder::dynamic().translation(vector![0.0, 1.2, 0.0]));
    let other = sim
        .colliders
        .insert_with_parent(ColliderBuilder::ball(0.5), body, &mut sim.bodies);
    let mut bp = Checked::new(CanopyBroadPhaseConfig::default());
    step(&mut sim, &mut bp);
    assert!(bp.inner.contains_pair(ball, other));
    for bad in [f32::NAN, f32::INFINITY, -f32::INFINITY] {
        sim.colliders[ball].set_translation(vector![bad, 0.5, 0.0]);
        step(&mut sim, &mut bp);
        assert_eq!(bp.inner.stats().invalid, 1);
        assert!(
            !bp.inner.contains_pair(ball, other),
            "pairs of an invalid collider are deleted"
        );
        assert!(bp.inner.fat_aabb(ball).is_none());
        sim.colliders[ball].set_translation(vector![0.0, 0.5, 0.0]);
        sim.bodies[body].set_translation(vector![0.0, 1.2, 0.0], true);
        step(&mut sim, &mut bp);
        assert_eq!(bp.inner.stats().invalid, 0);
        assert!(
            bp.inner.contains_pair(ball, other),
            "the collider comes back"
        );
    }
    // Removing an invalid collider keeps the count right.
    sim.colliders[ball].set_translation(vector![f32::NAN, 0.0, 0.0]);
    step(&mut sim, &mut bp);
    sim.colliders
        .remove(ball, &mut sim.islands, &mut sim.bodies, true);
    step(&mut sim, &mut bp);
    assert_eq!(bp.inner.stats().invalid, 0);
    assert!(bp.violations.is_empty(), "{:#?}", bp.violations);
}

/// A live pair ends (`DeletePair`) once a moved collider's exact box has parted from its
/// partner's by more than twice the live-pair skin, while the fat boxes still overlap: it waits
/// again as a candidate and goes live again (`AddPair`) when the boxes meet. With a skin of
/// `f32::MAX` the pair stays live as long as the fat boxes overlap.
#[test]
fn live_pairs_end_once_their_exact_boxes_part() {
    for (skin, ends) in [(0.01, true), (f32::MAX, false)] {
        let mut bodies = RigidBodySet::new();
        let mut colliders = ColliderSet::new();
        let mut ball_at = |x: f32| {
            let body = bodies.insert(RigidBodyBuilder::dynamic().translation(vector![x, 0.0, 0.0]));
            colliders.insert_with_parent(ColliderBuilder::ball(0.5), body, &mut bodies)
        };
        // Touching at x = 0.5.
        let (a, b) = (ball_at(0.0), ball_at(1.0));
        let config = CanopyBroadPhaseConfig {
            margin: 0.5,
            velocity_steps: 0.0,
            live_pair_skin: skin,
            ..Default::default()
        };
        let mut bp = Checked::new(config);
        let params = IntegrationParameters::default();
        let update = |colliders: &ColliderSet, bp: &mut Checked| {
            let mut events = Vec::new();
            bp.update(&params, colliders, &bodies, &[a, b], &[], &mut events);
            events
        };
        update(&colliders, &mut bp);
        assert!(bp.inner.contains_pair(a, b));
        // `b` moves 0.6 away: its exact box leaves its fat box (margin 0.5), and its new fat box
        // still overlaps the fat box of `a`.
        colliders[b].set_translation(vector![1.6, 0.0, 0.0]);
        let parted = update(&colliders, &mut bp);
        assert_eq!(bp.inner.stats().candidates, 1, "skin {skin}");
        assert_eq!(bp.inner.contains_pair(a, b), !ends, "skin {skin}");
        assert_eq!(
            parted
                .iter()
                .filter(|e| matches!(e, BroadPhasePairEvent::DeletePair(_)))
                .count(),
            ends as usize,
            "skin {skin}"
        );
        // Touching again.
        colliders[b].set_translation(vector![1.0, 0.0, 0.0]);
        let met = update(&colliders, &mut bp);
        assert!(bp.inner.contains_pair(a, b), "skin {skin}");
        assert_eq!(
            met.iter()
                .filter(|e| matches!(e, BroadPhasePairEvent::AddPair(_)))
                .count(),
            ends as usize,
            "skin {skin}"
        );
        assert!(bp.checked_pairs > 0);
        assert!(bp.violations.is_empty(), "{:#?}", bp.violations);
    }
}

#[test]
fn huge_coordinates_do_not_panic() {
    let mut rng = Rng(5);
    let mut sim = new_sim(&mut rng, 10);
    let far = sim
        .colliders
        .insert(ColliderBuilder::cuboid(1.0, 1.0, 1.0).translation(vector![1.0e30, 0.0, 0.0]));
    let mut bp = Checked::new(CanopyBroadPhaseConfig::default());
    for _ in 0..5 {
        step(&mut sim, &mut bp);
    }
    assert!(bp.inner.fat_aabb(far).is_some());
    assert!(bp.violations.is_empty(), "{:#?}", bp.violations);
}

proptest! {
    /// A configuration is accepted exactly when its margins, velocity stretch and live-pair skin
    /// are finite and at least 0 and its rebuild fractions are at least 0; a refused one names
    /// its field.
    #[test]
    fn configurations_are_accepted_exactly_when_in_range(
        margin in prop_oneof![-1.0f32..1.0, Just(f32::NAN), Just(f32::INFINITY)],
        fixed_margin in prop_oneof![0.0f32..1.0, -1.0f32..0.0, Just(f32::NAN)],
        velocity_steps in prop_oneof![0.0f32..20.0, -20.0f32..0.0, Just(f32::NEG_INFINITY)],
        live_pair_skin in prop_oneof![0.0f32..1.0, Just(f32::MAX), Just(-0.01), Just(f32::NAN)],
        max_cost_growth in prop_oneof![0.0f64..4.0, -1.0f64..0.0, Just(f64::INFINITY), Just(f64::NAN)],
        pending_fraction in prop_oneof![0.0f64..1.0, Just(-0.5), Just(f64::NAN)],
        max_dead_fraction in prop_oneof![0.0f64..1.0, Just(-0.5), Just(f64::NAN)],
    ) {
        let mut config = CanopyBroadPhaseConfig {
            margin,
            fixed_margin,
            velocity_steps,
            live_pair_skin,
            ..Default::default()
        };
        config.rebuild.max_cost_growth = max_cost_growth;
        config.rebuild.pending_fraction = pending_fraction;
        config.rebuild.max_dead_fraction = max_dead_fraction;
        let in_range = |x: f32| x.is_finite() && x >= 0.0;
        let bad_f32 = [
            ("margin", margin),
            ("fixed_margin", fixed_margin),
            ("velocity_steps", velocity_steps),
            ("live_pair_skin", live_pair_skin),
        ]
            .into_iter()
            .find(|&(_, x)| !in_range(x));
        let bad_f64 = [
            ("max_cost_growth", max_cost_growth),
            ("pending_fraction", pending_fraction),
            ("max_dead_fraction", max_dead_fraction),
        ]
        .into_iter()
        .find(|&(_, x)| x.is_nan() || x < 0.0);
        match (CanopyBroadPhase::with_config(config), bad_f32, bad_f64) {
            (Ok(bp), None, None) => prop_assert_eq!(bp.config(), &config),
            (Err(ConfigError::NegativeOrNotFinite { field, .. }), Some((bad, _)), _) => {
                prop_assert_eq!(field, bad)
            }
            (Err(ConfigError::NegativeOrNan { field, .. }), None, Some((bad, _))) => {
                prop_assert_eq!(field, bad)
            }
            (got, f, d) => prop_assert!(false, "{:?} for {:?} {:?}", got.map(|_| ()), f, d),
        }
    }
}

/// One update outside a step that lists every collider as modified, so each is examined.
fn update_every_collider(sim: &Sim, bp: &mut Checked) {
    let handles: Vec<ColliderHandle> = sim.colliders.iter().map(|(h, _)| h).collect();
    bp.update(
        &sim.params,
        &sim.colliders,
        &sim.bodies,
        &handles,
        &[],
        &mut Vec::new(),
    );
}

#[test]
fn negative_or_nan_loosening_keeps_every_pair() {
    // Colliders whose contact skin makes the loosening negative or NaN (parry's loosening, and
    // so Rapier's own broadphase, panics on them), among ordinary ones, stepped under random
    // edits: nothing panics, they are counted, and the contract holds against their shapes'
    // own boxes.
    NO_COMPOUNDS.set(true);
    let mut rng = Rng(2024);
    let mut sim = new_sim(&mut rng, 60);
    let handles: Vec<ColliderHandle> = sim.colliders.iter().map(|(h, _)| h).collect();
    let odd: Vec<ColliderHandle> = handles.iter().copied().skip(1).step_by(4).collect();
    for (k, &h) in odd.iter().enumerate() {
        let skin = if k % 3 == 0 { f32::NAN } else { -0.5 };
        sim.colliders[h].set_contact_skin(skin);
    }
    let mut bp = Checked::new(CanopyBroadPhaseConfig::default());
    // Every collider examined once: each odd one counted.
    update_every_collider(&sim, &mut bp);
    assert_eq!(bp.inner.stats().negative_loosening, odd.len());
    for _ in 0..40 {
        for _ in 0..rng.below(4) {
            random_edit(&mut sim, &mut rng);
        }
        step(&mut sim, &mut bp);
    }
    assert!(bp.checked_pairs > 0);
    assert!(
        bp.violations.is_empty(),
        "{:#?}",
        &bp.violations[..bp.violations.len().min(10)]
    );
    // With a valid skin again, a collider is loosened as usual.
    for &h in &odd {
        if let Some(c) = sim.colliders.get_mut(h) {
            c.set_contact_skin(0.0);
        }
    }
    update_every_collider(&sim, &mut bp);
    assert_eq!(bp.inner.stats().negative_loosening, 0);
    step(&mut sim, &mut bp);
    assert!(
        bp.violations.is_empty(),
        "{:#?}",
        &bp.violations[..bp.violations.len().min(10)]
    );
}

#[test]
fn bad_integration_parameters_keep_every_pair() {
    // Integration parameters are user input too: a negative or NaN length unit (margins and
    // prediction distance with it) or time step, and NaN or infinite velocities, must neither
    // panic nor shrink a box below the collider's nor drop a collider from the trees; also for
    // bodies with soft CCD, whose boxes are predicted from the velocity and time step.
    let mut rng = Rng(99);
    let sim = new_sim(&mut rng, 80);
    let (colliders, mut bodies) = (sim.colliders, sim.bodies);
    let body_handles: Vec<RigidBodyHandle> = bodies.iter().map(|(h, _)| h).collect();
    for (k, &h) in body_handles.iter().enumerate().filter(|(k, _)| k % 5 == 0) {
        let bad = [f32::NAN, f32::INFINITY, -f32::INFINITY][k % 3];
        bodies[h].set_linvel(vector![bad, 1.0, -bad], false);
    }
    for (k, &h) in body_handles.iter().enumerate().filter(|(k, _)| k % 2 == 0) {
        bodies[h].set_soft_ccd_prediction([0.5, f32::INFINITY, f32::MAX][k % 3]);
    }
    let all: Vec<ColliderHandle> = colliders.iter().map(|(h, _)| h).collect();
    for (length_unit, dt) in [
        (-1.0, 1.0 / 60.0),
        (f32::NAN, 1.0 / 60.0),
        (1.0, f32::NAN),
        (1.0, -0.5),
    ] {
        let params = IntegrationParameters {
            length_unit,
            dt,
            ..Default::default()
        };
        let mut bp = Checked::new(CanopyBroadPhaseConfig::default());
        let mut events = Vec::new();
        bp.update(&params, &colliders, &bodies, &all, &[], &mut events);
        // A second update over the same colliders (each re-examined) changes nothing.
        bp.update(&params, &colliders, &bodies, &all, &[], &mut events);
        let stats = bp.inner.stats();
        assert_eq!(
            stats.invalid, 0,
            "length unit {length_unit}, dt {dt}: {stats:?}"
        );
        assert!(bp.checked_pairs > 0);
        assert!(
            bp.violations.is_empty(),
            "length unit {length_unit}, dt {dt}: {:#?}",
            &bp.violations[..bp.violations.len().min(10)]
        );
    }
}
