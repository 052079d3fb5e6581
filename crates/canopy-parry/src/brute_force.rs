//! The truth the world is tested and benchmarked against: parry called on every pair, fresh
//! (no manifold or workspace carried over), without any broad phase.

use nalgebra::{Isometry3, Point3};
use parry3d::query::{DefaultQueryDispatcher, PersistentQueryDispatcher};
use parry3d::shape::{Shape, SharedShape};
use rayon::prelude::*;

use crate::error::CollisionError;
use crate::narrow::in_contact;
use crate::pair::Manifold;
use crate::parts::mesh_triangle;
use crate::self_contact::{adjacent, triangles_manifold};
use crate::validate::{
    check_bounds, check_mesh_buffers, check_object, check_prediction, points_box,
};

/// A pair `(i, j)`, `i < j`, of objects with at least one contact point, and its manifolds.
pub type TruthPair = (usize, usize, Vec<Manifold>);

/// `DefaultQueryDispatcher.contact_manifolds(pose_i⁻¹·pose_j, shape_i, shape_j, prediction)`
/// called fresh on pair `(i, j)`: its manifolds when some point is within `prediction` (see
/// [`in_contact`]). `None` also when `i` or `j` is not an index of `objects`, for a
/// `prediction` that is negative, NaN or infinite, and for an object the world would refuse
/// at this prediction distance: a pose that [`check_pose`](crate::check_pose) refuses, a
/// shape that [`check_shape`](crate::check_shape) refuses, or a box (in the shape's own
/// frame, or at its pose grown by `prediction`) that [`check_bounds`]
/// refuses, i.e. one reaching beyond ±[`MAX_COORDINATE`](crate::MAX_COORDINATE). Parry
/// panics on some of these: a negative prediction against a mesh, a NaN rotation, a convex
/// hull without faces, coordinates near `f32::MAX`.
pub fn pair(
    objects: &[(Isometry3<f32>, SharedShape)],
    i: usize,
    j: usize,
    prediction: f32,
) -> Option<Vec<Manifold>> {
    let object1 = objects.get(i)?;
    let object2 = objects.get(j)?;
    let valid = valid_prediction(prediction)
        && valid_object(object1, prediction)
        && valid_object(object2, prediction);
    if !valid {
        return None;
    }
    manifolds(object1, object2, prediction)
}

/// `true` for a finite prediction distance `>= 0`.
fn valid_prediction(prediction: f32) -> bool {
    check_prediction(prediction).is_ok()
}

/// `true` when the world would accept `shape` at `pose` with this prediction distance.
fn valid_object((pose, shape): &(Isometry3<f32>, SharedShape), prediction: f32) -> bool {
    check_object(&**shape, pose, prediction).is_ok()
}

/// The parry call of [`pair`], on objects already checked.
fn manifolds(
    (pose1, shape1): &(Isometry3<f32>, SharedShape),
    (pose2, shape2): &(Isometry3<f32>, SharedShape),
    prediction: f32,
) -> Option<Vec<Manifold>> {
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

/// Whether each object passes the checks of [`pair`] (all `false` for an invalid
/// `prediction`): each object is checked once, not once per pair.
fn valid_objects(objects: &[(Isometry3<f32>, SharedShape)], prediction: f32) -> Vec<bool> {
    let ok = valid_prediction(prediction);
    objects
        .iter()
        .map(|o| ok && valid_object(o, prediction))
        .collect()
}

/// Every pair `i < j` in contact, in order, one thread: [`pair`] on each pair, so pairs with
/// an object the world would refuse are left out.
pub fn contact_pairs(objects: &[(Isometry3<f32>, SharedShape)], prediction: f32) -> Vec<TruthPair> {
    let valid = valid_objects(objects, prediction);
    let n = objects.len();
    (0..n)
        .filter(|&i| valid[i])
        .flat_map(|i| (i + 1..n).map(move |j| (i, j)))
        .filter(|&(_, j)| valid[j])
        .filter_map(|(i, j)| manifolds(&objects[i], &objects[j], prediction).map(|m| (i, j, m)))
        .collect()
}

/// [`contact_pairs`] on the current rayon pool (same result, same order).
pub fn par_contact_pairs(
    objects: &[(Isometry3<f32>, SharedShape)],
    prediction: f32,
) -> Vec<TruthPair> {
    let valid = valid_objects(objects, prediction);
    let valid = &valid;
    let n = objects.len();
    (0..n)
        .into_par_iter()
        .filter(|&i| valid[i])
        .flat_map_iter(|i| {
            (i + 1..n).filter(move |&j| valid[j]).filter_map(move |j| {
                manifolds(&objects[i], &objects[j], prediction).map(|m| (i, j, m))
            })
        })
        .collect()
}

/// Every pair of triangles `(t1, t2)` of two meshes (`t1` of the first) whose convex-convex
/// manifold has a point within `prediction`, with its smallest point distance: all `n1 × n2` pairs through parry's
/// `contact_manifold_convex_convex`, with the meshes' pseudo-normal constraints and the
/// relative pose composed as parry's own mesh-mesh routine does (it walks the larger mesh
/// first; with pseudo-normals the manifold is not continuous in the pose, so even the last bit
/// of the pose matters).
///
/// # Errors
/// What the world would refuse, on which parry can panic (its GJK asserts finite bounds):
/// [`CollisionError::InvalidPrediction`] for a `prediction` that is negative, NaN or
/// infinite, and the error of [`check_pose`](crate::check_pose),
/// [`check_shape`](crate::check_shape) or [`check_bounds`] for a mesh
/// with NaN or out-of-range vertices, or reaching beyond
/// ±[`MAX_COORDINATE`](crate::MAX_COORDINATE) at its pose grown by `prediction`.
pub fn mesh_mesh_triangle_pairs(
    mesh1: &parry3d::shape::TriMesh,
    pose1: &Isometry3<f32>,
    mesh2: &parry3d::shape::TriMesh,
    pose2: &Isometry3<f32>,
    prediction: f32,
) -> Result<Vec<(u32, u32, f32)>, CollisionError> {
    check_prediction(prediction)?;
    check_object(mesh1, pose1, prediction)?;
    check_object(mesh2, pose2, prediction)?;
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
    Ok(out)
}

/// Every pair of triangles `t1 < t2` of one mesh that share no vertex and whose convex-convex
/// manifold has a point within `prediction`: all `n²/2` pairs, fresh.
///
/// # Errors
/// What the world would refuse for a deformable mesh, on which parry can panic (its GJK
/// asserts finite bounds): [`CollisionError::InvalidPrediction`] for a `prediction` that is
/// negative, NaN or infinite; [`CollisionError::DegenerateShape`] (no triangle, an index out
/// of range, a NaN, infinite or out-of-range vertex) or [`CollisionError::TooMany`] from the
/// buffers' check; [`CollisionError::OutOfRange`] when the vertices' box grown by
/// `prediction` reaches beyond ±[`MAX_COORDINATE`](crate::MAX_COORDINATE).
pub fn self_contacts(
    vertices: &[Point3<f32>],
    indices: &[[u32; 3]],
    prediction: f32,
) -> Result<Vec<(u32, u32, Manifold)>, CollisionError> {
    check_prediction(prediction)?;
    check_mesh_buffers(vertices, indices)?;
    check_bounds(&points_box(vertices, prediction))?;
    let n = indices.len() as u32;
    let mut out = Vec::new();
    for t1 in 0..n {
        for t2 in t1 + 1..n {
            if adjacent(&indices[t1 as usize], &indices[t2 as usize]) {
                continue;
            }
            let (Some(a), Some(b)) = (
                mesh_triangle(vertices, indices, t1),
                mesh_triangle(vertices, indices, t2),
            ) else {
                continue;
            };
            if let Some(m) = triangles_manifold(&a, &b, t1, t2, prediction) {
                out.push((t1, t2, m));
            }
        }
    }
    Ok(out)
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

    /// An object the world refuses gives `None` and is left out of `contact_pairs`, where
    /// parry panicked: coordinates near `f32::MAX` (`sqnab != 0.0` in `point_segment.rs`), a
    /// triangle reaching 3e38 (`min_bound.is_finite()` in GJK), a convex hull with no face
    /// (index out of bounds in `local_support_feature`). The prediction distance counts, as
    /// in the world: two balls near `MAX_COORDINATE` are in range at 0 and out at 2000.
    #[test]
    fn objects_the_world_refuses_give_none() {
        use crate::{CollisionError, CollisionWorld, MAX_COORDINATE};
        use nalgebra::{Translation3, UnitQuaternion};
        let tiny = 1.0e-8;
        let hull = SharedShape::convex_hull(&[
            Point3::origin(),
            Point3::new(tiny, 0.0, 0.0),
            Point3::new(0.0, tiny, 0.0),
            Point3::new(0.0, 0.0, tiny),
        ])
        .unwrap();
        let tilted = Isometry3::from_parts(
            Translation3::new(0.3, 0.0, 0.0),
            UnitQuaternion::from_euler_angles(1.0, 2.0, 3.0),
        );
        let near = MAX_COORDINATE - 1000.0;
        let objects = vec![
            (Isometry3::identity(), SharedShape::cuboid(1.0, 1.0, 1.0)),
            (
                Isometry3::translation(1.5, 0.0, 0.0),
                SharedShape::ball(1.0),
            ),
            (
                Isometry3::translation(-f32::MAX, 0.0, 0.0),
                SharedShape::ball(1.0),
            ),
            (
                Isometry3::translation(f32::MAX, 0.0, 0.0),
                SharedShape::capsule_y(1.0e-45, 1.0),
            ),
            (
                tilted,
                SharedShape::segment(Point3::new(0.0, -1.0, 0.0), Point3::new(0.0, 1.0, 0.0)),
            ),
            (
                Isometry3::identity(),
                SharedShape::triangle(
                    Point3::origin(),
                    Point3::new(1.0, 0.0, 0.0),
                    Point3::new(0.0, 3.0e38, 0.0),
                ),
            ),
            (Isometry3::identity(), hull),
            (
                Isometry3::translation(near, 0.0, 0.0),
                SharedShape::ball(1.0),
            ),
            (
                Isometry3::translation(near, 0.0, 0.0),
                SharedShape::ball(1.0),
            ),
        ];
        let refused = [2, 3, 5, 6];
        for (i, j) in [(2, 3), (4, 5), (0, 6), (6, 1), (0, 2), (3, 1), (0, 5)] {
            assert!(pair(&objects, i, j, 0.0).is_none(), "({i}, {j})");
        }
        assert!(pair(&objects, 0, 1, 0.0).is_some());
        assert!(pair(&objects, 0, 4, 0.0).is_some());
        assert!(pair(&objects, 7, 8, 0.0).is_some());
        assert!(pair(&objects, 7, 8, 2000.0).is_none());
        let found = contact_pairs(&objects, 0.0);
        let pairs: Vec<(usize, usize)> = found.iter().map(|p| (p.0, p.1)).collect();
        assert!(pairs.contains(&(0, 1)) && pairs.contains(&(0, 4)) && pairs.contains(&(7, 8)));
        assert!(pairs
            .iter()
            .all(|(i, j)| !refused.contains(i) && !refused.contains(j)));
        let par: Vec<(usize, usize)> = par_contact_pairs(&objects, 0.0)
            .iter()
            .map(|p| (p.0, p.1))
            .collect();
        assert_eq!(pairs, par);
        // The world draws the same lines.
        let mut world = CollisionWorld::new();
        for (k, (pose, shape)) in objects.iter().enumerate() {
            let result = world.insert(shape.clone(), *pose, k);
            assert_eq!(
                result.is_err(),
                refused.contains(&k),
                "object {k}: {result:?}"
            );
        }
        world.update(0.0).unwrap();
        assert_eq!(world.update(2000.0), Err(CollisionError::OutOfRange));
    }
}
