//! Self-collision of a deformable mesh: pairs of triangles that share no vertex, culled by the
//! mesh's refit BVH (`self_pairs`), then parry's convex-convex manifold on each survivor.

use canopy_core::Bvh;
use nalgebra::{Isometry3, Point3};
use parry3d::query::{DefaultQueryDispatcher, PersistentQueryDispatcher};
use rayon::prelude::*;

use crate::handle::ObjectHandle;
use crate::pair::Manifold;
use crate::parts::mesh_triangle;
use crate::validate::{check_bounds, check_prediction, points_box};
use parry3d::shape::Triangle;

/// Two non-adjacent triangles of one deformable mesh in contact (within the prediction
/// distance). The manifold is in the mesh's local frame; `triangle1 < triangle2`.
#[derive(Clone, Debug)]
pub struct SelfContact {
    /// The deformable mesh.
    pub object: ObjectHandle,
    /// The first triangle (index into the mesh's index buffer).
    pub triangle1: u32,
    /// The second triangle, `> triangle1`.
    pub triangle2: u32,
    /// parry's manifold for the two triangles (`subshape1`, `subshape2` are the triangles).
    pub manifold: Manifold,
}

/// `true` when triangles `a` and `b` share a vertex index.
#[inline]
pub fn adjacent(a: &[u32; 3], b: &[u32; 3]) -> bool {
    a.iter().any(|v| b.contains(v))
}

/// The manifold of triangles `t1` and `t2` of a mesh (both in the mesh's frame), or `None`
/// when it has no point within `prediction`. `None` also, without calling parry (whose GJK
/// asserts finite bounds), for what the collision world would refuse in these two triangles:
/// a triangle index or a vertex index out of range, a `prediction` that is negative, NaN or
/// infinite, a vertex with a NaN or infinite coordinate, or the two triangles' box grown by
/// `prediction` reaching beyond ±[`MAX_COORDINATE`](crate::MAX_COORDINATE).
///
/// ```
/// use canopy_parry::triangle_pair_manifold;
/// use nalgebra::Point3;
/// let mut vertices = vec![
///     Point3::new(0.0, 0.0, 0.0), Point3::new(1.0, 0.0, 0.0), Point3::new(0.0, 1.0, 0.0),
///     Point3::new(0.0, 0.0, 0.01), Point3::new(1.0, 0.0, 0.01), Point3::new(0.0, 1.0, 0.01),
/// ];
/// let indices = [[0, 1, 2], [3, 4, 5]];
/// assert!(triangle_pair_manifold(&vertices, &indices, 0, 1, 0.1).is_some());
/// assert!(triangle_pair_manifold(&vertices, &indices, 0, 1, -1.0).is_none());
/// vertices[4] = Point3::new(f32::MAX, -f32::MAX, 0.0);
/// assert!(triangle_pair_manifold(&vertices, &indices, 0, 1, 0.1).is_none());
/// ```
pub fn triangle_pair_manifold(
    vertices: &[Point3<f32>],
    indices: &[[u32; 3]],
    t1: u32,
    t2: u32,
    prediction: f32,
) -> Option<Manifold> {
    let a = mesh_triangle(vertices, indices, t1)?;
    let b = mesh_triangle(vertices, indices, t2)?;
    let corners = [a.a, a.b, a.c, b.a, b.b, b.c];
    if check_prediction(prediction).is_err()
        || check_bounds(&points_box(&corners, prediction)).is_err()
    {
        return None;
    }
    triangles_manifold(&a, &b, t1, t2, prediction)
}

/// [`triangle_pair_manifold`] of two triangles the caller has checked (those of a mesh the
/// world accepted, at a prediction distance it accepted).
pub(crate) fn triangles_manifold(
    a: &Triangle,
    b: &Triangle,
    t1: u32,
    t2: u32,
    prediction: f32,
) -> Option<Manifold> {
    let mut manifold = Manifold::with_data(t1, t2, ());
    DefaultQueryDispatcher
        .contact_manifold_convex_convex(
            &Isometry3::identity(),
            a,
            b,
            None,
            None,
            prediction,
            &mut manifold,
        )
        .ok()?;
    crate::narrow::in_contact(std::slice::from_ref(&manifold), prediction).then_some(manifold)
}

/// The self-contacts of a mesh whose `tree` holds its triangle boxes grown by at least
/// `prediction`, sorted by triangle pair.
pub(crate) fn self_contacts(
    object: ObjectHandle,
    vertices: &[Point3<f32>],
    indices: &[[u32; 3]],
    tree: &Bvh,
    prediction: f32,
) -> Vec<SelfContact> {
    let mut candidates = Vec::new();
    tree.self_pairs(|a, b| {
        if !adjacent(&indices[a as usize], &indices[b as usize]) {
            candidates.push((a.min(b), a.max(b)));
        }
    });
    candidates.sort_unstable();
    candidates
        .par_iter()
        .filter_map(|&(t1, t2)| {
            let a = mesh_triangle(vertices, indices, t1)?;
            let b = mesh_triangle(vertices, indices, t2)?;
            let manifold = triangles_manifold(&a, &b, t1, t2, prediction)?;
            Some(SelfContact {
                object,
                triangle1: t1,
                triangle2: t2,
                manifold,
            })
        })
        .collect()
}
