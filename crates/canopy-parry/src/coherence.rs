//! `Coherence`: whether manifolds and workspaces carry over from one update to the next.

/// How the narrow phase treats the previous update's manifolds.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Coherence {
    /// Keep manifolds and workspaces per pair (and per triangle / part pair) across updates,
    /// so parry can update contacts cheaply when the relative motion is small. The pairs of a
    /// deformable mesh start afresh in an update after its vertices moved (parry would keep
    /// the old triangles' contacts: their pose in the mesh's frame does not change). The
    /// default.
    #[default]
    Persistent,
    /// Compute every manifold from scratch each update: the results are then exactly those of
    /// a fresh parry call on the pair, at some cost in speed.
    Fresh,
}
