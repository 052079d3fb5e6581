//! Composite geometry seen part by part: a parry `TriMesh` or `Compound` (through parry's
//! `CompositeShape`), or a deformable mesh's current triangles, together with the canopy-core
//! BVH over the parts' boxes in the composite's local frame.

use canopy_core::{Aabb, BuildOptions, Bvh};
use nalgebra::{Isometry3, Point3};
use parry3d::bounding_volume::Aabb as ParryAabb;
use parry3d::query::details::NormalConstraints;
use parry3d::shape::{CompositeShape, Shape, Triangle};

use crate::convert::to_canopy;
use crate::error::CollisionError;

/// The parts of one composite object.
#[derive(Clone, Copy)]
pub(crate) enum Parts<'a> {
    /// A parry composite shape (`TriMesh` or `Compound`): parts through `map_part_at`.
    Shape(&'a dyn CompositeShape),
    /// The current triangles of a deformable mesh (no pseudo-normals).
    Mesh {
        vertices: &'a [Point3<f32>],
        indices: &'a [[u32; 3]],
        /// Exact local box of the triangles (what parry's own mesh BVH would have as root).
        local_aabb: ParryAabb,
    },
}

/// The part's pose in the composite's frame (`None`: identity), its shape, and the normal
/// constraints parry attaches to it (a mesh triangle's pseudo-normals).
pub(crate) type PartFn<'f, R> =
    dyn FnMut(Option<&Isometry3<f32>>, &dyn Shape, Option<&dyn NormalConstraints>) -> R + 'f;

impl Parts<'_> {
    /// Calls `f` on part `i`.
    pub fn with_part<R>(&self, i: u32, f: &mut PartFn<'_, R>) -> Option<R> {
        match self {
            Parts::Shape(composite) => {
                let mut out = None;
                composite.map_part_at(i, &mut |pos, shape, normals| {
                    out = Some(f(pos, shape, normals));
                });
                out
            }
            Parts::Mesh {
                vertices, indices, ..
            } => {
                let tri = mesh_triangle(vertices, indices, i)?;
                Some(f(None, &tri, None))
            }
        }
    }

    /// Squared norm of the half-extents of the composite's local box: parry's composite-vs-
    /// composite routine traverses the larger side first, which decides how it composes the
    /// part poses (replicated so results match parry to the last bit).
    pub fn size_sq(&self) -> f32 {
        match self {
            Parts::Shape(composite) => composite.bvh().root_aabb().half_extents().norm_squared(),
            Parts::Mesh { local_aabb, .. } => local_aabb.half_extents().norm_squared(),
        }
    }

    /// Box of part `i` placed at `pose` (the composite's frame mapped by `pose`).
    pub fn part_aabb(&self, i: u32, pose: &Isometry3<f32>) -> Option<ParryAabb> {
        self.with_part(i, &mut |part_pos, shape, _| match part_pos {
            Some(p) => shape.compute_aabb(&(pose * p)),
            None => shape.compute_aabb(pose),
        })
    }
}

/// Triangle `i` of a vertex / index buffer (`None` when `i` is out of range).
pub(crate) fn mesh_triangle(
    vertices: &[Point3<f32>],
    indices: &[[u32; 3]],
    i: u32,
) -> Option<Triangle> {
    let [a, b, c] = *indices.get(i as usize)?;
    Some(Triangle::new(
        *vertices.get(a as usize)?,
        *vertices.get(b as usize)?,
        *vertices.get(c as usize)?,
    ))
}

/// The local-frame boxes of a parry composite's parts (triangles of a mesh, parts of a
/// compound).
pub(crate) fn composite_part_aabbs(shape: &dyn Shape) -> Vec<Aabb> {
    if let Some(mesh) = shape.as_trimesh() {
        mesh.triangles()
            .map(|t| to_canopy(&t.local_aabb()))
            .collect()
    } else if let Some(compound) = shape.as_compound() {
        compound.aabbs().iter().map(to_canopy).collect()
    } else {
        Vec::new()
    }
}

/// Boxes of a deformable mesh's triangles, grown by `margin`.
pub(crate) fn mesh_triangle_aabbs(
    vertices: &[Point3<f32>],
    indices: &[[u32; 3]],
    margin: f32,
) -> Vec<Aabb> {
    indices
        .iter()
        .map(|t| Aabb::from_points(t.iter().map(|&v| &vertices[v as usize])).loosened(margin))
        .collect()
}

/// Exact box of the triangles of a vertex / index buffer.
pub(crate) fn mesh_local_aabb(vertices: &[Point3<f32>], indices: &[[u32; 3]]) -> ParryAabb {
    let mut aabb = ParryAabb::new_invalid();
    for &v in indices.iter().flatten() {
        if let Some(p) = vertices.get(v as usize) {
            aabb.take_point(*p);
        }
    }
    aabb
}

/// Builds the BVH over part boxes.
pub(crate) fn build_part_tree(aabbs: &[Aabb]) -> Result<Bvh, CollisionError> {
    Bvh::build(aabbs, BuildOptions::default())
        .map_err(|_| CollisionError::DegenerateShape("part with an invalid bounding box".into()))
}
