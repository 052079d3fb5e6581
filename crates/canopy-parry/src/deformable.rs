//! A deformable triangle mesh: vertices that move every update, fixed indices, and a
//! canopy-core BVH over the triangles that is refit (never rebuilt) when the vertices move.

use canopy_core::{Aabb, Bvh};
use nalgebra::Point3;

use crate::error::CollisionError;
use crate::parts::{build_part_tree, mesh_local_aabb, mesh_triangle_aabbs, Parts};
use crate::validate::{check_mesh_buffers, in_range_point};
use parry3d::bounding_volume::Aabb as ParryAabb;

/// The state of one deformable mesh of the world.
pub(crate) struct DeformableMesh {
    pub vertices: Vec<Point3<f32>>,
    pub indices: Vec<[u32; 3]>,
    /// BVH over the triangle boxes grown by `margin` (the last update's prediction).
    pub tree: Bvh,
    pub margin: f32,
    /// Exact local box of the triangles, as of the last refit.
    pub local_aabb: ParryAabb,
    /// The vertices changed since the tree was last refit.
    pub dirty: bool,
}

impl DeformableMesh {
    /// Checks the buffers and builds the triangle tree (no margin yet).
    pub fn new(vertices: Vec<Point3<f32>>, indices: Vec<[u32; 3]>) -> Result<Self, CollisionError> {
        check_mesh_buffers(&vertices, &indices)?;
        let boxes = mesh_triangle_aabbs(&vertices, &indices, 0.0);
        let tree = build_part_tree(&boxes)?;
        let local_aabb = mesh_local_aabb(&vertices, &indices);
        Ok(Self {
            local_aabb,
            vertices,
            indices,
            tree,
            margin: 0.0,
            dirty: false,
        })
    }

    /// Replaces the vertices (same count, all finite and within ±[`MAX_COORDINATE`](crate::MAX_COORDINATE)).
    pub fn set_vertices(&mut self, vertices: &[Point3<f32>]) -> Result<(), CollisionError> {
        if vertices.len() != self.vertices.len() {
            return Err(CollisionError::VertexCountMismatch {
                expected: self.vertices.len(),
                got: vertices.len(),
            });
        }
        if !vertices.iter().all(in_range_point) {
            return Err(CollisionError::DegenerateShape(
                "mesh vertex with a NaN, infinite or out-of-range coordinate".into(),
            ));
        }
        self.vertices.copy_from_slice(vertices);
        self.dirty = true;
        Ok(())
    }

    /// The triangle boxes for `margin`, when the tree needs a refit for it (`None`: up to date).
    pub fn pending_boxes(&self, margin: f32) -> Option<Vec<Aabb>> {
        (self.dirty || margin != self.margin)
            .then(|| mesh_triangle_aabbs(&self.vertices, &self.indices, margin))
    }

    /// Refits the tree over `boxes` (from [`Self::pending_boxes`]).
    pub fn apply_boxes(&mut self, boxes: &[Aabb], margin: f32) -> Result<(), CollisionError> {
        self.tree
            .refit(boxes)
            .map_err(|_| CollisionError::OutOfRange)?;
        self.margin = margin;
        self.local_aabb = mesh_local_aabb(&self.vertices, &self.indices);
        self.dirty = false;
        Ok(())
    }

    /// The parts view used by the narrow phase.
    pub fn parts(&self) -> Parts<'_> {
        Parts::Mesh {
            vertices: &self.vertices,
            indices: &self.indices,
            local_aabb: self.local_aabb,
        }
    }
}
