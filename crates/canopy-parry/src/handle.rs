//! `ObjectHandle`: a stable, generation-checked name for an object of a collision world.

/// Names one object of a [`crate::CollisionWorld`]. Handles stay valid until the object is
/// removed; the slot may then be reused, but with a new generation, so an old handle is
/// reported as [`crate::CollisionError::StaleHandle`] instead of naming the newcomer.
///
/// Handles order by slot index, then generation: pairs are always reported with
/// `object1 < object2`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct ObjectHandle {
    index: u32,
    generation: u32,
}

impl ObjectHandle {
    pub(crate) fn new(index: u32, generation: u32) -> Self {
        Self { index, generation }
    }

    /// The slot index (dense, reused after removal).
    #[inline]
    pub fn index(&self) -> u32 {
        self.index
    }

    /// The generation of the slot when this object was inserted.
    #[inline]
    pub fn generation(&self) -> u32 {
        self.generation
    }
}
