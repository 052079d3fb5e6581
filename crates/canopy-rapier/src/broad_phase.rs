//! [`CanopyBroadPhase`]: rapier3d 0.27's `BroadPhase` on canopy-core trees.
//!
//! One update, in order:
//! 1. Removals (before insertions: a removed handle's index may come back in `modified`).
//!    Pairs of removed or disabled colliders are dropped silently, as Rapier's own broadphase
//!    does: the narrow phase removes them itself.
//! 2. Every collider in `modified` is re-examined (Rapier's change flags are private): its box
//!    (prediction distance, soft-CCD), its filter inputs and its tree. A proxy whose exact box
//!    left its fat box, whose filter changed, or that is new, goes into the move buffer.
//!    Invalid boxes (NaN, infinite) take the proxy out of the trees and delete its pairs.
//! 3. Trees are refit or rebuilt (`proxy_tree.rs`).
//! 4. Deletions: only candidate pairs (fat boxes overlapping, see `pair_set.rs`) of moved
//!    proxies are checked; a candidate goes when the fat boxes separate or the filter now
//!    rejects it, with `DeletePair` if it was live. The searches of step 5 decide it: a
//!    candidate of a moved proxy that its queries (few moves) or the pair walks (many moves)
//!    no longer meet has ended.
//! 5. New candidates. With few moves, one query per moved proxy on every tree it may pair
//!    with (members and the pending proxies' small tree); of two moved proxies the smaller id
//!    reports. Otherwise moved proxies are marked in their tree, and one marked pair walk per
//!    pair of trees that may pair (never fixed-fixed unless some collider enables it) finds
//!    every pair with a moved proxy, skipping subtrees without one (parallel walks give the
//!    same order with any thread count); proxies added since the last rebuild have a small
//!    tree of their own, walked with marks against the member trees, and are swept and pruned
//!    among themselves. A new candidate whose exact boxes overlap is live at once (`AddPair`).
//!    Last, the live pairs of moved proxies whose exact boxes have parted by more than twice
//!    the live-pair skin end (`DeletePair`) and wait again as candidates.
//! 6. Liveness: every collider Rapier reported checks its candidates that are not live yet;
//!    those whose exact boxes now overlap become live (`AddPair`).

use crate::arena_ahead::{body_last_byte, ExamineAhead};
use crate::box_lanes::BoxLanes;
use crate::config::{CanopyBroadPhaseConfig, ConfigError};
use crate::filter::{FilterData, Mobility};
use crate::pair_set::{unkey, Edge, PairSet};
use crate::proxy::{Loc, Place, Proxy};
use crate::proxy_tree::{ProxyTree, DEAD, MOVING_LEAF_SIZE};
use crate::queries::{QueryMirror, QueryOverlay};
use crate::shape_box::Written;
use crate::stats::BroadPhaseStats;
use canopy_core::{Aabb, BuildOptions, PairMarks};
use rapier3d::prelude::*;

/// Sets the bit of each handle's index of `modified` in `bits`, and its generation in
/// `generations` (64 entries per word of `bits`; both grow as needed). Of two handles listed at
/// one index (a stale one beside the collider that reused its index), the live collider's is
/// kept, whatever the order.
///
/// The word being filled stays in a register while consecutive handles fall into it (Rapier
/// often lists them in index order): an `|=` on the word in memory made each handle wait for
/// the store of the one before (perf: `balls`' hottest instruction of the update after the
/// parent body's read).
fn mark_modified(
    bits: &mut Vec<u64>,
    generations: &mut Vec<u32>,
    modified: &[ColliderHandle],
    colliders: &ColliderSet,
) {
    // `acc` holds word `current` of `bits` (none yet: `usize::MAX`).
    let (mut current, mut acc) = (usize::MAX, 0u64);
    for h in modified {
        let (index, generation) = h.into_raw_parts();
        let (word, index) = ((index / 64) as usize, index as usize);
        if word != current {
            if let Some(w) = bits.get_mut(current) {
                *w = acc;
            }
            if word >= bits.len() {
                bits.resize(word + 1, 0);
                generations.resize(bits.len() * 64, 0);
            }
            current = word;
            acc = bits[word];
        }
        let bit = 1u64 << (index % 64);
        let slot = &mut generations[index];
        if acc & bit != 0 && *slot != generation && !colliders.contains(*h) {
            continue;
        }
        acc |= bit;
        *slot = generation;
    }
    if let Some(w) = bits.get_mut(current) {
        *w = acc;
    }
}

/// The examine loop gives the proxies whose exact box left their fat box their new one
/// (`refatten`) every this many words of the modified colliders' bitmap (256 indices), while
/// their collider and body are still cached (`many_kinematics`, where one proxy in fifteen
/// leaves: about 10% of the update, against refattening after the loop). Counted in words,
/// not colliders: no counter in the loop.
const REFATTEN_WORDS: usize = 4;

/// `b` with each infinite coordinate at `±f32::MAX` (a NaN stays NaN): for a box that only
/// overflow made infinite, the largest finite box holding what it held.
fn clamped_to_finite(b: &Aabb) -> Aabb {
    let clamp = |p: Point<f32>| p.map(|x| x.clamp(-f32::MAX, f32::MAX));
    Aabb::new(clamp(b.min), clamp(b.max))
}

/// The fast path compares the parent's body type with the one the proxy was filed under, with
/// no branch on the result (an `|=` into a per-update flag; `check_body_types` finds the
/// colliders when it is set). Where the bodies outgrow the caches (`DELAYED_BODY_BYTES`), the
/// loop asks for the body's last line and compares this many fast-path colliders later, so
/// that the read finds the line cached: `many_static`'s 125,000 bodies (52 MB) took 1.11x as
/// long comparing at once, against 0.96x for comparing late (`tools/ab`, against the chunked
/// checks before); `boxes` and `many_kinematics` (27,000 bodies, 11 MB) are faster comparing
/// at once, `balls` the same either way.
const BODY_TYPE_DELAY: usize = 16;

/// Bodies taking more bytes than this (a last-level cache's worth) have their types compared
/// late (`BODY_TYPE_DELAY`).
const DELAYED_BODY_BYTES: usize = 16 << 20;

/// Starts loading the cache line at `address` into the second-level cache, not the first
/// (`prefetch_into`). (Into the first level as well, body lines evicted what the examine loop
/// was reading: `many_kinematics` about 13% slower, with the chunked checks this replaced.)
#[inline(always)]
fn prefetch_l2(address: usize) {
    prefetch_into::<false>(address);
}

/// The examine loop asks for the colliders and bodies ahead (`ExamineAhead`) when at least one
/// collider in this many is modified: most of the indices just ahead are then its next ones.
const DENSE_EXAMINE: usize = 2;

/// ... and when the colliders and bodies take at least this many bytes (a second-level cache's
/// worth): smaller sets stay cached between updates, and the requests only cost instructions
/// (`boxes`, 1,001 colliders: 0.935 old / new in `tools/ab` with them).
const AHEAD_MIN_BYTES: usize = 2 << 20;

/// Where the colliders' shapes are scattered over the heap (`shapes_look_scattered`), the examine
/// loop asks for the shape of the collider this many modified colliders ahead, from the
/// address its last full examination saw (`shape_hints`). Each shape is an allocation of its
/// own, read by the box computation: in `compare`, where the rest of the physics step runs
/// between two updates, `spawn_storm`'s update waited on that read for about 70% of its time in
/// parry's `Cuboid::compute_aabb`; with this, its update takes about 0.85x the time (alternating
/// runs). Where shapes lie in collider order the hardware streams them, and the loop does not
/// look ahead: doing it always cost `balls` about 10%.
const SHAPE_AHEAD: usize = 8;

/// `shape_kinds` entry of an id with no shape seen.
const NO_KIND: u8 = u8::MAX;

/// Updates between two checks of whether shapes are scattered (64 cache misses each) or of
/// mixed types.
const SHAPE_CHECK_INTERVAL: u32 = 8;

/// The address of the data of `collider`'s shape, for `shape_hints`.
#[inline(always)]
fn shape_address(collider: &Collider) -> usize {
    std::sync::Arc::as_ptr(&collider.shared_shape().0).cast::<u8>() as usize
}

/// `true` when more than a quarter of 64 pairs of neighbouring entries of `v` (`i`, `i + 1`),
/// spread over `v`, satisfy `differ`.
fn neighbours_often_differ<T: Copy>(v: &[T], differ: impl Fn(T, T) -> bool) -> bool {
    const SAMPLES: usize = 64;
    if v.len() < 2 {
        return false;
    }
    let count = (0..SAMPLES)
        .map(|j| j * (v.len() - 1) / SAMPLES)
        .filter(|&i| differ(v[i], v[i + 1]))
        .count();
    count > SAMPLES / 4
}

/// Whether bit `i` of the bitmap `words` is set (bits past its end are not).
#[inline]
fn has_bit(words: &[u64], i: u32) -> bool {
    words
        .get(i as usize / 64)
        .is_some_and(|w| w & (1 << (i % 64)) != 0)
}

/// The set bits of a bitmap, in order (the examine loop walks its words by hand instead,
/// which measured faster there).
struct SetBits<'a> {
    words: &'a [u64],
    w: usize,
    word: u64,
}

impl<'a> SetBits<'a> {
    fn new(words: &'a [u64]) -> Self {
        Self {
            words,
            w: 0,
            word: words.first().copied().unwrap_or(0),
        }
    }
}

impl Iterator for SetBits<'_> {
    type Item = u32;

    #[inline(always)]
    fn next(&mut self) -> Option<u32> {
        while self.word == 0 {
            self.w += 1;
            self.word = *self.words.get(self.w)?;
        }
        let bit = self.word.trailing_zeros();
        self.word &= self.word - 1;
        Some(self.w as u32 * 64 + bit)
    }
}

/// Two proxy ids.
type IdPair = (u32, u32);

/// Buffers an update fills and empties, kept from one update to the next so that none is
/// allocated and grown afresh every update (each is empty between updates).
#[derive(Clone, Debug, Default)]
struct Scratch {
    /// The former partners of a proxy taken out (`PairSet::remove_all`).
    edges: Vec<Edge>,
    /// Steps 4 and 5: the candidates that ended, the new candidates, and which of a moved
    /// proxy's candidates its queries met.
    gone: Vec<IdPair>,
    found: Vec<IdPair>,
    seen: KnownMarks,
    /// Live pairs whose exact boxes parted (`end_parted_live_pairs`), and step 6's waiting
    /// candidates that become live: each as a proxy id and the index of the pair's edge in
    /// its partner list.
    parted: Vec<(u32, u32)>,
    flips: Vec<(u32, u32)>,
    /// Steps 4 and 5 when many moved: a bitmap of the moved proxy ids.
    moved_bits: Vec<u64>,
}

/// Per proxy id, two bits for the query of one moved proxy (`moved_pairs`): the id is a
/// candidate partner of that proxy, and the query met it. All clear between queries: `take` clears
/// both bits of each partner that `mark` set.
#[derive(Clone, Debug, Default)]
struct KnownMarks {
    known: Vec<u64>,
    met: Vec<u64>,
}

impl KnownMarks {
    /// Room for ids below `n`.
    fn fit(&mut self, n: usize) {
        let words = n.div_ceil(64);
        if self.known.len() < words {
            self.known.resize(words, 0);
            self.met.resize(words, 0);
        }
    }

    /// Marks every partner id in `known` (ids within `fit`).
    #[inline]
    fn mark(&mut self, known: impl IntoIterator<Item = u32>) {
        for id in known {
            self.known[id as usize / 64] |= 1 << (id % 64);
        }
    }

    /// `true` when `id` is a marked partner (then noted as met).
    #[inline]
    fn meet(&mut self, id: u32) -> bool {
        let (w, bit) = (id as usize / 64, 1u64 << (id % 64));
        let known = self.known[w] & bit != 0;
        self.met[w] |= bit & (known as u64).wrapping_neg();
        known
    }

    /// Whether marked partner `id` was met; clears both its bits.
    #[inline]
    fn take(&mut self, id: u32) -> bool {
        let (w, bit) = (id as usize / 64, 1u64 << (id % 64));
        let met = self.met[w] & bit != 0;
        self.known[w] &= !bit;
        self.met[w] &= !bit;
        met
    }
}

/// The inputs of step 2 (`examine_all`).
#[derive(Clone, Copy)]
struct ExaminePass<'a> {
    params: &'a IntegrationParameters,
    colliders: &'a ColliderSet,
    bodies: &'a RigidBodySet,
    /// Bitmap of the modified colliders' indices, and their generations.
    modified: &'a [u64],
    generations: &'a [u32],
    /// Shape hints to prefetch, in the loop's order (empty where shapes are not scattered).
    shape_queue: &'a [usize],
    /// Where the colliders and bodies ahead lie, when most colliders are modified (the loop
    /// then asks for the colliders a few indices ahead: most of them are its next ones).
    ahead: Option<ExamineAhead>,
    shapes_mixed: bool,
    margins: (f32, f32),
}

/// What step 2 did with one collider.
enum Examined<'b> {
    /// The fast path: the parent (if any) and the body type the proxy was filed under, still
    /// to compare (`BODY_TYPE_DELAY`), and whether the exact box left the fat box (the
    /// caller gives those their new fat box: `refatten`).
    Fast {
        parent: Option<&'b RigidBody>,
        filed: RigidBodyType,
        left: bool,
    },
    /// Anything else: the full examination, or a collider that is gone.
    Full,
}

/// With the `phase-times` feature, adds the time since the last lap to phase `$field` of
/// `$self.phase_times`; without it, nothing.
macro_rules! lap {
    ($self:ident, $clock:ident, $field:ident) => {
        #[cfg(feature = "phase-times")]
        $clock.lap(&mut $self.phase_times.$field);
    };
}

/// Loops over moved proxies or pairs by id, whose records and partner lists are scattered over
/// the arrays (a cache miss each), ask for them this many entries ahead: a proxy's record and
/// the head of its partner list; the list itself, whose address is in the head, half as far
/// ahead. (`spawn_storm` replay: 1.09x faster, `tools/ab`; 8 instead of 4, no better. Loops
/// over nearly every proxy, in index order, need none: the hardware streams them.)
const PREFETCH_AHEAD: usize = 4;

/// Starts loading the one cache line holding `address`, into every cache level when `L1`,
/// else from the second level out. Only a hint: a prefetch never faults and never changes
/// memory, whatever the address.
#[inline(always)]
fn prefetch_into<const L1: bool>(address: usize) {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: see above; SSE is part of the x86-64 baseline.
    unsafe {
        use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0, _MM_HINT_T1};
        let p = address as *const i8;
        if L1 {
            _mm_prefetch::<_MM_HINT_T0>(p);
        } else {
            _mm_prefetch::<_MM_HINT_T1>(p);
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = address;
}

/// Starts loading the one cache line holding `address`, into every cache level.
#[inline(always)]
pub(crate) fn prefetch_line(address: usize) {
    prefetch_into::<true>(address);
}

/// Starts loading the cache lines holding the 64 bytes from `p` (one or two lines: a proxy
/// record straddles two), into every cache level.
#[inline(always)]
pub(crate) fn prefetch<T>(p: *const T) {
    prefetch_line(p as usize);
    prefetch_line((p as usize).wrapping_add(63));
}

/// With fewer moved proxies than one tree member in this many, new pairs are found by one
/// query per moved proxy instead of marked pair walks. 8 until the walks tested two leaves'
/// primitives only after cutting each down to those that overlap the other leaf's box; since
/// then the queries win up to more moved proxies (`spawn_storm`'s grid landing on its pile,
/// 694 to 1,525 of 4,000 moved: the walks and their bookkeeping took 0.9 to 1.1 ms). `tools/ab`
/// old / new, 4 against 8: `spawn_storm` 1.017 (9 runs), `many_kinematics` 1.069, `balls`
/// 1.002, `teleport` 1.001, the others within noise; 3 gave 1.012 and 1.004, 2 gave 1.008 and
/// `balls` 0.987.
const SPARSE_MOVES: usize = 4;

/// A broadphase for Rapier built on canopy-core BVHs: fat boxes, one tree per mobility
/// (fixed, kinematic, dynamic), a move buffer, per-proxy pair lists and pair filtering at the
/// source. Swap it in wherever Rapier takes a `&mut dyn BroadPhase`.
///
/// ```
/// use canopy_rapier::CanopyBroadPhase;
/// use rapier3d::prelude::*;
///
/// let mut bodies = RigidBodySet::new();
/// let mut colliders = ColliderSet::new();
/// colliders.insert(ColliderBuilder::cuboid(10.0, 0.1, 10.0));
/// let ball = bodies.insert(RigidBodyBuilder::dynamic().translation(vector![0.0, 1.0, 0.0]));
/// colliders.insert_with_parent(ColliderBuilder::ball(0.5), ball, &mut bodies);
///
/// let mut broad_phase = CanopyBroadPhase::new();
/// let (mut pipeline, mut islands, mut narrow_phase) =
///     (PhysicsPipeline::new(), IslandManager::new(), NarrowPhase::new());
/// let (mut joints, mut multibody_joints, mut ccd) =
///     (ImpulseJointSet::new(), MultibodyJointSet::new(), CCDSolver::new());
/// for _ in 0..120 {
///     pipeline.step(
///         &vector![0.0, -9.81, 0.0], &IntegrationParameters::default(), &mut islands,
///         &mut broad_phase, &mut narrow_phase, &mut bodies, &mut colliders, &mut joints,
///         &mut multibody_joints, &mut ccd, &(), &(),
///     );
/// }
/// // The ball rests on the ground.
/// let y = bodies[ball].translation().y;
/// assert!((y - 0.6).abs() < 0.05, "ball at {y}");
/// assert_eq!(broad_phase.stats().pairs, 1);
/// ```
#[derive(Clone, Debug, Default)]
pub struct CanopyBroadPhase {
    config: CanopyBroadPhaseConfig,
    /// Indexed by the collider handle's index.
    pub(crate) proxies: Vec<Option<Proxy>>,
    /// Indexed like `proxies`: where each proxy is in its tree, and its flags for this update
    /// (apart from the records, which the examine loop streams: `proxy.rs`).
    places: Vec<Place>,
    pub(crate) trees: [ProxyTree; 3],
    pairs: PairSet,
    moved: Vec<u32>,
    /// Per tree (by mobility): some BVH member of that tree is in `moved`, and some pending
    /// proxy of it (set by `mark_moved`, cleared at the end of each update; a rebuild turns the
    /// second into the first).
    moved_members: [bool; 3],
    moved_pending: [bool; 3],
    stats: BroadPhaseStats,
    /// Number of proxies whose `active_collision_types` allow fixed-fixed contacts.
    fixed_fixed: usize,
    /// Per proxy id: the exact collision box at the last update that saw the collider. Kept
    /// apart from the proxies so the liveness pass reads one dense array. A collider Rapier
    /// does not report has not moved, so every valid proxy's entry is its current box.
    pub(crate) tights: Vec<Aabb>,
    /// Per proxy id: where the collider's shape was at its last full examination (the address
    /// of its data, 0 for none), as a number: only ever used as a prefetch hint, never read
    /// through. See `SHAPE_AHEAD`.
    shape_hints: Vec<usize>,
    /// Reused buffer: the shape hints of this update's modified colliders, in handle order.
    shape_queue: Vec<usize>,
    /// Per proxy id: the type of the collider's shape at its last full examination
    /// (`ShapeType as u8`, `NO_KIND` for none), a hint for `shapes_look_mixed`.
    shape_kinds: Vec<u8>,
    /// The last answers of `shapes_look_scattered` and `shapes_look_mixed`, and the updates
    /// since the first check.
    shapes_scattered: bool,
    shapes_mixed: bool,
    shape_checks: u32,
    /// Compare body types late (`BODY_TYPE_DELAY`) whatever the bodies' size: for tests of
    /// that path on small worlds.
    delay_body_types: bool,
    /// Reused buffers: a bitmap of the modified handles' indices (all zero between updates;
    /// step 6 reads it) and their generations.
    scratch_order: (Vec<u64>, Vec<u32>),
    scratch: Scratch,
    /// Edits made outside a step, for the scene queries (`queries/overlay.rs`).
    pub(crate) overlay: QueryOverlay,
    /// The parry BVH behind `as_query_pipeline` (`queries/pipeline.rs`).
    pub(crate) mirror: QueryMirror,
    /// Time per step of `update`, summed (`phase_times.rs`).
    #[cfg(feature = "phase-times")]
    phase_times: crate::phase_times::PhaseTimes,
}

impl CanopyBroadPhase {
    /// A broadphase with the default configuration.
    pub fn new() -> Self {
        Self::default()
    }

    /// A broadphase with the given configuration, or the first field out of range
    /// ([`CanopyBroadPhaseConfig::validate`]).
    ///
    /// ```
    /// use canopy_rapier::{CanopyBroadPhase, CanopyBroadPhaseConfig};
    /// let config = CanopyBroadPhaseConfig { margin: 0.05, ..Default::default() };
    /// let broad_phase = CanopyBroadPhase::with_config(config)?;
    /// assert_eq!(broad_phase.config().margin, 0.05);
    /// let negative = CanopyBroadPhaseConfig { velocity_steps: -1.0, ..Default::default() };
    /// assert!(CanopyBroadPhase::with_config(negative).is_err());
    /// # Ok::<(), canopy_rapier::ConfigError>(())
    /// ```
    pub fn with_config(config: CanopyBroadPhaseConfig) -> Result<Self, ConfigError> {
        config.validate()?;
        Ok(Self {
            config,
            ..Default::default()
        })
    }

    /// The configuration.
    pub fn config(&self) -> &CanopyBroadPhaseConfig {
        &self.config
    }

    /// Counts of what the broadphase holds and what its last update did.
    pub fn stats(&self) -> BroadPhaseStats {
        let mut s = self.stats;
        s.proxies = [0, 1, 2].map(|i| self.trees[i].len());
        s.pairs = self.pairs.live_len();
        s.candidates = self.pairs.candidate_len();
        s.rebuilds = self.trees.iter().map(|t| t.rebuilds).sum();
        s.refits = self.trees.iter().map(|t| t.refits).sum();
        s
    }

    /// The time each step of `update` took, summed over the updates since the last call, and
    /// resets it (feature `phase-times`).
    #[cfg(feature = "phase-times")]
    pub fn take_phase_times(&mut self) -> crate::PhaseTimes {
        std::mem::take(&mut self.phase_times)
    }

    /// `true` when the pair of colliders is live (reported by `AddPair` and not deleted since).
    pub fn contains_pair(&self, a: ColliderHandle, b: ColliderHandle) -> bool {
        match (self.proxy_id(a), self.proxy_id(b)) {
            (Some(x), Some(y)) => self.pairs.is_live(x, y),
            _ => false,
        }
    }

    /// Every live pair, in no particular order.
    pub fn pairs(&self) -> impl Iterator<Item = (ColliderHandle, ColliderHandle)> + '_ {
        self.pairs.live_pairs().filter_map(|(a, b)| {
            let pa = self.proxies.get(a as usize)?.as_ref()?;
            let pb = self.proxies.get(b as usize)?.as_ref()?;
            Some((pa.handle(a), pb.handle(b)))
        })
    }

    /// The fat box stored for a collider, `None` when it is not in the broadphase (unknown,
    /// removed, disabled, or with an invalid box).
    pub fn fat_aabb(&self, handle: ColliderHandle) -> Option<Aabb> {
        let p = self.proxy(handle)?;
        p.is_valid().then_some(p.fat)
    }

    /// For tests: the pairs of colliders in the broadphase whose candidate status is wrong,
    /// each with `true` when it is missing (fat boxes overlapping and the filter passing, not a
    /// candidate) and `false` when it should not be one. Every pair of proxies is checked, so
    /// this costs time quadratic in the number of colliders; it allocates. Empty between
    /// updates of a correct broadphase.
    #[doc(hidden)]
    pub fn candidate_mismatches(&self) -> Vec<(ColliderHandle, ColliderHandle, bool)> {
        let valid: Vec<(u32, &Proxy)> = self
            .proxies
            .iter()
            .enumerate()
            .filter_map(|(i, p)| Some((i as u32, p.as_ref().filter(|p| p.is_valid())?)))
            .collect();
        let mut wrong = Vec::new();
        for (k, &(a, pa)) in valid.iter().enumerate() {
            let partners = self.pairs.partners(a);
            for &(b, pb) in &valid[k + 1..] {
                let should = pa.fat.intersects(&pb.fat) && pa.filter.may_pair(&pb.filter);
                let is = partners.iter().any(|e| e.other == b);
                if should != is {
                    wrong.push((pa.handle(a), pb.handle(b), should));
                }
            }
        }
        wrong
    }

    fn proxy_id(&self, handle: ColliderHandle) -> Option<u32> {
        self.proxy(handle).map(|_| handle.into_raw_parts().0)
    }

    fn proxy(&self, handle: ColliderHandle) -> Option<&Proxy> {
        let p = self
            .proxies
            .get(handle.into_raw_parts().0 as usize)?
            .as_ref()?;
        p.is_for(handle).then_some(p)
    }

    /// `true` when the shapes of the colliders seem scattered over the heap rather than laid
    /// out in collider order (where the hardware prefetcher already streams them): neighbouring
    /// proxy ids often have shapes more than 512 bytes apart. Shapes allocated one after the
    /// other when the world was built are neighbours; those of colliders added later to reused
    /// slots are not (`spawn_storm`).
    fn shapes_look_scattered(&self) -> bool {
        neighbours_often_differ(&self.shape_hints, |a, b| {
            a != 0 && b != 0 && a.abs_diff(b) > 512
        })
    }

    /// `true` when neighbouring proxy ids (neighbours in the examine loop) often have shapes of
    /// different types (`spawn_storm`'s mix of balls, cuboids and capsules; not scenes of one
    /// shape on a ground).
    fn shapes_look_mixed(&self) -> bool {
        neighbours_often_differ(&self.shape_kinds, |a, b| {
            a != NO_KIND && b != NO_KIND && a != b
        })
    }

    /// Records where the collider's shape is and its type, the hints of `shapes_look_scattered`
    /// and `shapes_look_mixed` (at a full examination; the fast path reads neither).
    fn note_shape(&mut self, id: u32, collider: &Collider) {
        self.shape_hints[id as usize] = shape_address(collider);
        self.shape_kinds[id as usize] = collider.shape().shape_type() as u8;
    }

    /// Drops a proxy and its pairs without events (the collider is gone or disabled).
    fn remove_proxy(&mut self, id: u32) {
        let Some(p) = self.proxies.get_mut(id as usize).and_then(Option::take) else {
            return;
        };
        if !p.is_valid() {
            self.stats.invalid -= 1;
        }
        self.mirror.touch(id);
        self.take_out_of_tree(id, p.mobility());
        if p.filter.active.contains(ActiveCollisionTypes::FIXED_FIXED) {
            self.fixed_fixed -= 1;
        }
        self.drop_pairs(id, None);
    }

    /// Drops every candidate of proxy `id` (`PairSet::remove_all`); with `events`, reports
    /// `DeletePair` for those that were live (`id`'s proxy must then be in place, for the
    /// pair's handles).
    fn drop_pairs(&mut self, id: u32, events: Option<&mut Vec<BroadPhasePairEvent>>) {
        let mut edges = std::mem::take(&mut self.scratch.edges);
        self.pairs.remove_all(id, &mut edges);
        if let Some(events) = events {
            for e in edges.iter().filter(|e| e.live()) {
                self.push_delete(id, e.other, events);
            }
        }
        edges.clear();
        self.scratch.edges = edges;
    }

    /// Takes proxy `id` out of the tree of `mobility` (its location becomes [`Loc::Out`]); the
    /// caller keeps its record valid or drops it.
    fn take_out_of_tree(&mut self, id: u32, mobility: Mobility) {
        let loc = std::mem::take(&mut self.places[id as usize].loc);
        if let Some((other, i)) = self.trees[mobility as usize].remove(loc) {
            self.places[other as usize].loc = Loc::Pending(i);
        }
    }

    /// Puts proxy `id` into the move buffer, once per update (its `moved` flag): the dense
    /// path's `take_unmet` relies on `moved` holding each id once.
    fn mark_moved(&mut self, id: u32) {
        self.mirror.touch(id);
        if let Some(p) = self.proxies[id as usize].as_ref() {
            let m = p.mobility() as usize;
            let place = &mut self.places[id as usize];
            // Before the `moved` check: a second examination may have moved it to another tree.
            match place.loc {
                Loc::Tree(_) => self.moved_members[m] = true,
                Loc::Pending(_) => self.moved_pending[m] = true,
                Loc::Out => {}
            }
            if !place.moved {
                place.moved = true;
                self.moved.push(id);
            }
        }
    }

    /// The box the narrow phase needs covered: Rapier's collision box (prediction distance);
    /// with soft CCD, merged with the box at the predicted pose (as Rapier's broadphase does)
    /// and loosened by the soft-CCD reach (`soft_ccd_reach`). `written_out`: through
    /// `shape_box::collision_box` (the same box, bit for bit), else through parry's virtual
    /// `compute_aabb` (the better choice where neighbouring colliders' shapes differ: one
    /// unpredictable call instead of an unpredictable call and an unpredictable branch).
    ///
    /// Where the loosening (contact skin plus half the prediction distance) is negative or NaN,
    /// which makes parry's loosening (and so Rapier's own broadphase) panic, the box is the
    /// shape's box, not loosened, and `negative_loosening` (the stats' count for this update)
    /// counts the collider. That box is
    /// still a superset of the shape, so no pair the narrow phase could need is lost.
    #[inline(always)]
    fn collision_aabb(
        params: &IntegrationParameters,
        collider: &Collider,
        parent: Option<&RigidBody>,
        written_out: bool,
        negative_loosening: &mut usize,
    ) -> Aabb {
        Self::collision_lanes(params, collider, parent, written_out, negative_loosening).to_aabb()
    }

    /// `collision_aabb` as lanes, for the examine loop: parry's box goes from the two stores
    /// that return it to the lanes without a load that straddles them
    /// (`BoxLanes::load_parry`).
    #[inline(always)]
    fn collision_lanes(
        params: &IntegrationParameters,
        collider: &Collider,
        parent: Option<&RigidBody>,
        written_out: bool,
        negative_loosening: &mut usize,
    ) -> BoxLanes {
        let prediction = params.prediction_distance() / 2.0;
        let amount = collider.contact_skin() + prediction;
        let negative = amount.is_nan() || amount < 0.0;
        // The parent, when it has soft CCD.
        let soft_ccd = parent.filter(|rb| rb.soft_ccd_prediction() > 0.0);
        if negative || soft_ccd.is_some() {
            return BoxLanes::load(&Self::unusual_collision_aabb(
                params,
                collider,
                soft_ccd,
                written_out,
                prediction,
                negative,
                negative_loosening,
            ));
        }
        if written_out {
            BoxLanes::load_parry(&crate::shape_box::collision_box(collider, prediction))
        } else {
            // `Collider::compute_collision_aabb`'s operations without its call: the shape's box,
            // loosened in the lanes.
            BoxLanes::load_parry(&collider.shape().compute_aabb(collider.position()))
                .loosened(amount)
        }
    }

    /// `collision_aabb` where the loosening is negative or NaN (`negative`), or the parent has
    /// soft CCD (`soft_ccd`: that parent); `prediction` is half the prediction distance, as
    /// `collision_lanes` found all three.
    #[allow(clippy::too_many_arguments)]
    #[cold]
    #[inline(never)]
    fn unusual_collision_aabb(
        params: &IntegrationParameters,
        collider: &Collider,
        soft_ccd: Option<&RigidBody>,
        written_out: bool,
        prediction: f32,
        negative: bool,
        negative_loosening: &mut usize,
    ) -> Aabb {
        let aabb = if negative {
            *negative_loosening += 1;
            Self::unloosened_aabb(collider)
        } else if written_out {
            crate::shape_box::collision_box(collider, prediction)
        } else {
            collider.compute_collision_aabb(prediction)
        };
        match soft_ccd {
            Some(rb) => Self::with_soft_ccd(params, collider, rb, aabb),
            None => Aabb::new(aabb.mins, aabb.maxs),
        }
    }

    /// `collision_aabb`'s box `aabb` for a collider whose parent `rb` has soft CCD: merged
    /// with the box at the predicted pose and loosened by the soft-CCD reach.
    #[cold]
    #[inline(never)]
    fn with_soft_ccd(
        params: &IntegrationParameters,
        collider: &Collider,
        rb: &RigidBody,
        mut aabb: rapier3d::parry::bounding_volume::Aabb,
    ) -> Aabb {
        // A predicted pose from a NaN or infinite velocity or time step gives no box: the
        // current one stays, valid, rather than the collider leaving the trees.
        let predicted = Self::soft_ccd_aabb(params, collider, rb);
        if crate::queries::finite(predicted.mins.iter().chain(predicted.maxs.iter())) {
            aabb.merge(&predicted);
        }
        let finite = crate::queries::finite(aabb.mins.iter().chain(aabb.maxs.iter()));
        aabb = aabb.loosened(Self::soft_ccd_reach(params, rb));
        if finite {
            // A finite box loosened past `f32::MAX` (a huge reach near huge coordinates) stops
            // there rather than becoming invalid.
            return clamped_to_finite(&Aabb::new(aabb.mins, aabb.maxs));
        }
        Aabb::new(aabb.mins, aabb.maxs)
    }

    /// How much farther than the prediction distance Rapier's narrow phase looks for contacts
    /// of a collider whose parent has soft CCD: it makes contacts up to `dt` times the two
    /// bodies' relative velocity, each velocity capped at `soft_ccd_prediction / dt`
    /// (`NarrowPhase::compute_contacts`), on the colliders' current poses and in every
    /// direction. That is at most the sum of this reach, `min(|v| dt, soft_ccd_prediction)`,
    /// over the two bodies, so boxes loosened by it overlap whenever the narrow phase could
    /// make a contact. (Merging only the box at the predicted pose, as Rapier's broadphase
    /// does, left out 65 of 131,297 pairs with contacts in a scene of fast soft-CCD bodies,
    /// `tests/soft_ccd.rs`: bodies passing each other sideways; Rapier's broadphase keeps
    /// such pairs through its looser tree leaves.) 0 for a NaN velocity or time step.
    #[cold]
    #[inline(never)]
    fn soft_ccd_reach(params: &IntegrationParameters, rb: &RigidBody) -> f32 {
        let reach = (rb.linvel().norm() * params.dt).min(rb.soft_ccd_prediction());
        if reach > 0.0 && reach.is_finite() {
            reach
        } else {
            0.0
        }
    }

    /// The box of the collider's shape at its pose, not loosened (see `collision_aabb`).
    #[cold]
    #[inline(never)]
    fn unloosened_aabb(collider: &Collider) -> rapier3d::parry::bounding_volume::Aabb {
        collider.shape().compute_aabb(collider.position())
    }

    /// The collider's box at the pose soft CCD predicts for its parent (rarely enabled, so out
    /// of line), loosened as `collision_aabb` loosens (not at all where that is negative).
    #[cold]
    #[inline(never)]
    fn soft_ccd_aabb(
        params: &IntegrationParameters,
        collider: &Collider,
        rb: &RigidBody,
    ) -> rapier3d::parry::bounding_volume::Aabb {
        let prediction = params.prediction_distance();
        let max_dist = rb.soft_ccd_prediction();
        // Rapier clamps the predicted motion to `max_dist`; its exact helper is private, so
        // clamp the time step the same way from the current velocity.
        let speed = rb.linvel().norm();
        let dt = if speed * params.dt > max_dist {
            max_dist / speed
        } else {
            params.dt
        };
        let pose = rb.predict_position_using_velocity_and_forces(dt)
            * collider
                .position_wrt_parent()
                .copied()
                .unwrap_or_else(Isometry::identity);
        collider
            .shape()
            .compute_aabb(&pose)
            .loosened((collider.contact_skin() + prediction / 2.0).max(0.0))
    }

    /// The fat box of an exact box: enlarged by the margin (`margins.1` for colliders of fixed
    /// bodies or without a body, `margins.0` for the others), and stretched along the parent's
    /// linear velocity over `velocity_steps` steps.
    ///
    /// A NaN or infinite stretch (velocity or time step) is left out: the box without it is
    /// still valid, and the collider stays in the trees. A fat box that overflows `f32` (a huge
    /// margin or stretch, which the configuration accepts) stops at `±f32::MAX`: see
    /// `finite_fat_box`.
    #[inline(always)]
    fn fat_box(
        velocity_steps: f32,
        tight: &Aabb,
        margins: (f32, f32),
        params: &IntegrationParameters,
        parent: Option<&RigidBody>,
    ) -> BoxLanes {
        let fixed = parent.is_none_or(|rb| rb.is_fixed());
        let margin = if fixed { margins.1 } else { margins.0 };
        let d = parent.map_or([0.0; 3], |rb| {
            let d = rb.linvel() * (params.dt * velocity_steps);
            [d.x, d.y, d.z]
        });
        let fat = BoxLanes::load(tight).fattened(margin, d);
        if fat.is_valid() {
            fat
        } else {
            Self::finite_fat_box(tight, fat)
        }
    }

    /// `fat_box` where the fat box is not valid. If the exact box is valid, only an overflow
    /// made it so (the margin is at least 0, possibly infinite, and only finite stretches are
    /// added: no NaN, and the sides stay ordered), and each infinite side stops at
    /// `±f32::MAX`: the box still holds the exact box, and the collider is not taken for an
    /// invalid one. Otherwise the box is left invalid.
    #[cold]
    #[inline(never)]
    fn finite_fat_box(tight: &Aabb, fat: BoxLanes) -> BoxLanes {
        if !tight.is_valid() {
            return fat;
        }
        BoxLanes::load(&clamped_to_finite(&fat.to_aabb()))
    }

    /// Step 2 for one collider: the fast path here, everything else in `examine_full`. On the
    /// fast path, returns the parent body and the body type the proxy was filed under (the
    /// caller still has to compare them) and whether the exact box left the fat box (the
    /// caller refattens those a chunk at a time): see `examine_all`. Always inlined into
    /// `examine_all`: called there, `balls` took about 1.1x as long.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn examine<'b, const WRITTEN_OUT: bool>(
        &mut self,
        params: &IntegrationParameters,
        colliders: &ColliderSet,
        bodies: &'b RigidBodySet,
        handle: ColliderHandle,
        margins: (f32, f32),
        events: &mut Vec<BroadPhasePairEvent>,
    ) -> Examined<'b> {
        let id = handle.into_raw_parts().0;
        let Some(collider) = colliders.get(handle) else {
            return Examined::Full;
        };
        let parent = collider.parent().and_then(|h| bodies.get(h));
        let enabled = collider.is_enabled();

        // Fast path, the common case: a known, valid proxy whose filter inputs did not change
        // (the parent's body type is checked after the loop). Either its exact box is still
        // inside its fat box (nothing to do), or it gets a new fat box in place after the loop.
        if let Some(Some(p)) = self.proxies.get_mut(id as usize) {
            if enabled
                && p.is_for(handle)
                && p.is_valid()
                && p.filter.same_as_but_body_type(collider, parent.is_some())
            {
                // Whether the exact box left the fat box waits on the collider's memory: no
                // branch on it here or in the caller (a misprediction would stall the loop
                // until that load arrives). The caller writes the id either way and keeps it
                // only when it left; those get their new fat box a chunk later (`refatten`).
                let left = if WRITTEN_OUT {
                    let tight = &mut self.tights[id as usize];
                    let soft_ccd = parent.is_some_and(|rb| rb.soft_ccd_prediction() > 0.0);
                    let written = if soft_ccd {
                        Written::Unwritten
                    } else {
                        let prediction = params.prediction_distance() / 2.0;
                        crate::shape_box::written_box(collider, prediction)
                    };
                    match written {
                        // A ball's or cuboid's box, stored and tested straight from registers.
                        Written::Lanes(lanes) => {
                            lanes.write(tight);
                            !lanes.inside(&p.fat)
                        }
                        Written::Capsule(b) => {
                            *tight = Aabb::new(b.mins, b.maxs);
                            !p.fat.contains_branchless(tight)
                        }
                        // With soft CCD, or a box `written_box` does not give (having seen the
                        // shape already, parry's path then).
                        Written::Unwritten => {
                            let lanes = Self::collision_lanes(
                                params,
                                collider,
                                parent,
                                soft_ccd,
                                &mut self.stats.negative_loosening,
                            );
                            lanes.write(tight);
                            !lanes.inside(&p.fat)
                        }
                    }
                } else {
                    // Parry's path keeps its own code: routed through the `match` above,
                    // `spawn_storm` (mixed shapes) took about 3% longer (`tools/ab`).
                    let lanes = Self::collision_lanes(
                        params,
                        collider,
                        parent,
                        false,
                        &mut self.stats.negative_loosening,
                    );
                    lanes.write(&mut self.tights[id as usize]);
                    !lanes.inside(&p.fat)
                };
                return Examined::Fast {
                    parent,
                    filed: p.filter.body_type,
                    left,
                };
            }
        }
        self.examine_full(params, colliders, bodies, handle, margins, events);
        Examined::Full
    }

    /// Step 2 for every modified collider, in index order (the collider arena and the proxies
    /// are then read front to back, which the hardware prefetcher streams): `examine` each,
    /// compare the parent's body type of those on the fast path (at once, or with `DELAY`
    /// `BODY_TYPE_DELAY` colliders late, after a prefetch), and give the leavers their new
    /// fat boxes a chunk at a time. Returns whether some parent's body type changed
    /// (`check_body_types` then finds which).
    fn examine_all<const DELAY: bool>(
        &mut self,
        pass: &ExaminePass<'_>,
        events: &mut Vec<BroadPhasePairEvent>,
    ) -> bool {
        let ExaminePass {
            params,
            colliders,
            bodies,
            modified,
            generations,
            shape_queue,
            ahead,
            shapes_mixed,
            margins,
        } = *pass;
        let mut retyped = false;
        // This chunk's leavers (`REFATTEN_WORDS` words: at most 256 colliders) and their
        // parents: written for every collider, kept (`left`) for those that left.
        let mut leavers = [(0u32, None::<&RigidBody>); 64 * REFATTEN_WORDS];
        let mut leaving = 0;
        let mut delayed: [Option<(&RigidBody, RigidBodyType)>; BODY_TYPE_DELAY] =
            [None; BODY_TYPE_DELAY];
        let mut delay_at = 0;
        let mut shapes_ahead = shape_queue.get(SHAPE_AHEAD..).unwrap_or_default().iter();
        // One generation per bit of `modified` (so no index below is out of bounds).
        let generations = &generations[..modified.len() * 64];
        for (w, &word) in modified.iter().enumerate() {
            let mut word = word;
            while word != 0 {
                let bit = word.trailing_zeros() as usize;
                word &= word - 1;
                let index = w * 64 + bit;
                if let Some(&shape) = shapes_ahead.next() {
                    prefetch(shape as *const u8);
                }
                if let Some(ahead) = &ahead {
                    ahead.prefetch(index, &self.proxies);
                }
                let handle = ColliderHandle::from_raw_parts(index as u32, generations[index]);
                // The collision box's path is chosen once per update (`collision_aabb`).
                let examined = if shapes_mixed {
                    self.examine::<false>(params, colliders, bodies, handle, margins, events)
                } else {
                    self.examine::<true>(params, colliders, bodies, handle, margins, events)
                };
                let Examined::Fast {
                    parent,
                    filed,
                    left,
                } = examined
                else {
                    continue;
                };
                // No branch on `left` (see `examine`): fewer than 256 leavers so far in this
                // chunk of at most 256 colliders, so the modulo never changes the index.
                leavers[leaving % leavers.len()] = (index as u32, parent);
                leaving += left as usize;
                if let Some(rb) = parent {
                    // No branch on the body type, only an `|=`.
                    if !DELAY {
                        retyped |= rb.body_type() != filed;
                    } else {
                        prefetch_l2(body_last_byte(rb as *const RigidBody as usize));
                        if let Some((due, filed)) = delayed[delay_at].replace((rb, filed)) {
                            retyped |= due.body_type() != filed;
                        }
                        delay_at = (delay_at + 1) % BODY_TYPE_DELAY;
                    }
                }
            }
            if (w + 1) % REFATTEN_WORDS == 0 || w + 1 == modified.len() {
                // The chunk's leavers, while their collider and body are cached.
                for &(id, parent) in &leavers[..leaving] {
                    self.refatten(params, colliders, bodies, id, parent, margins, events);
                }
                leaving = 0;
            }
        }
        for (due, filed) in delayed.iter().flatten() {
            retyped |= due.body_type() != *filed;
        }
        retyped
    }

    /// Step 2, the fast path's last check, for updates where some collider's parent changed
    /// body type (rare; the fast path only notes that one did): every modified collider
    /// (`modified`, the bitmap of their indices, with their `generations`) whose proxy was
    /// filed under another body type than its parent's gets the full examination.
    #[allow(clippy::too_many_arguments)]
    fn check_body_types(
        &mut self,
        params: &IntegrationParameters,
        colliders: &ColliderSet,
        bodies: &RigidBodySet,
        modified: &[u64],
        generations: &[u32],
        margins: (f32, f32),
        events: &mut Vec<BroadPhasePairEvent>,
    ) {
        for index in SetBits::new(modified) {
            let handle = ColliderHandle::from_raw_parts(index, generations[index as usize]);
            let Some(rb) = colliders
                .get(handle)
                .and_then(|c| c.parent())
                .and_then(|h| bodies.get(h))
            else {
                continue;
            };
            // A collider with no proxy (disabled since it came, say) may have no entry at all.
            let retyped = self
                .proxies
                .get(index as usize)
                .and_then(Option::as_ref)
                .is_some_and(|p| p.is_for(handle) && p.filter.body_type != rb.body_type());
            if retyped {
                self.examine_full(params, colliders, bodies, handle, margins, events);
            }
        }
    }

    /// Step 2 for proxy `id` of the fast path, whose exact box left its fat box (`parent`: its
    /// collider's parent body, as the fast path found it): a new fat box in place, or the full
    /// examination when that box is not valid.
    #[allow(clippy::too_many_arguments)]
    fn refatten(
        &mut self,
        params: &IntegrationParameters,
        colliders: &ColliderSet,
        bodies: &RigidBodySet,
        id: u32,
        parent: Option<&RigidBody>,
        margins: (f32, f32),
        events: &mut Vec<BroadPhasePairEvent>,
    ) {
        let velocity_steps = self.config.velocity_steps;
        let fat = Self::fat_box(
            velocity_steps,
            &self.tights[id as usize],
            margins,
            params,
            parent,
        );
        let Some(p) = self.proxies[id as usize].as_mut() else {
            return;
        };
        if fat.is_valid() {
            // Unless the full examination moved it already (filter, tree), only its box changed.
            let place = &mut self.places[id as usize];
            place.box_only = !place.moved;
            let jumped = !fat.to_aabb().intersects(&p.fat);
            fat.write(&mut p.fat);
            self.trees[p.mobility() as usize].set_box(place.loc, p.fat, jumped);
            self.mark_moved(id);
        } else {
            let handle = p.handle(id);
            self.examine_full(params, colliders, bodies, handle, margins, events);
        }
    }

    /// Step 2 for one collider outside the fast path: new, stale, disabled, invalid, or with
    /// changed filter inputs or mobility.
    #[allow(clippy::too_many_arguments)]
    fn examine_full(
        &mut self,
        params: &IntegrationParameters,
        colliders: &ColliderSet,
        bodies: &RigidBodySet,
        handle: ColliderHandle,
        margins: (f32, f32),
        events: &mut Vec<BroadPhasePairEvent>,
    ) {
        let id = handle.into_raw_parts().0;
        let velocity_steps = self.config.velocity_steps;
        let Some(collider) = colliders.get(handle) else {
            return;
        };
        let parent = collider.parent().and_then(|h| bodies.get(h));
        let enabled = collider.is_enabled();

        if let Some(Some(p)) = self.proxies.get(id as usize) {
            if !p.is_for(handle) {
                // A stale proxy under a reused index (its removal was not reported).
                self.remove_proxy(id);
            }
        }
        if !enabled {
            // Disabled colliders also arrive in `removed`; make sure nothing is left.
            self.remove_proxy(id);
            return;
        }
        let tight = Self::collision_aabb(
            params,
            collider,
            parent,
            crate::shape_box::written_out_agrees(),
            &mut self.stats.negative_loosening,
        );
        let filter = FilterData::new(collider, parent);
        let mobility = Mobility::of(filter.body_type);
        let fat = Self::fat_box(velocity_steps, &tight, margins, params, parent).to_aabb();
        let valid = tight.is_valid() && fat.is_valid();

        if id as usize >= self.proxies.len() {
            self.proxies.resize_with(id as usize + 1, || None);
            self.places.resize(id as usize + 1, Place::default());
            self.tights.resize(id as usize + 1, Aabb::EMPTY);
            self.shape_hints.resize(id as usize + 1, 0);
            self.shape_kinds.resize(id as usize + 1, NO_KIND);
        }
        let existing = self.proxies[id as usize].take();
        let mut p = match existing {
            Some(p) => p,
            None => {
                if filter.active.contains(ActiveCollisionTypes::FIXED_FIXED) {
                    self.fixed_fixed += 1;
                }
                self.tights[id as usize] = tight;
                self.note_shape(id, collider);
                let p = Proxy {
                    generation: handle.into_raw_parts().1,
                    fat: if valid { fat } else { Aabb::EMPTY },
                    filter,
                };
                // A proxy removed earlier in this update may have left its flags here: its
                // `box_only` is not this one's; its `moved` stays, as the id is in the move
                // buffer already (which holds each id once).
                self.places[id as usize].box_only = false;
                if valid {
                    self.places[id as usize].loc =
                        self.trees[mobility as usize].insert(id, &filter);
                } else {
                    self.stats.invalid += 1;
                }
                self.proxies[id as usize] = Some(p);
                if valid {
                    self.mark_moved(id);
                }
                return;
            }
        };

        if !valid {
            if p.is_valid() {
                self.mirror.touch(id);
                self.take_out_of_tree(id, p.mobility());
                p.fat = Aabb::EMPTY;
                self.stats.invalid += 1;
                self.proxies[id as usize] = Some(p);
                self.drop_pairs(id, Some(events));
            } else {
                self.proxies[id as usize] = Some(p);
            }
            return;
        }

        self.tights[id as usize] = tight;
        self.note_shape(id, collider);
        // The tree it is in now: the filter below may change the body type it was filed under.
        let filed = p.mobility();
        let mut moved = false;
        if p.filter != filter {
            let had_ff = p.filter.active.contains(ActiveCollisionTypes::FIXED_FIXED);
            let has_ff = filter.active.contains(ActiveCollisionTypes::FIXED_FIXED);
            self.fixed_fixed = self.fixed_fixed + has_ff as usize - had_ff as usize;
            p.filter = filter;
            // A filter change can widen what the tree summary must cover.
            self.trees[mobility as usize].summary.add(&p.filter);
            moved = true;
        }
        if !p.is_valid() || filed != mobility {
            if p.is_valid() {
                self.take_out_of_tree(id, filed);
            } else {
                self.stats.invalid -= 1;
            }
            p.fat = fat;
            self.places[id as usize].loc = self.trees[mobility as usize].insert(id, &p.filter);
            moved = true;
        } else if !p.fat.contains(&tight) {
            let jumped = !p.fat.intersects(&fat);
            p.fat = fat;
            self.trees[mobility as usize].set_box(self.places[id as usize].loc, fat, jumped);
            moved = true;
        }
        if moved {
            self.places[id as usize].box_only = false;
        }
        self.proxies[id as usize] = Some(p);
        if moved {
            self.mark_moved(id);
        }
    }

    /// The collider pair of proxies `a` and `b`, smaller id first.
    fn collider_pair(&self, a: u32, b: u32) -> Option<ColliderPair> {
        let (a, b) = if a < b { (a, b) } else { (b, a) };
        match (&self.proxies[a as usize], &self.proxies[b as usize]) {
            (Some(pa), Some(pb)) => Some(ColliderPair::new(pa.handle(a), pb.handle(b))),
            _ => None,
        }
    }

    fn push_delete(&self, a: u32, b: u32, events: &mut Vec<BroadPhasePairEvent>) {
        if let Some(pair) = self.collider_pair(a, b) {
            events.push(BroadPhasePairEvent::DeletePair(pair));
        }
    }

    fn push_add(&self, a: u32, b: u32, events: &mut Vec<BroadPhasePairEvent>) {
        if let Some(pair) = self.collider_pair(a, b) {
            events.push(BroadPhasePairEvent::AddPair(pair));
        }
    }

    /// Sets the live flag of the candidate at edge `k` of the partner list of `a`
    /// (`PairSet::set_live_at`) and, when the flag changed, reports it: `AddPair` for a pair
    /// gone live, `DeletePair` for one waiting again.
    fn set_live_reported(
        &mut self,
        a: u32,
        k: u32,
        live: bool,
        events: &mut Vec<BroadPhasePairEvent>,
    ) {
        if self.pairs.set_live_at(a, k as usize, live) == live {
            return;
        }
        let b = self.pairs.partners(a)[k as usize].other;
        if live {
            self.push_add(a, b, events);
        } else {
            self.push_delete(a, b, events);
        }
    }

    /// Step 5 for the pending proxies (not in a BVH yet): against BVH members, a marked walk of
    /// each pending tree against each member tree (pairs where either side moved); among
    /// themselves, one sweep along x.
    fn pending_pairs(&self, marks: &[Option<PairMarks>; 3], out: &mut Vec<(u32, u32)>) {
        let mut pending: Vec<(f32, u32)> = Vec::new();
        for t in &self.trees {
            for &id in &t.pending {
                if let Some(p) = &self.proxies[id as usize] {
                    pending.push((p.fat.min.x, id));
                }
            }
        }
        if pending.is_empty() {
            return;
        }
        for a in Mobility::ALL {
            let ta = &self.trees[a as usize];
            if ta.pending.is_empty() {
                continue;
            }
            let Some(pending_bvh) = ta.pending_bvh() else {
                // No pending tree (a list short enough to scan, `SCANNED_PENDING`, or a build
                // that failed, which valid fat boxes never make happen): one query per pending
                // proxy instead.
                for &id in &ta.pending {
                    let Some(p) = &self.proxies[id as usize] else {
                        continue;
                    };
                    for b in Mobility::ALL {
                        let tb = &self.trees[b as usize];
                        if tb.members.is_empty() || !self.may_query(p, b) {
                            continue;
                        }
                        tb.query_members(&p.fat, |other| {
                            if let Some(o) = &self.proxies[other as usize] {
                                if p.filter.may_pair(&o.filter) {
                                    out.push((id, other));
                                }
                            }
                        });
                    }
                }
                continue;
            };
            let pending_marks =
                pending_bvh.marks(|i| self.places[ta.pending[i as usize] as usize].moved);
            for b in Mobility::ALL {
                let tb = &self.trees[b as usize];
                if tb.members.is_empty() || !self.trees_may_pair(a, b) {
                    continue;
                }
                let member_marks = marks[b as usize].as_ref().unwrap_or_else(|| tb.no_marks());
                pending_bvh.pairs_with_marked(&pending_marks, &tb.bvh, member_marks, |i, j| {
                    let (id, other) = (ta.pending[i as usize], tb.members[j as usize]);
                    if other == DEAD {
                        return;
                    }
                    if let (Some(p), Some(o)) =
                        (&self.proxies[id as usize], &self.proxies[other as usize])
                    {
                        if p.filter.may_pair(&o.filter) {
                            out.push((id, other));
                        }
                    }
                });
            }
        }
        // Sweep and prune: sorted by min x (ties by id, for a deterministic order), each box
        // meets the boxes that start before it ends.
        pending.sort_unstable_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        for (i, &(_, a)) in pending.iter().enumerate() {
            let Some(pa) = &self.proxies[a as usize] else {
                continue;
            };
            for &(min_x, b) in &pending[i + 1..] {
                if min_x > pa.fat.max.x {
                    break;
                }
                let Some(pb) = &self.proxies[b as usize] else {
                    continue;
                };
                // `may_pair` also rules out fixed-fixed pairs unless a collider enables them.
                if pa.fat.intersects(&pb.fat) && pa.filter.may_pair(&pb.filter) {
                    out.push((a, b));
                }
            }
        }
    }

    /// Steps 4 and 5 for a moved proxy when few moved: its partners among every proxy (BVH
    /// members and pending ones), found by a query on every tree it may pair with. Of two
    /// moved proxies, the one with the smaller id reports a new pair (`out`). Its candidates
    /// the queries did not meet ended (`gone`), as did those the filter now rejects (checked
    /// only when more than its box changed: a filter change moves both sides, and the side
    /// whose filter changed checks). `seen` is scratch space.
    fn moved_pairs(
        &self,
        id: u32,
        seen: &mut KnownMarks,
        gone: &mut Vec<(u32, u32)>,
        out: &mut Vec<(u32, u32)>,
    ) {
        let Some(p) = self.proxies[id as usize].as_ref().filter(|p| p.is_valid()) else {
            // Out of the trees: its candidates were dropped when its box became invalid.
            return;
        };
        // Its current candidates are met again: its partners are marked (`KnownMarks`) and
        // each hit is recognised by one bit test, not a scan of the list, whose varying
        // length mispredicted (`spawn_storm` 1.021 old / new in `tools/ab`); every other pair
        // it reports is new (`PairSet::insert_new`).
        let known = self.pairs.partners(id);
        seen.mark(known.iter().map(|e| e.other));
        for m in Mobility::ALL {
            let tree = &self.trees[m as usize];
            if tree.len() == 0 || !self.may_query(p, m) {
                continue;
            }
            tree.for_each_overlap(&self.proxies, &p.fat, |other| {
                if other == id {
                    return;
                }
                if seen.meet(other) {
                    return;
                }
                let Some(o) = &self.proxies[other as usize] else {
                    return;
                };
                if self.places[other as usize].moved && other < id {
                    return;
                }
                if p.filter.may_pair(&o.filter) {
                    out.push((id, other));
                }
            });
        }
        for e in known {
            let met = seen.take(e.other);
            let ended = !met
                || (!self.places[id as usize].box_only
                    && self.proxies[e.other as usize]
                        .as_ref()
                        .is_none_or(|o| !p.filter.may_pair(&o.filter)));
            if ended {
                gone.push((id, e.other));
            }
        }
    }

    /// Asks for the partner lists of both ends of `pairs[k + PREFETCH_AHEAD]` (their heads) and
    /// of `pairs[k + PREFETCH_AHEAD / 2]` (the lists), before the pair-set edits reach them.
    #[inline]
    fn prefetch_pair_lists(&self, pairs: &[IdPair], k: usize) {
        if let Some(&(a, b)) = pairs.get(k + PREFETCH_AHEAD) {
            self.pairs.prefetch_list_head(a);
            self.pairs.prefetch_list_head(b);
        }
        if let Some(&(a, b)) = pairs.get(k + PREFETCH_AHEAD / 2) {
            self.pairs.prefetch_list(a);
            self.pairs.prefetch_list(b);
        }
    }

    /// `prefetch_pair_lists` for a list of proxy ids: the list heads of `ids[k + PREFETCH_AHEAD]`
    /// and the lists of `ids[k + PREFETCH_AHEAD / 2]`.
    #[inline]
    fn prefetch_id_lists(&self, ids: &[u32], k: usize) {
        if let Some(&ahead) = ids.get(k + PREFETCH_AHEAD) {
            self.pairs.prefetch_list_head(ahead);
        }
        if let Some(&near) = ids.get(k + PREFETCH_AHEAD / 2) {
            self.pairs.prefetch_list(near);
        }
    }

    /// `false` when no collider of tree `m` can pair with `p`.
    fn may_query(&self, p: &Proxy, m: Mobility) -> bool {
        if m == Mobility::Fixed && p.mobility() == Mobility::Fixed && self.fixed_fixed == 0 {
            return false;
        }
        self.trees[m as usize].summary.may_pair_with(&p.filter)
    }

    /// `false` when no collider of tree `a` can pair with one of tree `b`.
    fn trees_may_pair(&self, a: Mobility, b: Mobility) -> bool {
        if a == Mobility::Fixed && b == Mobility::Fixed && self.fixed_fixed == 0 {
            return false;
        }
        let (ta, tb) = (&self.trees[a as usize], &self.trees[b as usize]);
        ta.len() > 0 && tb.len() > 0 && ta.summary.may_pair_with_tree(&tb.summary)
    }

    /// Step 5, last: the live pairs of the moved proxies whose exact boxes are now more than
    /// twice the live-pair skin apart end (`DeletePair`) and wait again as candidates (see
    /// `CanopyBroadPhaseConfig::live_pair_skin`). A pair of two moved proxies is looked at from
    /// both sides and ends once.
    fn end_parted_live_pairs(
        &mut self,
        moved: &[u32],
        params: &IntegrationParameters,
        events: &mut Vec<BroadPhasePairEvent>,
    ) {
        // Boxes that do not meet once one of them is loosened by both skins are apart by more
        // than that; loosening only by a non-negative amount, no pair whose exact boxes
        // overlap ever ends here (nor with a skin so large that the loosening overflows).
        let gap = 2.0 * self.config.live_pair_skin * params.length_unit;
        if !(0.0..f32::MAX).contains(&gap) {
            // A NaN or negative length unit, or a skin that keeps pairs as long as candidates.
            return;
        }
        // `(id, k)`: edge `k` of the partner list of `id`.
        let mut parted = std::mem::take(&mut self.scratch.parted);
        for &id in moved {
            // Most moved proxies of a falling grid have no live pair: their lists, allocated
            // apart, are not read.
            if !self.pairs.has_live(id) {
                continue;
            }
            let reach = self.tights[id as usize].loosened(gap);
            for (k, e) in self.pairs.partners(id).iter().enumerate() {
                if e.live() && !reach.intersects(&self.tights[e.other as usize]) {
                    parted.push((id, k as u32));
                }
            }
        }
        for &(a, k) in &parted {
            self.set_live_reported(a, k, false, events);
        }
        parted.clear();
        self.scratch.parted = parted;
    }

    /// Step 6: the waiting candidates (not live yet) of the colliders Rapier reported
    /// (`modified`, a bitmap of their indices, `count` of them) whose exact boxes now overlap.
    /// Either every waiting candidate is checked, in the flat list's order, or each reported
    /// proxy's, in index order: whichever reads less, by an estimate (each reported proxy's
    /// lookup, plus its share of the waiting candidates, two ends each). Both give the same
    /// pairs (see step 6 in `update`), each into `flips` as a proxy id and the index of the
    /// pair's edge in its partner list (for `PairSet::set_live_at`).
    fn liveness_flips(&self, modified: &[u64], count: usize, flips: &mut Vec<(u32, u32)>) {
        let waiting = self.pairs.waiting_list();
        if waiting.is_empty() {
            return;
        }
        // A slice, not the `Vec`: its pointer and length stay in registers through the loop
        // (read through the `Vec`, they were loaded again for every pair).
        let tights: &[Aabb] = &self.tights;
        let proxies = self.proxies.len().max(1);
        let per_proxy_reads = count + 2 * waiting.len() * count.min(proxies) / proxies;
        if waiting.len() <= per_proxy_reads {
            for (&k, &edge) in waiting.iter().zip(self.pairs.waiting_edges()) {
                let (a, b) = unkey(k);
                // Without early exits: a partial overlap along one axis is common among
                // waiting candidates, and each early exit mispredicted (spawn_storm: ~3%).
                if tights[a as usize].intersects_branchless(&tights[b as usize]) {
                    flips.push((a, edge));
                }
            }
            return;
        }
        let reported = |id: u32| has_bit(modified, id);
        for id in SetBits::new(modified) {
            if self.pairs.waiting(id) == 0 {
                continue;
            }
            let tight = &tights[id as usize];
            for (k, e) in self.pairs.partners(id).iter().enumerate() {
                // A pair of two reported colliders is checked once, from its smaller id.
                if e.live() || (e.other < id && reported(e.other)) {
                    continue;
                }
                if tight.intersects_branchless(&tights[e.other as usize]) {
                    flips.push((id, k as u32));
                }
            }
        }
    }

    /// Steps 4 and 5: the candidates of moved proxies that ended, and every new candidate pair
    /// of a moved proxy. With few moves, one query per moved proxy finds both; otherwise the
    /// tree members that moved are marked and found by one marked pair walk per pair of trees,
    /// and the pending proxies' trees are walked against the member trees; the candidates of
    /// moved proxies that no walk met ended.
    fn find_changed_pairs(&mut self, moved: &[u32]) -> (Vec<IdPair>, Vec<IdPair>) {
        let members: usize = self.trees.iter().map(|t| t.members.len()).sum();
        let mut found = std::mem::take(&mut self.scratch.found);
        let mut gone = std::mem::take(&mut self.scratch.gone);
        self.stats.walked = moved.len() * SPARSE_MOVES >= members;
        if !self.stats.walked {
            // Few moved: one query each beats any pass over whole trees.
            let mut seen = std::mem::take(&mut self.scratch.seen);
            seen.fit(self.proxies.len());
            for (k, &id) in moved.iter().enumerate() {
                // Records and partner lists a few moved proxies ahead (`PREFETCH_AHEAD`): the
                // query and the check of known partners then do not wait for them.
                if let Some(&ahead) = moved.get(k + PREFETCH_AHEAD) {
                    prefetch(self.proxies.as_ptr().wrapping_add(ahead as usize));
                }
                self.prefetch_id_lists(moved, k);
                self.moved_pairs(id, &mut seen, &mut gone, &mut found);
            }
            self.scratch.seen = seen;
            return (gone, found);
        }
        // Which proxies moved, as a bitmap (a few KB, cached) rather than their records.
        let mut moved_bits = std::mem::take(&mut self.scratch.moved_bits);
        moved_bits.clear();
        moved_bits.resize(self.proxies.len().div_ceil(64), 0);
        for &id in moved {
            moved_bits[id as usize / 64] |= 1 << (id % 64);
        }
        // Every moved member's tree was noted (by `mark_moved`, or by step 3's rebuilds).
        debug_assert!(moved.iter().all(|&id| {
            let p = self.proxies[id as usize].as_ref();
            p.is_none_or(|p| {
                !matches!(self.places[id as usize].loc, Loc::Tree(_))
                    || self.moved_members[p.mobility() as usize]
            })
        }));
        let marks = self.member_marks(&moved_bits);
        self.walk_members(&marks, &mut found);
        self.pending_pairs(&marks, &mut found);
        // The walks met every candidate of a moved proxy that goes on (fat boxes overlapping,
        // filter passing): those are marked met on the moved side, and the moved proxies'
        // other candidates ended. Only the pairs that are not candidates yet stay in `found`.
        let is_moved = |id: u32| has_bit(&moved_bits, id);
        // Both ends' partner lists asked for a few pairs ahead (`prefetch_pair_lists`): the
        // walks' pairs come in tree order, their proxies' lists scattered.
        let mut kept = 0;
        for k in 0..found.len() {
            self.prefetch_pair_lists(&found, k);
            let (a, b) = found[k];
            if !self.pairs.mark_met(a, b, is_moved(a), is_moved(b)) {
                found[kept] = (a, b);
                kept += 1;
            }
        }
        found.truncate(kept);
        self.scratch.moved_bits = moved_bits;
        // Every marked list is read here (`moved` holds each id once: `mark_moved`), each asked
        // for a few proxies ahead; with no candidate at all, there is none to read.
        if self.pairs.candidate_len() > 0 {
            for (k, &id) in moved.iter().enumerate() {
                self.prefetch_id_lists(moved, k);
                self.pairs.take_unmet(id, &mut gone);
            }
        }
        (gone, found)
    }

    /// Marks of the moved BVH members (`moved_bits`: the moved proxy ids), per tree (`None`:
    /// none of its members moved, or no tree may pair with it, so that no walk reads them).
    /// Read through the slots' proxy ids, not the moved proxies' records, which are scattered.
    fn member_marks(&self, moved_bits: &[u64]) -> [Option<PairMarks>; 3] {
        std::array::from_fn(|i| {
            // `many_kinematics`: 27,000 kinematic colliders and no other tree; marking the
            // 21,000 to 24,000 that leave their boxes together took 230 to 550 µs for nothing.
            let m = Mobility::ALL[i];
            let walked = Mobility::ALL
                .iter()
                .any(|&o| self.trees_may_pair(m, o) || self.trees_may_pair(o, m));
            (self.moved_members[i] && walked).then(|| {
                let t = &self.trees[i];
                t.bvh.marks(|slot| {
                    let id = t.members[slot as usize];
                    id != DEAD && has_bit(moved_bits, id)
                })
            })
        })
    }

    /// One marked pair walk per pair of trees that may pair: every pair of BVH members with a
    /// moved one.
    fn walk_members(&self, marks: &[Option<PairMarks>; 3], found: &mut Vec<(u32, u32)>) {
        let parallel = self.config.parallel;
        use Mobility::*;
        for (a, b) in [
            (Dynamic, Dynamic),
            (Dynamic, Kinematic),
            (Dynamic, Fixed),
            (Kinematic, Kinematic),
            (Kinematic, Fixed),
            (Fixed, Fixed),
        ] {
            let (ia, ib) = (a as usize, b as usize);
            if (marks[ia].is_none() && marks[ib].is_none()) || !self.trees_may_pair(a, b) {
                continue;
            }
            let (ta, tb) = (&self.trees[ia], &self.trees[ib]);
            let ma = marks[ia].as_ref().unwrap_or_else(|| ta.no_marks());
            let mb = marks[ib].as_ref().unwrap_or_else(|| tb.no_marks());
            let mut keep = |x: u32, y: u32| {
                let (px, py) = (ta.members[x as usize], tb.members[y as usize]);
                if px == DEAD || py == DEAD {
                    return;
                }
                let (Some(p), Some(q)) = (&self.proxies[px as usize], &self.proxies[py as usize])
                else {
                    return;
                };
                if p.filter.may_pair(&q.filter) {
                    found.push((px, py));
                }
            };
            match (a == b, parallel) {
                (true, true) => ta
                    .bvh
                    .par_self_pairs_marked(ma)
                    .into_iter()
                    .for_each(|(x, y)| keep(x, y)),
                (true, false) => ta.bvh.self_pairs_marked(ma, &mut keep),
                (false, true) => ta
                    .bvh
                    .par_pairs_with_marked(ma, &tb.bvh, mb)
                    .into_iter()
                    .for_each(|(x, y)| keep(x, y)),
                (false, false) => ta.bvh.pairs_with_marked(ma, &tb.bvh, mb, &mut keep),
            }
        }
    }
}

impl BroadPhase for CanopyBroadPhase {
    fn update(
        &mut self,
        params: &IntegrationParameters,
        colliders: &ColliderSet,
        bodies: &RigidBodySet,
        modified_colliders: &[ColliderHandle],
        removed_colliders: &[ColliderHandle],
        events: &mut Vec<BroadPhasePairEvent>,
    ) {
        let events_before = events.len();
        // This update sees every edit the overlay recorded (Rapier reports them as modified
        // or removed); the mirror re-reads those proxies after it.
        if !self.overlay.is_empty() {
            let affected = self.overlay.clear();
            self.mirror.touch_all(&affected);
        }
        if modified_colliders.is_empty() && removed_colliders.is_empty() {
            // Nothing changed, so no pair can start or end.
            self.stats.moved = 0;
            self.stats.walked = false;
            self.stats.added = 0;
            self.stats.deleted = 0;
            self.stats.negative_loosening = 0;
            return;
        }
        #[cfg(feature = "phase-times")]
        let mut clock = crate::phase_times::Clock::start();
        // 1. Removals first, each proxy's partner list asked for a few removals ahead.
        for (k, &handle) in removed_colliders.iter().enumerate() {
            if let Some(ahead) = removed_colliders.get(k + PREFETCH_AHEAD) {
                self.pairs.prefetch_list_head(ahead.into_raw_parts().0);
            }
            if let Some(near) = removed_colliders.get(k + PREFETCH_AHEAD / 2) {
                self.pairs.prefetch_list(near.into_raw_parts().0);
            }
            if self.proxy(handle).is_some() {
                self.remove_proxy(handle.into_raw_parts().0);
            }
        }

        lap!(self, clock, removals);
        // 2. Re-examine every modified collider.
        // A negative or NaN `length_unit` gives margins of 0: smaller fat boxes would lose pairs.
        let margins = (
            (self.config.margin * params.length_unit).max(0.0),
            (self.config.fixed_margin * params.length_unit).max(0.0),
        );
        // Counted afresh by this update's examinations (`collision_aabb`).
        self.stats.negative_loosening = 0;
        // In handle order (a bitmap of the modified indices, read back in order): the collider
        // arena and the proxies are then read front to back, which the hardware prefetcher
        // turns into streaming instead of one cache miss per collider.
        let (mut bits, mut generations) = std::mem::take(&mut self.scratch_order);
        mark_modified(&mut bits, &mut generations, modified_colliders, colliders);
        // The bitmap stays set until step 6 has read it. Where shapes are scattered over the
        // heap, the loop asks for the shape `SHAPE_AHEAD` colliders ahead (`shape_queue`: the
        // modified colliders' shape hints, in the loop's order).
        let mut shape_queue = std::mem::take(&mut self.shape_queue);
        shape_queue.clear();
        if self.shape_checks % SHAPE_CHECK_INTERVAL == 0 {
            self.shapes_scattered = self.shapes_look_scattered();
            self.shapes_mixed = self.shapes_look_mixed();
        }
        self.shape_checks = self.shape_checks.wrapping_add(1);
        if self.shapes_scattered {
            let hints = &self.shape_hints;
            shape_queue
                .extend(SetBits::new(&bits).map(|i| hints.get(i as usize).copied().unwrap_or(0)));
        }
        let shapes_mixed = self.shapes_mixed || !crate::shape_box::written_out_agrees();
        let body_bytes = bodies
            .len()
            .saturating_mul(std::mem::size_of::<RigidBody>());
        let set_bytes = colliders
            .len()
            .saturating_mul(std::mem::size_of::<Collider>())
            .saturating_add(body_bytes);
        let ahead = if modified_colliders.len().saturating_mul(DENSE_EXAMINE) >= colliders.len()
            && set_bytes >= AHEAD_MIN_BYTES
        {
            ExamineAhead::learn(colliders, bodies, SetBits::new(&bits), |i| {
                ColliderHandle::from_raw_parts(i, generations[i as usize])
            })
        } else {
            None
        };
        let pass = ExaminePass {
            params,
            colliders,
            bodies,
            modified: &bits,
            generations: &generations,
            shape_queue: &shape_queue,
            ahead,
            shapes_mixed,
            margins,
        };
        let retyped = if body_bytes > DELAYED_BODY_BYTES || self.delay_body_types {
            self.examine_all::<true>(&pass, events)
        } else {
            self.examine_all::<false>(&pass, events)
        };
        if retyped {
            self.check_body_types(
                params,
                colliders,
                bodies,
                &bits,
                &generations,
                margins,
                events,
            );
        }
        self.shape_queue = shape_queue;

        lap!(self, clock, examine);
        // 3. Trees.
        let policy = self.config.rebuild;
        for m in Mobility::ALL {
            let (builder, max_leaf_size) = if m == Mobility::Fixed {
                (policy.fixed_builder, BuildOptions::default().max_leaf_size)
            } else {
                (policy.moving_builder, MOVING_LEAF_SIZE)
            };
            let build = BuildOptions {
                builder,
                max_leaf_size,
                parallel: self.config.parallel,
                ..Default::default()
            };
            let rebuilds = self.trees[m as usize].rebuilds;
            self.trees[m as usize].maintain(&self.proxies, &mut self.places, &policy, build);
            if self.trees[m as usize].rebuilds != rebuilds {
                // The pending proxies are members now.
                self.moved_members[m as usize] |= self.moved_pending[m as usize];
            }
        }

        lap!(self, clock, trees);
        // 4. Candidates of moved proxies that ended (fat boxes apart, or the filter now rejects
        //    them), and 5. new candidates, live at once when their exact boxes overlap. The
        //    candidates that end are all dropped before any new one is added.
        let moved = std::mem::take(&mut self.moved);
        let (mut gone, mut found) = self.find_changed_pairs(&moved);
        lap!(self, clock, search);
        // Both ends' partner lists (and, for new pairs, exact boxes) are asked for a few pairs
        // ahead: the pairs' proxies are scattered over the arrays.
        for (k, &(a, b)) in gone.iter().enumerate() {
            self.prefetch_pair_lists(&gone, k);
            if self.pairs.remove(a, b) == Some(true) {
                self.push_delete(a, b, events);
            }
        }
        for (k, &(a, b)) in found.iter().enumerate() {
            self.prefetch_pair_lists(&found, k);
            if let Some(&(x, y)) = found.get(k + PREFETCH_AHEAD) {
                prefetch(self.tights.as_ptr().wrapping_add(x as usize));
                prefetch(self.tights.as_ptr().wrapping_add(y as usize));
            }
            // Every pair found is new (see `PairSet::insert_new`).
            let live = self.tights[a as usize].intersects(&self.tights[b as usize]);
            self.pairs.insert_new(a, b, live);
            if live {
                self.push_add(a, b, events);
            }
        }
        gone.clear();
        found.clear();
        (self.scratch.gone, self.scratch.found) = (gone, found);

        self.end_parted_live_pairs(&moved, params, events);
        lap!(self, clock, pair_edits);
        // 6. Liveness: every collider Rapier reported re-checks its candidates that are not live
        //    yet (new candidates were checked above). Live pairs end with their candidate, or
        //    in step 5 when their exact boxes part.
        //    A waiting candidate neither of whose colliders was reported kept both boxes, so it
        //    still does not overlap: checking it too changes nothing. So when the reported
        //    colliders hold most waiting candidates, the flat list of waiting candidates is
        //    read front to back; otherwise each reported collider's partner list is.
        let mut flips = std::mem::take(&mut self.scratch.flips);
        self.liveness_flips(&bits, modified_colliders.len(), &mut flips);
        bits.fill(0);
        self.scratch_order = (bits, generations);
        for &(a, k) in &flips {
            self.set_live_reported(a, k, true, events);
        }
        flips.clear();
        self.scratch.flips = flips;
        lap!(self, clock, liveness);
        let added = events[events_before..]
            .iter()
            .filter(|e| matches!(e, BroadPhasePairEvent::AddPair(_)))
            .count();
        let deleted = events.len() - events_before - added;

        for (k, &id) in moved.iter().enumerate() {
            if let Some(&ahead) = moved.get(k + PREFETCH_AHEAD) {
                prefetch(self.places.as_ptr().wrapping_add(ahead as usize));
            }
            let place = &mut self.places[id as usize];
            place.moved = false;
            place.box_only = false;
        }
        self.moved_members = [false; 3];
        self.moved_pending = [false; 3];
        self.stats.moved = moved.len();
        self.stats.deleted = deleted;
        self.stats.added = added;
        self.moved = moved;
        self.moved.clear();
        lap!(self, clock, finish);
        #[cfg(feature = "phase-times")]
        {
            self.phase_times.updates += 1;
            self.phase_times.moved += self.stats.moved as u64;
        }
    }
}

/// For tests (here and in `arena_ahead.rs`): a row of `n` balls of radius 0.6 one unit apart
/// along x (each overlapping its two neighbours), each on a body of type `body_type`: the sets
/// and the bodies in row order.
#[cfg(test)]
pub(crate) fn ball_row(
    n: usize,
    body_type: RigidBodyType,
) -> (RigidBodySet, ColliderSet, Vec<RigidBodyHandle>) {
    let mut bodies = RigidBodySet::new();
    let mut colliders = ColliderSet::new();
    let handles = (0..n)
        .map(|i| {
            let body = RigidBodyBuilder::new(body_type).translation(vector![i as f32, 0.0, 0.0]);
            let b = bodies.insert(body);
            colliders.insert_with_parent(ColliderBuilder::ball(0.6), b, &mut bodies);
            b
        })
        .collect();
    (bodies, colliders, handles)
}

#[cfg(test)]
mod tests {
    use super::*;
    use canopy_scenes::harness::record;
    use canopy_scenes::{spawn_storm, Size};
    use proptest::prelude::*;

    proptest! {
        #[test]
        fn set_bits_yields_every_set_bit_in_order(words in prop::collection::vec(any::<u64>(), 0..6)) {
            let naive: Vec<u32> = (0..words.len() as u32 * 64)
                .filter(|&i| words[i as usize / 64] & (1 << (i % 64)) != 0)
                .collect();
            prop_assert_eq!(SetBits::new(&words).collect::<Vec<_>>(), naive);
        }

        /// `KnownMarks`: after marking a set of partners and meeting any ids (marked or not,
        /// repeated or not), `take` says met for exactly the marked ids that were met, and
        /// leaves every bit clear for the next query.
        #[test]
        fn known_marks_meet_exactly_the_marked_ids(
            known in prop::collection::btree_set(0u32..300, 0..20),
            hits in prop::collection::vec(0u32..300, 0..40),
        ) {
            let mut marks = KnownMarks::default();
            marks.fit(300);
            for _ in 0..2 {
                marks.mark(known.iter().copied());
                for &h in &hits {
                    prop_assert_eq!(marks.meet(h), known.contains(&h));
                }
                for &k in &known {
                    prop_assert_eq!(marks.take(k), hits.contains(&k));
                }
                prop_assert!(marks.known.iter().chain(&marks.met).all(|&w| w == 0));
            }
        }

        /// `mark_modified` sets exactly the listed indices, each with its first listed
        /// generation when no collider is live there (an empty set: the first stays), over
        /// bitmaps left from an earlier update, in any order and with repeats.
        #[test]
        fn mark_modified_sets_every_listed_index(
            handles in prop::collection::vec((0u32..300, 0u32..3), 0..200),
            sorted in any::<bool>(),
            earlier in prop::collection::vec(0u32..300, 0..20),
        ) {
            let mut handles = handles;
            if sorted {
                handles.sort();
            }
            let listed: Vec<ColliderHandle> = handles
                .iter()
                .map(|&(i, g)| ColliderHandle::from_raw_parts(i, g))
                .collect();
            let colliders = ColliderSet::new();
            let (mut bits, mut generations) = (Vec::new(), Vec::new());
            // An earlier update's bitmap, read and cleared as `update` does.
            let before: Vec<ColliderHandle> =
                earlier.iter().map(|&i| ColliderHandle::from_raw_parts(i, 7)).collect();
            mark_modified(&mut bits, &mut generations, &before, &colliders);
            bits.fill(0);
            mark_modified(&mut bits, &mut generations, &listed, &colliders);
            prop_assert_eq!(generations.len(), bits.len() * 64);
            let mut want = std::collections::BTreeMap::new();
            for &(i, g) in &handles {
                want.entry(i).or_insert(g);
            }
            let got: Vec<u32> = SetBits::new(&bits).collect();
            prop_assert_eq!(&got, &want.keys().copied().collect::<Vec<_>>());
            for (&i, &g) in &want {
                prop_assert_eq!(generations[i as usize], g);
            }
        }
    }

    /// Every non-empty update is counted, with its moved proxies, and taking the times resets
    /// them.
    #[cfg(feature = "phase-times")]
    #[test]
    fn phase_times_count_every_update() {
        let updates = record(spawn_storm(Size::Small), 20);
        let mut bp = CanopyBroadPhase::new();
        let (mut counted, mut moved) = (0, 0);
        for u in &updates {
            u.apply(&mut bp, &mut Vec::new());
            if !u.modified.is_empty() || !u.removed.is_empty() {
                counted += 1;
                moved += bp.stats().moved as u64;
            }
        }
        let t = bp.take_phase_times();
        assert_eq!((t.updates, t.moved), (counted, moved));
        assert!(counted > 0 && t.total() > std::time::Duration::ZERO);
        assert_eq!(bp.take_phase_times(), crate::PhaseTimes::default());
    }

    /// The two paths of the collision box (`shape_box::collision_box`, parry's virtual
    /// `compute_aabb`) give the same events and the same exact boxes, update by update, on a
    /// scene of balls, cuboids and capsules (`spawn_storm`, whose mix `shapes_look_mixed`
    /// tells apart from scenes of one shape).
    #[test]
    fn both_collision_box_paths_agree() {
        let updates = record(spawn_storm(Size::Small), 60);
        let (mut written, mut virtual_call) = (CanopyBroadPhase::new(), CanopyBroadPhase::new());
        let (mut a, mut b) = (Vec::new(), Vec::new());
        let mut events = 0;
        for (k, u) in updates.iter().enumerate() {
            // A count that is no multiple of the interval: the flags stay as set here.
            for (bp, mixed) in [(&mut written, false), (&mut virtual_call, true)] {
                bp.shapes_mixed = mixed;
                bp.shape_checks = 1;
            }
            a.clear();
            b.clear();
            u.apply(&mut written, &mut a);
            u.apply(&mut virtual_call, &mut b);
            assert_eq!(plain(&a), plain(&b), "update {k}");
            let bits = |bp: &CanopyBroadPhase| -> Vec<[u32; 6]> {
                bp.tights
                    .iter()
                    .map(|t| {
                        [t.min.x, t.min.y, t.min.z, t.max.x, t.max.y, t.max.z].map(f32::to_bits)
                    })
                    .collect()
            };
            assert_eq!(bits(&written), bits(&virtual_call), "update {k}");
            events += a.len();
        }
        assert!(events > 0);
        assert!(virtual_call.shapes_look_mixed());
    }

    /// Body types compared at once and compared late (`BODY_TYPE_DELAY`, after a prefetch)
    /// give the same events, update by update, on a churning scene, and both see body type
    /// changes anywhere in an update: the first collider examined, one in the middle, and ones
    /// among the last `BODY_TYPE_DELAY` (compared after the loop on the late path).
    #[test]
    fn body_types_compared_at_once_or_late_agree() {
        let updates = record(spawn_storm(Size::Small), 40);
        let (mut at_once, mut late) = (CanopyBroadPhase::new(), CanopyBroadPhase::new());
        late.delay_body_types = true;
        let (mut a, mut b) = (Vec::new(), Vec::new());
        for (k, u) in updates.iter().enumerate() {
            a.clear();
            b.clear();
            u.apply(&mut at_once, &mut a);
            u.apply(&mut late, &mut b);
            assert_eq!(plain(&a), plain(&b), "update {k}");
        }

        // A row of fixed balls, each overlapping its neighbours (fixed-fixed pairs are
        // filtered out); some become dynamic and must pair with their neighbours.
        let (bodies, colliders, handles) = ball_row(100, RigidBodyType::Fixed);
        let all: Vec<ColliderHandle> = colliders.iter().map(|(h, _)| h).collect();
        let params = IntegrationParameters::default();
        for delay in [false, true] {
            let mut bp = CanopyBroadPhase::new();
            bp.delay_body_types = delay;
            let mut bodies = bodies.clone();
            bp.update(&params, &colliders, &bodies, &all, &[], &mut Vec::new());
            assert_eq!(bp.stats().pairs, 0);
            // One change per update, so that no other change raises the update's flag.
            let mut expected = Vec::new();
            for i in [0u32, 50, 90, 97, 99] {
                bodies[handles[i as usize]].set_body_type(RigidBodyType::Dynamic, true);
                bp.update(&params, &colliders, &bodies, &all, &[], &mut Vec::new());
                // With its one or two neighbours, once per pair (97 and 99 share 98).
                for n in [i.wrapping_sub(1), i + 1].into_iter().filter(|&n| n < 100) {
                    let pair = (i.min(n), i.max(n));
                    if !expected.contains(&pair) {
                        expected.push(pair);
                    }
                }
                expected.sort_unstable();
                let mut pairs: Vec<(u32, u32)> = bp
                    .pairs()
                    .map(|(x, y)| {
                        let (x, y) = (x.into_raw_parts().0, y.into_raw_parts().0);
                        (x.min(y), x.max(y))
                    })
                    .collect();
                pairs.sort_unstable();
                assert_eq!(pairs, expected, "delay {delay}, body {i}");
            }
        }
    }

    /// The first disagreement between the proxy records and their places (`proxy.rs`): a
    /// proxy is in a tree exactly when its record is valid, in the tree of its body type, at
    /// the slot or pending index that holds its id there; every live tree slot and pending
    /// entry points back at such a proxy; no flag outlives an update.
    fn places_disagree(bp: &CanopyBroadPhase) -> Option<String> {
        for (id, place) in bp.places.iter().enumerate() {
            let p = bp.proxies.get(id).and_then(Option::as_ref);
            if place.moved || place.box_only {
                return Some(format!("{id}: flags left set"));
            }
            let tree = match (p, place.loc) {
                (None, Loc::Out) => continue,
                (Some(p), Loc::Out) if !p.is_valid() => continue,
                (Some(p), _) if p.is_valid() => &bp.trees[p.mobility() as usize],
                _ => return Some(format!("{id}: {:?} with {:?}", place.loc, p.map(|p| p.fat))),
            };
            let holds = match place.loc {
                Loc::Tree(slot) => tree.members.get(slot as usize) == Some(&(id as u32)),
                Loc::Pending(i) => tree.pending.get(i as usize) == Some(&(id as u32)),
                Loc::Out => false,
            };
            if !holds {
                return Some(format!("{id}: {:?} does not hold it", place.loc));
            }
        }
        for tree in &bp.trees {
            let slots = tree
                .members
                .iter()
                .enumerate()
                .filter(|&(_, &id)| id != DEAD);
            for (slot, &id) in slots {
                if bp.places.get(id as usize).map(|p| p.loc) != Some(Loc::Tree(slot as u32)) {
                    return Some(format!("slot {slot}: member {id} placed elsewhere"));
                }
            }
            for (i, &id) in tree.pending.iter().enumerate() {
                if bp.places.get(id as usize).map(|p| p.loc) != Some(Loc::Pending(i as u32)) {
                    return Some(format!("pending {i}: {id} placed elsewhere"));
                }
            }
        }
        None
    }

    /// Records and places agree (`places_disagree`) after every update, through what moves a
    /// proxy between trees or out of them: a churning scene (removals, reused indices,
    /// rebuilds), and by hand a box turned invalid and valid again, body types changed both
    /// ways, a collider disabled and enabled, and a collider removed with its index reused.
    #[test]
    fn proxy_records_and_places_agree() {
        let mut bp = CanopyBroadPhase::new();
        for (k, u) in record(spawn_storm(Size::Small), 60).iter().enumerate() {
            u.apply(&mut bp, &mut Vec::new());
            assert_eq!(places_disagree(&bp), None, "spawn_storm update {k}");
        }

        let (mut bodies, mut colliders, handles) = ball_row(40, RigidBodyType::Dynamic);
        let params = IntegrationParameters::default();
        let mut bp = CanopyBroadPhase::new();
        let update = |bp: &mut CanopyBroadPhase,
                      bodies: &RigidBodySet,
                      colliders: &ColliderSet,
                      removed: &[ColliderHandle],
                      what: &str| {
            let all: Vec<ColliderHandle> = colliders.iter().map(|(h, _)| h).collect();
            bp.update(&params, colliders, bodies, &all, removed, &mut Vec::new());
            assert_eq!(places_disagree(bp), None, "{what}");
        };
        update(&mut bp, &bodies, &colliders, &[], "inserted");
        assert_eq!(bp.stats().pairs, 39);
        // Every proxy new, none in a tree yet: the pairs came from the walks.
        assert!(bp.stats().walked && bp.stats().moved == 40);
        let c5 = bodies[handles[5]].colliders()[0];
        colliders[c5].set_translation(vector![f32::NAN, 0.0, 0.0]);
        update(&mut bp, &bodies, &colliders, &[], "invalid");
        assert!(bp.fat_aabb(c5).is_none());
        assert_eq!(bp.stats().pairs, 37);
        colliders[c5].set_translation(vector![5.0, 0.0, 0.0]);
        update(&mut bp, &bodies, &colliders, &[], "valid again");
        assert!(bp.fat_aabb(c5).is_some());
        assert_eq!(bp.stats().pairs, 39);
        // One proxy back among 39 tree members: one query.
        assert!(!bp.stats().walked && bp.stats().moved == 1);
        for (ty, what) in [
            (RigidBodyType::Fixed, "fixed"),
            (RigidBodyType::KinematicPositionBased, "kinematic"),
            (RigidBodyType::Dynamic, "dynamic"),
        ] {
            for &i in &[0, 7, 8, 39] {
                bodies[handles[i]].set_body_type(ty, true);
            }
            update(&mut bp, &bodies, &colliders, &[], what);
        }
        assert_eq!(bp.stats().pairs, 39);
        let c9 = bodies[handles[9]].colliders()[0];
        colliders[c9].set_enabled(false);
        update(&mut bp, &bodies, &colliders, &[c9], "disabled");
        assert_eq!(bp.stats().pairs, 37);
        colliders[c9].set_enabled(true);
        update(&mut bp, &bodies, &colliders, &[], "enabled");
        assert_eq!(bp.stats().pairs, 39);
        let c3 = bodies[handles[3]].colliders()[0];
        colliders.remove(c3, &mut IslandManager::new(), &mut bodies, true);
        update(&mut bp, &bodies, &colliders, &[c3], "removed");
        assert_eq!(bp.stats().pairs, 37);
        let reused =
            colliders.insert_with_parent(ColliderBuilder::ball(0.6), handles[3], &mut bodies);
        assert_eq!(reused.into_raw_parts().0, c3.into_raw_parts().0);
        update(&mut bp, &bodies, &colliders, &[], "index reused");
        assert!(bp.fat_aabb(reused).is_some() && bp.fat_aabb(c3).is_none());
        assert_eq!(bp.stats().pairs, 39);
    }

    fn plain(events: &[BroadPhasePairEvent]) -> Vec<(bool, ColliderHandle, ColliderHandle)> {
        events
            .iter()
            .map(|e| match e {
                BroadPhasePairEvent::AddPair(p) => (true, p.collider1, p.collider2),
                BroadPhasePairEvent::DeletePair(p) => (false, p.collider1, p.collider2),
            })
            .collect()
    }

    /// The shape look-ahead only ever prefetches: with every hint replaced by a bogus address
    /// (scattered, so the look-ahead runs), a churning scene gives the same events, update by
    /// update, as with true hints, and nothing faults.
    #[test]
    fn shape_hints_are_only_hints() {
        let updates = record(spawn_storm(Size::Small), 60);
        let (mut honest, mut bogus) = (CanopyBroadPhase::new(), CanopyBroadPhase::new());
        let (mut a, mut b) = (Vec::new(), Vec::new());
        let (mut scattered_updates, mut events) = (0, 0);
        for (k, u) in updates.iter().enumerate() {
            if k > 0 {
                for (i, h) in bogus.shape_hints.iter_mut().enumerate() {
                    *h = 0x1000 + i * 0x1_0000;
                }
                // Checked at the next update whose count is a multiple of the interval.
                assert!(bogus.shapes_look_scattered() || bogus.shape_hints.len() < 2);
                scattered_updates += (bogus.shape_checks % SHAPE_CHECK_INTERVAL == 0) as usize;
            }
            a.clear();
            b.clear();
            u.apply(&mut honest, &mut a);
            u.apply(&mut bogus, &mut b);
            assert_eq!(plain(&a), plain(&b), "update {k}");
            events += a.len();
        }
        assert!(scattered_updates > 0 && events > 0);
    }
}
