//! Input checks: poses (finite, unit rotation), shapes (finite, non-degenerate, of a supported
//! type) and deformable-mesh buffers. Everything the world accepts has passed through here, so
//! parry and canopy-core never see NaN or a broken index.

use canopy_core::Aabb;
use nalgebra::{Isometry3, Point3, Vector3};
use parry3d::bounding_volume::BoundingVolume;
use parry3d::shape::{ConvexPolyhedron, Shape, TypedShape};

use crate::convert::to_canopy;
use crate::error::CollisionError;

/// Largest coordinate magnitude of an object's world-space bounding box (prediction margin
/// included). Beyond it `f32` spacing exceeds 8 units, and parry's GJK/EPA, which multiplies up
/// to four lengths together (squared norms of cross products), overflows to infinity and
/// panics; such objects are refused with [`CollisionError::OutOfRange`] instead.
pub const MAX_COORDINATE: f32 = 1.0e8;

/// Checks that a world-space box is valid and within ±[`MAX_COORDINATE`].
pub fn check_bounds(aabb: &Aabb) -> Result<(), CollisionError> {
    let inside = |c: f32| c.abs() <= MAX_COORDINATE;
    if aabb.is_valid() && aabb.min.iter().chain(aabb.max.iter()).all(|&c| inside(c)) {
        Ok(())
    } else {
        Err(CollisionError::OutOfRange)
    }
}

/// Checks a prediction distance: finite and `>= 0`, else
/// [`CollisionError::InvalidPrediction`] (`CollisionWorld::update` and `brute_force`).
pub(crate) fn check_prediction(prediction: f32) -> Result<(), CollisionError> {
    if prediction.is_finite() && prediction >= 0.0 {
        Ok(())
    } else {
        Err(CollisionError::InvalidPrediction(prediction))
    }
}

/// The box of `points` grown by `margin`, for [`check_bounds`] (not valid when a coordinate
/// is NaN or infinite, or when there is no point).
pub(crate) fn points_box(points: &[Point3<f32>], margin: f32) -> Aabb {
    // `merge` keeps the other side of a NaN comparison: NaN points are refused first.
    if points.iter().any(|p| !finite_point(p)) {
        return Aabb::EMPTY;
    }
    Aabb::from_points(points).loosened(margin)
}

/// The box of `shape` placed at `pose`, grown by `margin`: the box the world keeps for a
/// shape object and checks with [`check_bounds`].
pub(crate) fn shape_aabb(shape: &dyn Shape, pose: &Isometry3<f32>, margin: f32) -> Aabb {
    to_canopy(&shape.compute_aabb(pose).loosened(margin))
}

/// The checks the world makes on a shape object: [`check_pose`], [`check_shape`] (composites
/// allowed), and [`check_bounds`] on its box in its own frame and on its box at `pose` grown
/// by `margin` (the prediction distance).
pub(crate) fn check_object(
    shape: &dyn Shape,
    pose: &Isometry3<f32>,
    margin: f32,
) -> Result<(), CollisionError> {
    check_pose(pose)?;
    check_shape(shape, true)?;
    check_bounds(&shape_aabb(shape, &Isometry3::identity(), 0.0))?;
    check_bounds(&shape_aabb(shape, pose, margin))
}

/// Largest accepted deviation of a rotation quaternion's norm from 1.
const UNIT_TOLERANCE: f32 = 1.0e-4;

/// Checks that `pose` has a finite translation and a finite unit rotation.
pub fn check_pose(pose: &Isometry3<f32>) -> Result<(), CollisionError> {
    let q = pose.rotation.quaternion();
    let finite = pose.translation.vector.iter().all(|c| c.is_finite())
        && q.coords.iter().all(|c| c.is_finite());
    if !finite || (q.norm() - 1.0).abs() > UNIT_TOLERANCE {
        return Err(CollisionError::InvalidPose);
    }
    Ok(())
}

fn degenerate(what: &str) -> CollisionError {
    CollisionError::DegenerateShape(what.to_string())
}

fn finite_point(p: &Point3<f32>) -> bool {
    p.coords.iter().all(|c| c.is_finite())
}

/// `true` when every coordinate of `p` is finite and within ±[`MAX_COORDINATE`].
pub fn in_range_point(p: &Point3<f32>) -> bool {
    p.coords.iter().all(|c| c.abs() <= MAX_COORDINATE)
}

fn positive(x: f32) -> bool {
    x.is_finite() && x > 0.0
}

fn positive_vector(v: &Vector3<f32>) -> bool {
    v.iter().all(|&c| positive(c))
}

fn border(radius: f32) -> Result<(), CollisionError> {
    if radius.is_finite() && radius >= 0.0 {
        Ok(())
    } else {
        Err(degenerate("border radius must be finite and >= 0"))
    }
}

/// Checks the vertex and index buffers of a triangle mesh: at least one triangle, finite
/// vertices within ±[`MAX_COORDINATE`], indices in range, a triangle count that fits `u32`.
pub fn check_mesh_buffers(
    vertices: &[Point3<f32>],
    indices: &[[u32; 3]],
) -> Result<(), CollisionError> {
    if indices.is_empty() {
        return Err(degenerate("a triangle mesh needs at least one triangle"));
    }
    if indices.len() >= u32::MAX as usize || vertices.len() >= u32::MAX as usize {
        return Err(CollisionError::TooMany);
    }
    if !vertices.iter().all(in_range_point) {
        return Err(degenerate(
            "mesh vertex with a NaN, infinite or out-of-range coordinate",
        ));
    }
    let n = vertices.len();
    if indices.iter().flatten().any(|&i| i as usize >= n) {
        return Err(degenerate("mesh index out of range"));
    }
    Ok(())
}

/// Checks that `shape` is of a supported type with finite, non-degenerate parameters.
/// `allow_composite` is false for the parts of a compound.
pub fn check_shape(shape: &dyn Shape, allow_composite: bool) -> Result<(), CollisionError> {
    match shape.as_typed_shape() {
        TypedShape::Ball(b) => {
            if !positive(b.radius) {
                return Err(degenerate("ball radius must be finite and > 0"));
            }
        }
        TypedShape::Cuboid(c) => {
            if !positive_vector(&c.half_extents) {
                return Err(degenerate("cuboid half-extents must be finite and > 0"));
            }
        }
        TypedShape::Capsule(c) => {
            if !finite_point(&c.segment.a) || !finite_point(&c.segment.b) || !positive(c.radius) {
                return Err(degenerate(
                    "capsule needs finite end points and a radius > 0",
                ));
            }
        }
        TypedShape::Segment(s) => {
            if !finite_point(&s.a) || !finite_point(&s.b) || s.a == s.b {
                return Err(degenerate("segment needs two distinct finite end points"));
            }
        }
        TypedShape::Triangle(t) => check_triangle(t)?,
        TypedShape::RoundTriangle(t) => {
            border(t.border_radius)?;
            check_triangle(&t.inner_shape)?;
        }
        TypedShape::RoundCuboid(c) => {
            border(c.border_radius)?;
            if !positive_vector(&c.inner_shape.half_extents) {
                return Err(degenerate("cuboid half-extents must be finite and > 0"));
            }
        }
        TypedShape::Cylinder(c) => {
            if !positive(c.half_height) || !positive(c.radius) {
                return Err(degenerate("cylinder needs a half-height and radius > 0"));
            }
        }
        TypedShape::RoundCylinder(c) => {
            border(c.border_radius)?;
            if !positive(c.inner_shape.half_height) || !positive(c.inner_shape.radius) {
                return Err(degenerate("cylinder needs a half-height and radius > 0"));
            }
        }
        TypedShape::Cone(c) => {
            if !positive(c.half_height) || !positive(c.radius) {
                return Err(degenerate("cone needs a half-height and radius > 0"));
            }
        }
        TypedShape::RoundCone(c) => {
            border(c.border_radius)?;
            if !positive(c.inner_shape.half_height) || !positive(c.inner_shape.radius) {
                return Err(degenerate("cone needs a half-height and radius > 0"));
            }
        }
        TypedShape::ConvexPolyhedron(p) => check_polyhedron(p)?,
        TypedShape::RoundConvexPolyhedron(p) => {
            border(p.border_radius)?;
            check_polyhedron(&p.inner_shape)?;
        }
        TypedShape::TriMesh(m) if allow_composite => {
            check_mesh_buffers(m.vertices(), m.indices())?;
        }
        TypedShape::Compound(c) if allow_composite => {
            if c.shapes().len() >= u32::MAX as usize {
                return Err(CollisionError::TooMany);
            }
            for (pose, part) in c.shapes() {
                check_pose(pose).map_err(|_| degenerate("compound part with an invalid pose"))?;
                check_shape(&**part, false)?;
            }
        }
        other => {
            let name = format!("{other:?}");
            let name = name.split('(').next().unwrap_or("unknown").to_string();
            return Err(CollisionError::UnsupportedShape(name));
        }
    }
    Ok(())
}

/// A convex polyhedron needs at least 4 finite points and at least one face: parry builds
/// one with no face from a hull too small for its tolerances (a tetrahedron of side 1e-8),
/// and its polygonal-feature code then indexes the first face and panics.
fn check_polyhedron(p: &ConvexPolyhedron) -> Result<(), CollisionError> {
    if p.points().len() < 4 || !p.points().iter().all(finite_point) {
        return Err(degenerate("convex polyhedron needs >= 4 finite points"));
    }
    if p.faces().is_empty() {
        return Err(degenerate(
            "convex polyhedron has no face (points too close together)",
        ));
    }
    Ok(())
}

fn check_triangle(t: &parry3d::shape::Triangle) -> Result<(), CollisionError> {
    if !finite_point(&t.a) || !finite_point(&t.b) || !finite_point(&t.c) || t.normal().is_none() {
        return Err(degenerate("triangle needs finite, non-collinear vertices"));
    }
    Ok(())
}
