//! One tree of proxies (fixed, kinematic or dynamic): a canopy-core [`Bvh`] over fat boxes,
//! a pending list for proxies added since the last build (with a small tree, refit or rebuilt
//! every update, unless the list is short enough to scan), and dead slots for proxies removed
//! since then. Refit when boxes change; rebuilt when the pending list or the dead slots grow
//! too large, or the SAH cost has drifted (see [`crate::RebuildPolicy`]).

use crate::config::RebuildPolicy;
use crate::filter::{FilterData, TreeFilterSummary};
use crate::proxy::{Loc, Place, Proxy};
use canopy_core::{Aabb, BuildOptions, Builder, Bvh, PairMarks, Ray};
use rapier3d::na::Point3;

/// Refits between two comparisons of the SAH cost with the cost after the last build.
const COST_CHECK_INTERVAL: u32 = 4;

/// Pending lists of at most this many proxies get no tree: their boxes are scanned.
const SCANNED_PENDING: usize = 4;

/// Most primitives per leaf of the moving trees (kinematic, dynamic) and of every pending
/// tree; the fixed tree keeps the builders' default of 4. Larger leaves make the tree
/// shallower, so a moved proxy's query visits fewer nodes and tests a few more boxes, each
/// without a branch on its outcome; rebuilds and refits have fewer nodes to make. Measured
/// with `broadphase_replay SCENE ab`, B / A of 8 against 4 (below 1: faster; identical A and
/// B 0.989 to 1.005 that hour): `spawn_storm` 0.964, 0.963, 0.971, 0.938, 0.988, `teleport`
/// 0.924, 0.922, `pyramid` 0.975, `many_pyramids` 0.979, `boxes` 0.991, `balls` 0.998,
/// `keva_tower` 1.010, 1.004, `many_kinematics` 1.009; 6 and 12 gave `spawn_storm` 0.964 and
/// 0.968, 16 gave 1.008; 8 for the fixed tree as well changed nothing (`many_static`). With
/// `tools/ab` (old / new, 3 to 5 runs): `spawn_storm` 1.022, `teleport` 1.024, `balls` 1.028,
/// `many_kinematics` 1.102, `boxes` 1.007, `keva_tower` 0.999, `many_pyramids` 1.004 and
/// 0.998, `pyramid` 1.006 and 0.988. (Stop 14 had measured 8 at 0.969 on `spawn_storm`,
/// within that tool's noise then.) 16 since the pair walks cut two leaves down to the
/// primitives that overlap the other leaf's box before testing their pairs (which makes
/// large leaves cheap to pair; leaves of up to 16 take that path): `tools/ab` old / new, 16
/// against 8, `spawn_storm` 1.009 (9 runs; 1.019 in 5 before), `balls` 1.016, `teleport`
/// 1.027, `many_kinematics` 1.073, `many_pyramids` 1.031, `pyramid` 1.026, `keva_tower`
/// 1.015, `boxes` 1.013; 10, 12 and 24 gave `spawn_storm` 0.995, 1.010 and 1.022, `balls`
/// 1.004, 0.996 and 0.988, `teleport` 1.006, 1.010 and 1.009. More instructions (callgrind,
/// 100 steps: `spawn_storm` 264.5M -> 279.7M, `balls` 241.6M -> 245.6M) in less time: fewer
/// node visits, whose branches mispredict, for more branch-free box tests.
pub(crate) const MOVING_LEAF_SIZE: u32 = 16;

/// Marks a slot whose proxy has left the tree.
pub(crate) const DEAD: u32 = u32::MAX;

#[derive(Clone, Debug, Default)]
pub(crate) struct ProxyTree {
    pub bvh: Bvh,
    /// New fat boxes of BVH primitives since the last refit.
    changes: Vec<(u32, Aabb)>,
    /// New fat boxes of members that do not overlap the box they replace (a teleport, or a
    /// body faster than its box), since the SAH cost was last compared or the tree built.
    jumped: usize,
    /// Proxy id of each BVH slot, or [`DEAD`].
    pub members: Vec<u32>,
    pub pending: Vec<u32>,
    /// A tree over the pending proxies' fat boxes (primitive `i` is `pending[i]`), brought up
    /// to date by every `maintain`: built anew when the pending list changed, refit when only
    /// boxes did. `None` from [`ProxyTree::pending_bvh`] when stale.
    pending_bvh: Bvh,
    pending_fresh: bool,
    /// The pending list changed (entries added, removed or moved) since `pending_bvh` was built.
    pending_dirty: bool,
    /// New fat boxes of pending proxies (by pending index) since `pending_bvh` was made or refit.
    pending_changes: Vec<(u32, Aabb)>,
    pub dead: usize,
    /// Refits since the SAH cost was last compared with the cost after the build.
    refits_since_check: u32,
    pub summary: TreeFilterSummary,
    /// Marks with nothing marked, for pair walks against this tree when none of it moved:
    /// made by the first such walk after a build ([`ProxyTree::no_marks`]), not by the build
    /// (about 37 µs of a 4,000-proxy rebuild's 230 in `spawn_storm`, whose moving tree is
    /// rebuilt 16 times in 200 steps and never needs them).
    no_marks: std::sync::OnceLock<PairMarks>,
    built_cost: f64,
    pub rebuilds: u64,
    pub refits: u64,
}

impl ProxyTree {
    /// Live proxies (tree and pending).
    pub fn len(&self) -> usize {
        self.members.len() - self.dead + self.pending.len()
    }

    /// Adds proxy `id` (filter inputs `filter`) to the pending list; returns its location.
    pub fn insert(&mut self, id: u32, filter: &FilterData) -> Loc {
        let loc = Loc::Pending(self.pending.len() as u32);
        self.pending.push(id);
        self.pending_dirty = true;
        self.summary.add(filter);
        loc
    }

    /// Takes the proxy at `loc` out (the caller marks it [`Loc::Out`]); returns the proxy id
    /// whose pending index changed, if any, with its new index.
    pub fn remove(&mut self, loc: Loc) -> Option<(u32, u32)> {
        match loc {
            Loc::Tree(slot) => {
                self.members[slot as usize] = DEAD;
                self.dead += 1;
                None
            }
            Loc::Pending(i) => {
                self.pending.swap_remove(i as usize);
                self.pending_dirty = true;
                self.pending.get(i as usize).map(|&other| (other, i))
            }
            Loc::Out => None,
        }
    }

    /// Records `fat`, the new fat box of the proxy at `loc` in this tree; `jumped`: the new box
    /// does not overlap the one it replaces.
    pub fn set_box(&mut self, loc: Loc, fat: Aabb, jumped: bool) {
        match loc {
            Loc::Tree(slot) => {
                self.changes.push((slot, fat));
                self.jumped += jumped as usize;
            }
            Loc::Pending(i) => self.pending_changes.push((i, fat)),
            Loc::Out => {}
        }
    }

    fn needs_rebuild(&self, policy: &RebuildPolicy) -> bool {
        let size = self.members.len() as f64;
        self.pending.len()
            > policy
                .min_pending
                .max((size * policy.pending_fraction) as usize)
            || (self.dead > 0 && self.dead as f64 > size * policy.max_dead_fraction)
    }

    /// Brings the BVH up to date: rebuild or refit as the policy says (a rebuild writes the
    /// members' new slots into `places`). `build`: the options of this tree's builds (the
    /// pending tree is always an LBVH, built serially, with the same leaves).
    pub fn maintain(
        &mut self,
        proxies: &[Option<Proxy>],
        places: &mut [Place],
        policy: &RebuildPolicy,
        build: BuildOptions,
    ) {
        self.maintain_members(proxies, places, policy, build);
        if self.pending.len() <= SCANNED_PENDING {
            // Scanned, not queried (a lone ground's pending tree cost each dynamic proxy's
            // query about 37 ns, the scan of its box a few).
            self.pending_fresh = false;
            self.pending_dirty = false;
            self.pending_changes.clear();
            return;
        }
        if self.pending_fresh && !self.pending_dirty {
            // Same list: a refit, when some pending box changed, keeps the tree (and its
            // four-wide copy) in step for less than a build.
            let refit = self.pending_bvh.refit_primitives(&self.pending_changes);
            self.pending_changes.clear();
            if refit.is_ok() {
                return;
            }
        }
        self.pending_fresh = false;
        self.pending_dirty = false;
        self.pending_changes.clear();
        let boxes: Vec<Aabb> = self
            .pending
            .iter()
            .map(|&id| proxies[id as usize].as_ref().map_or(Aabb::EMPTY, |p| p.fat))
            .collect();
        let options = BuildOptions {
            builder: Builder::Lbvh,
            parallel: false,
            ..build
        };
        if let Ok(bvh) = Bvh::build(&boxes, options) {
            self.pending_bvh = bvh;
            self.pending_fresh = true;
        }
    }

    /// The tree over the pending proxies, when it matches them (after `maintain`).
    pub fn pending_bvh(&self) -> Option<&Bvh> {
        (self.pending_fresh
            && !self.pending_dirty
            && self.pending_changes.is_empty()
            && !self.pending.is_empty())
        .then_some(&self.pending_bvh)
    }

    fn maintain_members(
        &mut self,
        proxies: &[Option<Proxy>],
        places: &mut [Place],
        policy: &RebuildPolicy,
        build: BuildOptions,
    ) {
        if self.needs_rebuild(policy) {
            self.rebuild(proxies, places, build);
        } else if !self.changes.is_empty() {
            self.refits += 1;
            // Most members moved, and some jumped since the last check: see below.
            let moved_and_jumped = self.changes.len() * 2 >= self.members.len() && self.jumped > 0;
            let refit = self.bvh.refit_primitives(&self.changes);
            self.changes.clear();
            if refit.is_err() {
                // Boxes are validated before they reach the tree; rebuilding is the safe answer
                // should that ever fail.
                self.rebuild(proxies, places, build);
                return;
            }
            // The cost is one pass over the nodes: check it every few refits only, or at once
            // after a refit that moved most members when some member jumped since the last
            // check (a new box clear of its old one): a few jumps stretch their leaves'
            // ancestors across the jump, and the pair walks that follow a refit of most
            // members visit the whole tree (`teleport`: 32 bodies jump each step, and its
            // dense refits find the tree at 61 to 71 times its cost after the build, which
            // it kept for up to three more updates). Members that only moved on, even all of
            // them (`balls` falling in lockstep: 1.03 to 1.33 times), leave the tree about as
            // good as it was and wait for the next check.
            self.refits_since_check += 1;
            if self.refits_since_check >= COST_CHECK_INTERVAL || moved_and_jumped {
                self.refits_since_check = 0;
                self.jumped = 0;
                if self.bvh.sah_cost(1.0, 1.0) > self.built_cost * policy.max_cost_growth {
                    self.rebuild(proxies, places, build);
                }
            }
        }
    }

    pub fn rebuild(
        &mut self,
        proxies: &[Option<Proxy>],
        places: &mut [Place],
        build: BuildOptions,
    ) {
        let mut members: Vec<u32> = self
            .members
            .iter()
            .copied()
            .filter(|&m| m != DEAD)
            .collect();
        members.append(&mut self.pending);
        // Every member has a record (a proxy leaves its tree before its record goes); one that
        // did not would be left out of the new tree rather than stop the update.
        let before = members.len();
        members.retain(|&id| proxies.get(id as usize).is_some_and(Option::is_some));
        debug_assert_eq!(members.len(), before, "tree members without a proxy record");
        self.pending_fresh = false;
        let mut boxes = Vec::with_capacity(members.len());
        self.changes.clear();
        self.refits_since_check = 0;
        self.summary = TreeFilterSummary::default();
        for (slot, &id) in members.iter().enumerate() {
            places[id as usize].loc = Loc::Tree(slot as u32);
            if let Some(p) = &proxies[id as usize] {
                boxes.push(p.fat);
                self.summary.add(&p.filter);
            }
        }
        // Fat boxes are checked before they enter a tree, so the build cannot fail; an empty
        // tree (and every member pending again) would be the safe fallback.
        match Bvh::build(&boxes, build) {
            Ok(bvh) => {
                self.bvh = bvh;
                self.members = members;
            }
            Err(_) => {
                self.bvh = Bvh::new();
                self.members.clear();
                for (i, &id) in members.iter().enumerate() {
                    places[id as usize].loc = Loc::Pending(i as u32);
                }
                self.pending = members;
                self.pending_fresh = false;
            }
        }
        self.no_marks = std::sync::OnceLock::new();
        self.jumped = 0;
        self.dead = 0;
        self.built_cost = self.bvh.sah_cost(1.0, 1.0);
        self.rebuilds += 1;
    }

    /// Marks of this tree's BVH with nothing marked (see the field).
    pub fn no_marks(&self) -> &PairMarks {
        self.no_marks.get_or_init(|| self.bvh.marks(|_| false))
    }

    /// The pending proxy ids with their tree (when it matches them), for the scene queries.
    fn pending_parts(&self) -> (&[u32], Option<&Bvh>) {
        (&self.pending, self.pending_bvh())
    }

    /// Calls `f` with every live proxy (members and pending) whose fat box overlaps `aabb`.
    pub fn for_each_overlap(&self, proxies: &[Option<Proxy>], aabb: &Aabb, mut f: impl FnMut(u32)) {
        self.query_members(aabb, &mut f);
        match self.pending_parts() {
            (pending, Some(bvh)) => bvh.for_each_overlap(aabb, |i| f(pending[i as usize])),
            (pending, None) => {
                for &id in pending {
                    if proxies[id as usize]
                        .as_ref()
                        .is_some_and(|p| p.fat.intersects(aabb))
                    {
                        f(id);
                    }
                }
            }
        }
    }

    /// The closest hit of `ray` within `t_max` over members and pending proxies: `hit(id,
    /// best_t)` gives the exact time of impact with proxy `id` (as in `Bvh::cast_ray`).
    pub fn cast_ray(
        &self,
        proxies: &[Option<Proxy>],
        ray: &Ray,
        t_max: f32,
        mut hit: impl FnMut(u32, f32) -> Option<f32>,
    ) -> Option<(u32, f32)> {
        let mut best: Option<(u32, f32)> = None;
        let mut best_t = t_max;
        let members = &self.members;
        if let Some(h) = self.bvh.cast_ray(ray, best_t, |slot, t| {
            let id = members[slot as usize];
            if id == DEAD {
                None
            } else {
                hit(id, t)
            }
        }) {
            best_t = h.t;
            best = Some((members[h.primitive as usize], h.t));
        }
        match self.pending_parts() {
            (pending, Some(bvh)) => {
                if let Some(h) = bvh.cast_ray(ray, best_t, |i, t| hit(pending[i as usize], t)) {
                    if best.is_none() || h.t < best_t {
                        best = Some((pending[h.primitive as usize], h.t));
                    }
                }
            }
            (pending, None) => {
                for &id in pending {
                    let Some(p) = proxies[id as usize].as_ref() else {
                        continue;
                    };
                    if ray.intersect_aabb(&p.fat, best_t).is_none() {
                        continue;
                    }
                    if let Some(t) = hit(id, best_t) {
                        if t <= best_t && (best.is_none() || t < best_t) {
                            best_t = t;
                            best = Some((id, t));
                        }
                    }
                }
            }
        }
        best
    }

    /// The proxy nearest to `point` within `max_distance`: `distance(id, best)` gives the exact
    /// distance to proxy `id` (as in `Bvh::nearest`).
    pub fn nearest(
        &self,
        proxies: &[Option<Proxy>],
        point: &Point3<f32>,
        max_distance: f32,
        mut distance: impl FnMut(u32, f32) -> Option<f32>,
    ) -> Option<(u32, f32)> {
        let mut best: Option<(u32, f32)> = None;
        let mut best_d = max_distance;
        let members = &self.members;
        if let Some(h) = self.bvh.nearest(point, best_d, |slot, d| {
            let id = members[slot as usize];
            if id == DEAD {
                None
            } else {
                distance(id, d)
            }
        }) {
            best_d = h.distance;
            best = Some((members[h.primitive as usize], h.distance));
        }
        match self.pending_parts() {
            (pending, Some(bvh)) => {
                if let Some(h) = bvh.nearest(point, best_d, |i, d| distance(pending[i as usize], d))
                {
                    if best.is_none() || h.distance < best_d {
                        best = Some((pending[h.primitive as usize], h.distance));
                    }
                }
            }
            (pending, None) => {
                for &id in pending {
                    let Some(p) = proxies[id as usize].as_ref() else {
                        continue;
                    };
                    if p.fat.distance_to_point(point) > best_d {
                        continue;
                    }
                    if let Some(d) = distance(id, best_d) {
                        if d <= best_d && (best.is_none() || d < best_d) {
                            best_d = d;
                            best = Some((id, d));
                        }
                    }
                }
            }
        }
        best
    }

    /// Calls `f` with every live BVH member whose fat box overlaps `aabb` (pending excluded).
    #[inline]
    pub fn query_members(&self, aabb: &Aabb, mut f: impl FnMut(u32)) {
        self.bvh.for_each_overlap(aabb, |slot| {
            let id = self.members[slot as usize];
            if id != DEAD {
                f(id);
            }
        });
    }
}
