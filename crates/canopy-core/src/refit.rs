//! Refit: new primitive boxes, same topology, in one reverse pass over the depth-first array
//! (children always follow their parent, so walking backwards visits children first).

use crate::aabb::Aabb;
use crate::build::{first_invalid, Bounds};
use crate::bvh::{Bvh, PrimBounds};
use crate::error::BvhError;

impl Bvh {
    /// Replaces every primitive's box (`aabbs[i]` for primitive `i`) and refits all nodes.
    ///
    /// The topology is kept, so query cost grows as boxes drift from where the tree was built;
    /// rebuild when [`crate::BvhStats::sah_cost`] has grown too much.
    ///
    /// # Errors
    /// [`BvhError::LengthMismatch`] unless `aabbs.len() == self.len()`, and
    /// [`BvhError::InvalidAabb`] for a NaN, infinite or inverted box. On error the tree is
    /// unchanged.
    ///
    /// # Example
    /// ```
    /// use canopy_core::{Aabb, Bvh, BuildOptions};
    /// let mut boxes = vec![Aabb::from_arrays([0.0; 3], [1.0; 3]); 10];
    /// let mut bvh = Bvh::build(&boxes, BuildOptions::default())?;
    /// boxes[3] = Aabb::from_arrays([5.0; 3], [6.0; 3]);
    /// bvh.refit(&boxes)?;
    /// assert_eq!(bvh.root_aabb().unwrap().max.x, 6.0);
    /// assert!(bvh.validate_with_primitives(&boxes).is_ok());
    /// # Ok::<(), canopy_core::BvhError>(())
    /// ```
    pub fn refit(&mut self, aabbs: &[Aabb]) -> Result<(), BvhError> {
        if aabbs.len() != self.len() {
            return Err(BvhError::LengthMismatch {
                expected: self.len(),
                got: aabbs.len(),
            });
        }
        if let Some(index) = first_invalid(aabbs) {
            return Err(BvhError::InvalidAabb { index });
        }
        for (slot, &prim) in self.prim_bounds.iter_mut().zip(&self.prim_indices) {
            *slot = PrimBounds::from_aabb(&aabbs[prim as usize]);
        }
        self.refit_nodes();
        Ok(())
    }

    /// Replaces the boxes of the primitives listed in `changes` (`(primitive, new box)`) and
    /// refits every node: the cheap path when only some primitives moved (one pass over the
    /// changes and one over the nodes, none over the other primitives).
    ///
    /// # Errors
    /// [`BvhError::UnknownPrimitive`] for an index `>= self.len()` and
    /// [`BvhError::InvalidAabb`] (with the position in `changes`) for an invalid box. On error
    /// the tree is unchanged.
    ///
    /// ```
    /// use canopy_core::{Aabb, Bvh, BuildOptions};
    /// let mut boxes = vec![Aabb::from_arrays([0.0; 3], [1.0; 3]); 10];
    /// let mut bvh = Bvh::build(&boxes, BuildOptions::default())?;
    /// boxes[7] = Aabb::from_arrays([5.0; 3], [6.0; 3]);
    /// bvh.refit_primitives(&[(7, boxes[7])])?;
    /// assert!(bvh.validate_with_primitives(&boxes).is_ok());
    /// # Ok::<(), canopy_core::BvhError>(())
    /// ```
    pub fn refit_primitives(&mut self, changes: &[(u32, Aabb)]) -> Result<(), BvhError> {
        for (i, (prim, aabb)) in changes.iter().enumerate() {
            if *prim as usize >= self.len() {
                return Err(BvhError::UnknownPrimitive {
                    index: *prim,
                    len: self.len(),
                });
            }
            if !aabb.is_valid() {
                return Err(BvhError::InvalidAabb { index: i });
            }
        }
        if changes.is_empty() {
            return Ok(());
        }
        if self.slot_of.len() != self.prim_indices.len() {
            self.slot_of = vec![0; self.prim_indices.len()];
            for (slot, &p) in self.prim_indices.iter().enumerate() {
                self.slot_of[p as usize] = slot as u32;
            }
        }
        for (prim, aabb) in changes {
            self.prim_bounds[self.slot_of[*prim as usize] as usize] = PrimBounds::from_aabb(aabb);
        }
        self.refit_nodes();
        Ok(())
    }

    /// Recomputes every node box from the stored primitive boxes.
    pub(crate) fn refit_nodes(&mut self) {
        for i in (0..self.nodes.len()).rev() {
            let node = self.nodes[i];
            let b = if node.is_leaf() {
                Bounds::of_prims(&self.prim_bounds[node.leaf_range()])
            } else {
                let (l, r) = (&self.nodes[i + 1], &self.nodes[node.right() as usize]);
                Bounds {
                    min: l.min,
                    max: l.max,
                }
                .merged(&Bounds {
                    min: r.min,
                    max: r.max,
                })
            };
            self.nodes[i].min = b.min;
            self.nodes[i].max = b.max;
        }
        if let Some(wide) = self.wide.get_mut() {
            crate::bvh::refresh_wide(&self.nodes, wide);
        }
        if let Some(r4) = self.ray4.get_mut() {
            r4.refresh(&self.nodes);
        }
    }
}
