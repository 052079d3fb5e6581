//! Scene queries on [`CanopyBroadPhase`]: what Rapier's `QueryPipeline` answers, culled by the
//! broadphase's own canopy-core trees, with parry's exact shape tests.
//!
//! [`CanopyBroadPhase::scene_queries`] gives a [`SceneQueries`] with the methods of Rapier's
//! `QueryPipeline`, same names, arguments and meanings. Files: `ray.rs` (ray casts, batched
//! ray casts), `point.rs` (projection, containment), `shape.rs` (shape casts, shape and box
//! intersection), `overlay.rs` (edits made since the last step: `refresh_queries`),
//! `pipeline.rs` (`as_query_pipeline`: Rapier's own `QueryPipeline` over a lazily synced
//! parry BVH, for the character controller and other code written against it).

mod overlay;
mod pipeline;
mod point;
mod ray;
mod shape;

pub(crate) use overlay::QueryOverlay;
pub(crate) use pipeline::QueryMirror;

use crate::broad_phase::CanopyBroadPhase;
use crate::filter::Mobility;
use canopy_core::Aabb;
use rapier3d::parry::query::QueryDispatcher;
use rapier3d::prelude::{
    Collider, ColliderHandle, ColliderSet, Isometry, QueryFilter, Ray, Real, RigidBodySet, Shape,
};

/// `true` when every coordinate is finite.
pub(crate) fn finite<'v>(coords: impl IntoIterator<Item = &'v Real>) -> bool {
    coords.into_iter().all(|c| c.is_finite())
}

/// `true` for a ray with a finite origin and direction and a time limit that is not NaN or
/// negative (infinite is fine).
pub(crate) fn valid_ray(ray: &Ray, max_toi: Real) -> bool {
    finite(ray.origin.iter()) && finite(ray.dir.iter()) && max_toi >= 0.0
}

/// `true` for a pose with a finite translation and rotation.
pub(crate) fn valid_pose(pose: &Isometry<Real>) -> bool {
    finite(pose.translation.vector.iter()) && finite(pose.rotation.coords.iter())
}

/// The distance beyond which parry's point projection on a shape made of parts is not to be
/// trusted: it squares `f32` distances (three of them summed), which overflow past about
/// 1.8e19 (1e19 leaves room for the sum). Its projection on a mesh, polyline or compound then
/// finds no part and panics (`unwrap` on `None`), and a heightfield's answers the query point
/// itself.
const PARTS_REACH: f64 = 1.0e19;

/// `true` when `shape` is made of parts (a mesh, polyline, compound, heightfield or voxels)
/// and some point of `query` lies farther than [`PARTS_REACH`] from some point of `shape_box`
/// (the farthest two points of the two boxes, in `f64`): parry's exact queries between them
/// may overflow, so such a shape is left out.
pub(crate) fn beyond_parts_reach(shape: &dyn Shape, shape_box: &Aabb, query: &Aabb) -> bool {
    use rapier3d::parry::shape::TypedShape;
    let parts = matches!(
        shape.as_typed_shape(),
        TypedShape::TriMesh(_)
            | TypedShape::Polyline(_)
            | TypedShape::Compound(_)
            | TypedShape::HeightField(_)
            | TypedShape::Voxels(_)
    );
    parts && {
        let far2: f64 = (0..3)
            .map(|i| {
                let a = query.max[i] as f64 - shape_box.min[i] as f64;
                let b = shape_box.max[i] as f64 - query.min[i] as f64;
                a.abs().max(b.abs()).powi(2)
            })
            .sum();
        far2.is_nan() || far2 > PARTS_REACH * PARTS_REACH
    }
}

/// Scene queries over a [`CanopyBroadPhase`] and the sets it was last updated with, with a
/// [`QueryFilter`]: the methods of Rapier's `QueryPipeline` (same names, arguments and
/// results), culled by canopy's trees. Get one from [`CanopyBroadPhase::scene_queries`].
///
/// The trees hold the colliders as of the broadphase's last update (every physics step
/// ends with one). After inserting, moving, removing or disabling colliders outside a step,
/// call [`CanopyBroadPhase::refresh_queries`] first; the exact tests always use each
/// collider's current shape and position. Invalid inputs (a NaN or infinite ray, point or
/// pose, a NaN or negative time limit) find nothing; no query panics.
///
/// ```
/// use canopy_rapier::CanopyBroadPhase;
/// use rapier3d::prelude::*;
///
/// let bodies = RigidBodySet::new();
/// let mut colliders = ColliderSet::new();
/// let wall = colliders.insert(ColliderBuilder::cuboid(0.5, 5.0, 5.0).translation(vector![10.0, 0.0, 0.0]));
/// let mut broad_phase = CanopyBroadPhase::new();
/// // Without a step in between, make the broadphase see the new collider.
/// broad_phase.refresh_queries(&colliders);
/// let narrow_phase = NarrowPhase::new();
/// let queries = broad_phase.scene_queries(narrow_phase.query_dispatcher(), &bodies, &colliders, QueryFilter::default());
/// let ray = Ray::new(point![0.0, 0.0, 0.0], vector![1.0, 0.0, 0.0]);
/// assert_eq!(queries.cast_ray(&ray, 100.0, true), Some((wall, 9.5)));
/// ```
#[derive(Clone, Copy)]
pub struct SceneQueries<'a> {
    pub(crate) broad_phase: &'a CanopyBroadPhase,
    /// The dispatcher for the exact shape-vs-shape tests (shape casts, shape intersections).
    pub dispatcher: &'a dyn QueryDispatcher,
    /// The rigid bodies of the colliders (for the filter's body-type flags).
    pub bodies: &'a RigidBodySet,
    /// The colliders the broadphase was updated with.
    pub colliders: &'a ColliderSet,
    /// Which colliders the queries consider.
    pub filter: QueryFilter<'a>,
}

impl CanopyBroadPhase {
    /// Scene queries over this broadphase, as Rapier's `BroadPhaseBvh::as_query_pipeline`
    /// gives them (see [`SceneQueries`]).
    pub fn scene_queries<'a>(
        &'a self,
        dispatcher: &'a dyn QueryDispatcher,
        bodies: &'a RigidBodySet,
        colliders: &'a ColliderSet,
        filter: QueryFilter<'a>,
    ) -> SceneQueries<'a> {
        SceneQueries {
            broad_phase: self,
            dispatcher,
            bodies,
            colliders,
            filter,
        }
    }
}

impl<'a> SceneQueries<'a> {
    /// The same queries with a different filter.
    pub fn with_filter(self, filter: QueryFilter<'a>) -> Self {
        Self { filter, ..self }
    }

    /// The collider behind proxy `id` when it is current (not superseded by an edit since
    /// the last update) and passes the filter.
    #[inline]
    pub(crate) fn collider(&self, id: u32) -> Option<(ColliderHandle, &'a Collider)> {
        if self.broad_phase.overlay.is_stale(id) {
            return None;
        }
        // Proxy ids are collider indices. Reading the collider by index alone (as Rapier's
        // pipeline does) saves a read of the proxy per candidate; a collider that replaced a
        // removed one under the same index since the last update is a current collider, and
        // `refresh_queries` marks such proxies stale anyway.
        let (collider, handle) = self.colliders.get_unknown_gen(id)?;
        (collider.is_enabled() && self.filter.test(self.bodies, handle, collider))
            .then_some((handle, collider))
    }

    /// Colliders inserted or moved out of their fat boxes since the last update (see
    /// [`CanopyBroadPhase::refresh_queries`]) that pass the filter, with their current boxes.
    pub(crate) fn edited(&self) -> impl Iterator<Item = (ColliderHandle, &'a Collider, Aabb)> + '_ {
        self.broad_phase
            .overlay
            .extra()
            .iter()
            .filter_map(move |&handle| {
                let collider = self.colliders.get(handle)?;
                if !collider.is_enabled() || !self.filter.test(self.bodies, handle, collider) {
                    return None;
                }
                let aabb = collider.compute_aabb();
                let aabb = Aabb::new(aabb.mins, aabb.maxs);
                aabb.is_valid().then_some((handle, collider, aabb))
            })
    }

    /// The collision box of proxy `id` at the last update (Rapier's box with prediction
    /// distance and soft-CCD motion, inside the fat box): a cheap first test before the
    /// collider is read. Current for every proxy the overlay does not mark stale.
    #[inline]
    pub(crate) fn tight(&self, id: u32) -> &'a Aabb {
        &self.broad_phase.tights[id as usize]
    }

    /// Whether the proxies of tree `m` have fat boxes larger than their collision boxes (all
    /// but the fixed tree with the default zero `fixed_margin`): only then is the collision
    /// box worth testing before the collider.
    #[inline]
    pub(crate) fn loose(&self, m: Mobility) -> bool {
        m != Mobility::Fixed || self.broad_phase.config().fixed_margin > 0.0
    }

    /// Every collider that passes the filter, whose boxes meet `aabb` (the fat box, then the
    /// collision box of the last update; the current box for colliders edited since) and for
    /// which `exact` holds: tree members in tree order, then edited colliders. The common body
    /// of the intersection queries.
    pub(crate) fn colliders_in_aabb(
        &self,
        aabb: &Aabb,
        exact: impl Fn(&Collider, &Aabb) -> bool,
    ) -> Vec<(ColliderHandle, &'a Collider)> {
        let mut found = Vec::new();
        self.cull_aabb(aabb, |id| {
            let tight = self.tight(id);
            if !tight.intersects(aabb) {
                return;
            }
            if let Some((handle, collider)) = self.collider(id) {
                if exact(collider, tight) {
                    found.push((handle, collider));
                }
            }
        });
        for (handle, collider, b) in self.edited() {
            if b.intersects(aabb) && exact(collider, &b) {
                found.push((handle, collider));
            }
        }
        found
    }

    /// Calls `f` with every proxy whose fat box overlaps `aabb`, over the three trees.
    pub(crate) fn cull_aabb(&self, aabb: &Aabb, mut f: impl FnMut(u32)) {
        let bp = self.broad_phase;
        for m in Mobility::ALL {
            bp.trees[m as usize].for_each_overlap(&bp.proxies, aabb, &mut f);
        }
    }
}
