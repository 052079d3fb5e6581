//! The truth the world is tested and benchmarked against: parry called on every pair, fresh
//! (no manifold or workspace carried over), without any broad phase.

use nalgebra::{Isometry3, Point3};
use parry3d::query::{DefaultQueryDispatcher, PersistentQueryDispatcher};
use parry3d::shape::{Shape, SharedShape};
use rayon::prelude::*;

use crate::narrow::in_contact;
use crate::pair::Manifold;
use crate::self_contact::{adjacent, triangle_pair_manifold};

/// A pair `(i, j)`, `i < j`, of objects with at least one contact point, and its manifolds.
pub type TruthPair = (usize, usize, Vec<Manifold>);

/// `DefaultQueryDispatcher.contact_manifolds(pose_i⁻¹·pose_j, shape_i, shape_j, prediction)`
/// called fresh on pair `(i, j)`: its manifolds when some point is within `prediction` (see
/// [`in_contact`]). `None` also when `i` or `j` is not an index of `objects`, for a
/// `prediction` that is negative, NaN or infinite, and for a pose that
/// [`check_pose`](crate::check_pose) refuses (parry panics on some of these: a negative
/// prediction against a mesh, a NaN rotation).
pub fn pair(
    objects: &[(Isometry3<f32>, SharedShape)],
    i: usize,
    j: usize,
    prediction: f32,
) -> Option<Vec<Manifold>> {
    let (pose1, shape1) = objects.get(i)?;
    let (pose2, shape2) = objects.get(j)?;
    let valid = |pose| crate::validate::check_pose(pose).is_ok();
    if !(prediction.is_finite() && prediction >= 0.0 && valid(pose1) && valid(pose2)) {
        return None;
    }
    let pos12 = pose1.inv_mul(pose2);
    let mut manifolds = Vec::new();
    DefaultQueryDispatcher
        .contact_manifolds(
            &pos12,
            &**shape1,
            &**shape2,
            prediction,
            &mut manifolds,
            &mut None,
        )
        .ok()?;
    in_contact(&manifolds, prediction).then_some(manifolds)
}

/// Every pair `i < j` in contact, in order, one thread.
pub fn contact_pairs(objects: &[(Isometry3<f32>, SharedShape)], prediction: f32) -> Vec<TruthPair> {
    let n = objects.len();
    (0..n)
        .flat_map(|i| (i + 1..n).map(move |j| (i, j)))
        .filter_map(|(i, j)| pair(objects, i, j, prediction).map(|m| (i, j, m)))
        .collect()
}

/// [`contact_pairs`] on the current rayon pool (same result, same order).
pub fn par_contact_pairs(
    objects: &[(Isometry3<f32>, SharedShape)],
    prediction: f32,
) -> Vec<TruthPair> {
    let n = objects.len();
    (0..n)
        .into_par_iter()
        .flat_map_iter(|i| {
            (i + 1..n).filter_map(move |j| pair(objects, i, j, prediction).map(|m| (i, j, m)))
        })
        .collect()
}

/// Every pair of triangles `(t1, t2)` of two meshes (`t1` of the first) whose convex-convex
/// manifold has a point within `prediction`, with its smallest point distance: all `n1 × n2` pairs through parry's
/// `contact_manifold_convex_convex`, with the meshes' pseudo-normal constraints and the
/// relative pose composed as parry's own mesh-mesh routine does (it walks the larger mesh
/// first; with pseudo-normals the manifold is not continuous in the pose, so even the last bit
/// of the pose matters).
pub fn mesh_mesh_triangle_pairs(
    mesh1: &parry3d::shape::TriMesh,
    pose1: &Isometry3<f32>,
    mesh2: &parry3d::shape::TriMesh,
    pose2: &Isometry3<f32>,
    prediction: f32,
) -> Vec<(u32, u32, f32)> {
    let pos12 = pose1.inv_mul(pose2);
    let size = |m: &parry3d::shape::TriMesh| m.bvh().root_aabb().half_extents().norm_squared();
    let pos12 = if size(mesh1) < size(mesh2) {
        pos12
    } else {
        pos12.inverse().inverse()
    };
    let mut out = Vec::new();
    for t1 in 0..mesh1.num_triangles() as u32 {
        let tri1 = mesh1.triangle(t1);
        let n1 = mesh1.triangle_normal_constraints(t1);
        for t2 in 0..mesh2.num_triangles() as u32 {
            let tri2 = mesh2.triangle(t2);
            let n2 = mesh2.triangle_normal_constraints(t2);
            let mut m = Manifold::with_data(t1, t2, ());
            let ok = DefaultQueryDispatcher.contact_manifold_convex_convex(
                &pos12,
                &tri1,
                &tri2,
                n1.as_ref().map(|n| n as _),
                n2.as_ref().map(|n| n as _),
                prediction,
                &mut m,
            );
            if ok.is_ok() {
                match crate::pair::min_distance(std::slice::from_ref(&m)) {
                    Some(d) if d <= prediction => out.push((t1, t2, d)),
                    _ => {}
                }
            }
        }
    }
    out
}

/// Every pair of triangles `t1 < t2` of one mesh that share no vertex and whose convex-convex
/// manifold has a point within `prediction`: all `n²/2` pairs, fresh.
pub fn self_contacts(
    vertices: &[Point3<f32>],
    indices: &[[u32; 3]],
    prediction: f32,
) -> Vec<(u32, u32, Manifold)> {
    let n = indices.len() as u32;
    let mut out = Vec::new();
    for t1 in 0..n {
        for t2 in t1 + 1..n {
            if adjacent(&indices[t1 as usize], &indices[t2 as usize]) {
                continue;
            }
            if let Some(m) = triangle_pair_manifold(vertices, indices, t1, t2, prediction) {
                out.push((t1, t2, m));
            }
        }
    }
    out
}

/// `true` when `shape` is something parry's dispatcher handles as one convex piece.
pub fn is_convex(shape: &dyn Shape) -> bool {
    shape.is_convex()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An index past the objects gives `None`, on either side; in range, the same pair gives
    /// parry's manifolds (two touching balls).
    #[test]
    fn pair_outside_the_objects_is_none() {
        let objects = [
            (Isometry3::identity(), SharedShape::ball(1.0)),
            (
                Isometry3::translation(1.5, 0.0, 0.0),
                SharedShape::ball(1.0),
            ),
        ];
        assert!(pair(&objects, 0, 1, 0.0).is_some());
        for (i, j) in [(0, 2), (5, 1), (2, 2), (usize::MAX, 0)] {
            assert!(pair(&objects, i, j, 0.0).is_none(), "({i}, {j})");
        }
    }

    /// A negative, NaN or infinite prediction, or a pose `check_pose` refuses, gives `None`
    /// (parry panicked: "the loosening margin must be positive" against a mesh, and an
    /// assertion or a subtraction overflow on a NaN rotation); the valid pairs next to them
    /// still give parry's manifolds.
    #[test]
    fn invalid_predictions_and_poses_give_none() {
        use nalgebra::{Quaternion, Translation3, UnitQuaternion};
        let mesh = SharedShape::trimesh(
            vec![
                Point3::origin(),
                Point3::new(1.0, 0.0, 0.0),
                Point3::new(0.0, 1.0, 0.0),
            ],
            vec![[0, 1, 2]],
        )
        .unwrap();
        let nan_rotation = UnitQuaternion::new_unchecked(Quaternion::new(f32::NAN, 0.0, 0.0, 0.0));
        let objects = vec![
            (Isometry3::identity(), SharedShape::ball(1.0)),
            (Isometry3::identity(), mesh),
            (
                Isometry3::from_parts(Translation3::identity(), nan_rotation),
                SharedShape::cuboid(1.0, 1.0, 1.0),
            ),
            (
                Isometry3::translation(f32::INFINITY, 0.0, 0.0),
                SharedShape::ball(1.0),
            ),
        ];
        assert!(pair(&objects, 0, 1, 0.0).is_some());
        for prediction in [-1.0, f32::NAN, f32::INFINITY] {
            assert!(pair(&objects, 0, 1, prediction).is_none(), "{prediction}");
        }
        for (i, j) in [(0, 2), (2, 1), (0, 3), (3, 2)] {
            assert!(pair(&objects, i, j, 0.0).is_none(), "({i}, {j})");
        }
        // No pair panics, and only the valid pair is found.
        let found: Vec<(usize, usize)> = contact_pairs(&objects, -1.0)
            .into_iter()
            .chain(par_contact_pairs(&objects, 0.0))
            .map(|(i, j, _)| (i, j))
            .collect();
        assert_eq!(found, vec![(0, 1)]);
    }
}
