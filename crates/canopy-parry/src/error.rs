//! The error type of the collision world: stale handles, invalid poses, degenerate or
//! unsupported shapes, bad update parameters.

use thiserror::Error;

use crate::handle::ObjectHandle;

/// Why a collision-world operation was refused. On error the world is unchanged.
#[derive(Clone, Debug, PartialEq, Error)]
pub enum CollisionError {
    /// The handle names an object that was removed (or never existed in this world).
    #[error("stale or unknown object handle {0:?}")]
    StaleHandle(ObjectHandle),
    /// A pose with a NaN or infinite component, or a rotation that is not a unit quaternion.
    #[error("invalid pose: translation must be finite and rotation a finite unit quaternion")]
    InvalidPose,
    /// A shape with NaN / infinite parameters, a non-positive size, broken mesh indices, or a
    /// convex polyhedron without faces.
    #[error("degenerate shape: {0}")]
    DegenerateShape(String),
    /// A shape type the world does not handle (half-spaces, height fields, polylines, voxels,
    /// custom shapes, composite parts of a compound).
    #[error("unsupported shape type: {0}")]
    UnsupportedShape(String),
    /// The shape placed at the given pose has a bounding box that is not finite or reaches
    /// beyond ±[`MAX_COORDINATE`](crate::MAX_COORDINATE) (too far away or too large for `f32`
    /// geometry).
    #[error(
        "the object's bounding box is not finite or reaches beyond ±{}",
        crate::MAX_COORDINATE
    )]
    OutOfRange,
    /// The prediction distance given to `update` is negative, NaN or infinite.
    #[error("invalid prediction distance {0}: it must be finite and >= 0")]
    InvalidPrediction(f32),
    /// A deformable-mesh operation on an object that is not a deformable mesh.
    #[error("object {0:?} is not a deformable mesh")]
    NotDeformable(ObjectHandle),
    /// New vertices for a deformable mesh, but not as many as it has.
    #[error("expected {expected} vertices, got {got}")]
    VertexCountMismatch {
        /// Vertex count of the mesh.
        expected: usize,
        /// Number of vertices given.
        got: usize,
    },
    /// More objects (or triangles) than `u32` indices can address.
    #[error("too many objects or triangles")]
    TooMany,
}
