//! `validate()`: checks every invariant of a [`Bvh`]; tests run it after every build and refit.

use crate::aabb::Aabb;
use crate::bvh::Bvh;
use crate::error::ValidationError;

macro_rules! ensure {
    ($cond:expr, $($msg:tt)*) => {
        if !$cond {
            return Err(ValidationError(format!($($msg)*)));
        }
    };
}

fn inside(inner_min: &[f32; 3], inner_max: &[f32; 3], min: &[f32; 3], max: &[f32; 3]) -> bool {
    (0..3).all(|a| min[a] <= inner_min[a] && inner_max[a] <= max[a])
}

impl Bvh {
    /// Checks the tree's invariants:
    /// * nodes are in depth-first order: the left child of node `i` is `i + 1`, the right child
    ///   comes after the whole left subtree, and a preorder walk visits `0, 1, 2, ...`;
    /// * every node box holds its children's boxes, every leaf box its primitives' boxes;
    /// * leaves are non-empty and their ranges tile the primitive array exactly once, in order;
    /// * every primitive index `0..len` appears exactly once, every stored box is valid;
    /// * the copies of the tree that queries and refits make on demand, where made, match it
    ///   (the wide array holds the node boxes, the maps of the partial refit the topology).
    ///
    /// # Example
    /// ```
    /// use canopy_core::{Aabb, Bvh, BuildOptions};
    /// let bvh = Bvh::build(&[Aabb::from_arrays([0.0; 3], [1.0; 3])], BuildOptions::default())?;
    /// bvh.validate().expect("a fresh tree is valid");
    /// # Ok::<(), canopy_core::BvhError>(())
    /// ```
    pub fn validate(&self) -> Result<(), ValidationError> {
        let n = self.prim_indices.len();
        ensure!(
            self.prim_bounds.len() == n,
            "{} boxes for {} primitives",
            self.prim_bounds.len(),
            n
        );
        if n == 0 {
            ensure!(
                self.nodes.is_empty(),
                "empty tree with {} nodes",
                self.nodes.len()
            );
            return Ok(());
        }
        ensure!(!self.nodes.is_empty(), "{n} primitives but no node");
        let mut seen = vec![false; n];
        for (slot, &p) in self.prim_indices.iter().enumerate() {
            ensure!((p as usize) < n, "slot {slot}: primitive {p} out of range");
            ensure!(!seen[p as usize], "primitive {p} appears twice");
            ensure!(
                self.refit.slot_of.is_empty()
                    || self.refit.slot_of.get(p as usize) == Some(&(slot as u32)),
                "primitive {p}: slot map does not point at slot {slot}"
            );
            seen[p as usize] = true;
            let b = &self.prim_bounds[slot];
            ensure!(
                Aabb::from_arrays(b.min, b.max).is_valid(),
                "slot {slot}: invalid box"
            );
        }

        // Preorder walk: must visit nodes 0, 1, 2, ... and leaves in slot order.
        let mut next_node = 0usize;
        let mut next_slot = 0usize;
        let mut stack = vec![0usize];
        while let Some(i) = stack.pop() {
            ensure!(
                i == next_node,
                "preorder visits node {i}, expected {next_node}"
            );
            ensure!(i < self.nodes.len(), "node index {i} out of range");
            next_node += 1;
            let node = &self.nodes[i];
            if node.is_leaf() {
                let r = node.leaf_range();
                ensure!(
                    r.start == next_slot,
                    "leaf {i} starts at slot {}, expected {next_slot}",
                    r.start
                );
                ensure!(r.end <= n, "leaf {i} ends past the primitive array");
                for s in r.clone() {
                    let b = &self.prim_bounds[s];
                    ensure!(
                        inside(&b.min, &b.max, &node.min, &node.max),
                        "leaf {i} does not hold slot {s}"
                    );
                }
                next_slot = r.end;
            } else {
                let (l, r) = (i + 1, node.right() as usize);
                ensure!(
                    r > l && r < self.nodes.len(),
                    "node {i}: bad right child {r}"
                );
                for c in [l, r] {
                    let c = &self.nodes[c];
                    ensure!(
                        inside(&c.min, &c.max, &node.min, &node.max),
                        "node {i} does not hold its child"
                    );
                }
                stack.push(r);
                stack.push(l);
            }
        }
        ensure!(
            next_node == self.nodes.len(),
            "{} nodes unreachable",
            self.nodes.len() - next_node
        );
        ensure!(next_slot == n, "leaves cover {next_slot} of {n} slots");
        // The copies and maps made on demand must match the tree.
        if let Some(wide) = self.wide.get() {
            ensure!(
                *wide == crate::bvh::make_wide(&self.nodes),
                "the wide array differs from the nodes"
            );
        }
        ensure!(
            self.refit.matches(&self.nodes, &self.prim_indices),
            "the refit maps differ from the tree"
        );
        Ok(())
    }

    /// [`Bvh::validate`], and also that the stored box of every primitive `i` equals `aabbs[i]`.
    pub fn validate_with_primitives(&self, aabbs: &[Aabb]) -> Result<(), ValidationError> {
        self.validate()?;
        ensure!(
            aabbs.len() == self.len(),
            "tree has {} primitives, {} boxes given",
            self.len(),
            aabbs.len()
        );
        for (slot, &p) in self.prim_indices.iter().enumerate() {
            let b = &self.prim_bounds[slot];
            ensure!(
                Aabb::from_arrays(b.min, b.max) == aabbs[p as usize],
                "primitive {p}: stored box differs from the input"
            );
        }
        Ok(())
    }
}
