//! Self-collision of a deformable mesh: pairs of triangles that share no vertex, culled by the
//! mesh's refit BVH (`self_pairs`), then parry's convex-convex manifold on each survivor.

use canopy_core::Bvh;
use nalgebra::{Isometry3, Point3};
use parry3d::query::{DefaultQueryDispatcher, PersistentQueryDispatcher};
use rayon::prelude::*;

use crate::handle::ObjectHandle;
use crate::pair::Manifold;
use crate::parts::mesh_triangle;

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
/// when it has no point within `prediction`.
pub fn triangle_pair_manifold(
    vertices: &[Point3<f32>],
    indices: &[[u32; 3]],
    t1: u32,
    t2: u32,
    prediction: f32,
) -> Option<Manifold> {
    let a = mesh_triangle(vertices, indices, t1)?;
    let b = mesh_triangle(vertices, indices, t2)?;
    let mut manifold = Manifold::with_data(t1, t2, ());
    DefaultQueryDispatcher
        .contact_manifold_convex_convex(
            &Isometry3::identity(),
            &a,
            &b,
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
            let manifold = triangle_pair_manifold(vertices, indices, t1, t2, prediction)?;
            Some(SelfContact {
                object,
                triangle1: t1,
                triangle2: t2,
                manifold,
            })
        })
        .collect()
}
