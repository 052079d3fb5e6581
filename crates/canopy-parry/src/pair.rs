//! `ContactPair`: two objects whose boxes overlap, their contact manifolds (kept across
//! updates so parry can exploit coherence), and world-space views of the contact points.

use std::fmt;

use nalgebra::{Isometry3, Point3, Vector3};
use parry3d::query::details::ContactManifoldsWorkspace;
use parry3d::query::ContactManifold;

use crate::handle::ObjectHandle;

/// A contact manifold as parry computes it: points in the local frames of the two (sub)shapes,
/// the normal `local_n1` in the first one's frame, and `subshape1` / `subshape2` naming the
/// triangles or compound parts for composite shapes.
pub type Manifold = ContactManifold<(), ()>;

/// A candidate pair of a [`crate::CollisionWorld`] (their loosened boxes overlap) and what the
/// narrow phase found for it. `object1 < object2`, and the manifolds are those of parry's
/// `contact_manifolds(pose1⁻¹·pose2, shape1, shape2, ..)`.
pub struct ContactPair {
    pub(crate) object1: ObjectHandle,
    pub(crate) object2: ObjectHandle,
    pub(crate) manifolds: Vec<Manifold>,
    /// For composite pairs: the `(part1, part2)` of each manifold, sorted.
    pub(crate) keys: Vec<(u32, u32)>,
    /// parry's workspace for non-composite pairs.
    pub(crate) workspace: Option<ContactManifoldsWorkspace>,
    pub(crate) pose1: Isometry3<f32>,
    pub(crate) pose2: Isometry3<f32>,
    pub(crate) touching: bool,
}

/// One contact point in world space.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WorldContact {
    /// The point on the first object.
    pub point1: Point3<f32>,
    /// The point on the second object.
    pub point2: Point3<f32>,
    /// The contact normal, pointing out of the first object.
    pub normal1: Vector3<f32>,
    /// Signed distance along the normal: negative when penetrating (`-dist` is the depth).
    pub dist: f32,
    /// Triangle / part of the first object (0 for a non-composite shape).
    pub subshape1: u32,
    /// Triangle / part of the second object (0 for a non-composite shape).
    pub subshape2: u32,
}

impl ContactPair {
    pub(crate) fn new(object1: ObjectHandle, object2: ObjectHandle) -> Self {
        Self {
            object1,
            object2,
            manifolds: Vec::new(),
            keys: Vec::new(),
            workspace: None,
            pose1: Isometry3::identity(),
            pose2: Isometry3::identity(),
            touching: false,
        }
    }

    /// The two objects, `object1 < object2`.
    #[inline]
    pub fn objects(&self) -> (ObjectHandle, ObjectHandle) {
        (self.object1, self.object2)
    }

    /// All manifolds parry keeps for the pair, some possibly without points.
    #[inline]
    pub fn manifolds(&self) -> &[Manifold] {
        &self.manifolds
    }

    /// `true` when some contact point is at most the prediction distance apart (equivalently,
    /// `min_distance() <= prediction`). Manifolds may hold farther, speculative points (from
    /// parry's polygon clipping); they alone do not make a contact.
    #[inline]
    pub fn has_contacts(&self) -> bool {
        self.touching
    }

    /// Number of contact points over all manifolds.
    pub fn num_contacts(&self) -> usize {
        self.manifolds.iter().map(|m| m.points.len()).sum()
    }

    /// The smallest signed distance over all points (the deepest penetration is its negation),
    /// or `None` without points.
    pub fn min_distance(&self) -> Option<f32> {
        min_distance(&self.manifolds)
    }

    /// The contact points in world space, using the poses of the last update.
    pub fn contacts(&self) -> impl Iterator<Item = WorldContact> + '_ {
        self.manifolds.iter().flat_map(move |m| {
            let frame1 = match &m.subshape_pos1 {
                Some(p) => self.pose1 * p,
                None => self.pose1,
            };
            let frame2 = match &m.subshape_pos2 {
                Some(p) => self.pose2 * p,
                None => self.pose2,
            };
            m.points.iter().map(move |pt| WorldContact {
                point1: frame1 * pt.local_p1,
                point2: frame2 * pt.local_p2,
                normal1: frame1 * m.local_n1,
                dist: pt.dist,
                subshape1: m.subshape1,
                subshape2: m.subshape2,
            })
        })
    }

    pub(crate) fn key(&self) -> (ObjectHandle, ObjectHandle) {
        (self.object1, self.object2)
    }
}

/// Smallest point distance over `manifolds`.
pub fn min_distance(manifolds: &[Manifold]) -> Option<f32> {
    manifolds
        .iter()
        .flat_map(|m| m.points.iter().map(|p| p.dist))
        .reduce(f32::min)
}

impl fmt::Debug for ContactPair {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("ContactPair")
            .field("object1", &self.object1)
            .field("object2", &self.object2)
            .field("manifolds", &self.manifolds.len())
            .field("contacts", &self.num_contacts())
            .field("min_distance", &self.min_distance())
            .finish()
    }
}
