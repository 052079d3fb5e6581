//! Tree statistics: SAH cost, depth, node, leaf and primitive counts.

use crate::aabb::surface_area;
use crate::bvh::Bvh;

/// Shape and quality figures of a [`Bvh`], from [`Bvh::stats`].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct BvhStats {
    /// Number of primitives.
    pub primitives: usize,
    /// Number of nodes (interior and leaves).
    pub nodes: usize,
    /// Number of leaves.
    pub leaves: usize,
    /// Longest root-to-leaf path, in edges (0 for a single leaf or an empty tree).
    pub depth: usize,
    /// Largest leaf.
    pub max_leaf_size: usize,
    /// SAH cost with unit traversal and intersection costs: the expected number of node visits
    /// plus primitive tests of a random ray that hits the root box. Lower is better.
    pub sah_cost: f64,
}

impl Bvh {
    /// Statistics with unit SAH costs (see [`Bvh::sah_cost`]).
    ///
    /// ```
    /// use canopy_core::{Aabb, Bvh, BuildOptions};
    /// let boxes: Vec<Aabb> = (0..64).map(|i| {
    ///     let x = i as f32;
    ///     Aabb::from_arrays([x, 0.0, 0.0], [x + 1.0, 1.0, 1.0])
    /// }).collect();
    /// let s = Bvh::build(&boxes, BuildOptions::default())?.stats();
    /// assert_eq!(s.primitives, 64);
    /// assert!(s.sah_cost > 1.0 && s.depth >= 4);
    /// # Ok::<(), canopy_core::BvhError>(())
    /// ```
    pub fn stats(&self) -> BvhStats {
        let mut s = BvhStats {
            primitives: self.len(),
            nodes: self.nodes.len(),
            sah_cost: self.sah_cost(1.0, 1.0),
            ..Default::default()
        };
        if self.nodes.is_empty() {
            return s;
        }
        let mut stack = vec![(0usize, 0usize)];
        while let Some((i, d)) = stack.pop() {
            let node = &self.nodes[i];
            s.depth = s.depth.max(d);
            if node.is_leaf() {
                s.leaves += 1;
                s.max_leaf_size = s.max_leaf_size.max(node.count as usize);
            } else {
                stack.push((i + 1, d + 1));
                stack.push((node.right() as usize, d + 1));
            }
        }
        s
    }

    /// SAH cost: `sum over interior nodes of A(n)/A(root) * traversal_cost + sum over leaves of
    /// A(l)/A(root) * count(l) * intersection_cost`. 0 for an empty tree; for a root of zero
    /// area (all boxes at one point) the node count stands in for the area ratio.
    pub fn sah_cost(&self, traversal_cost: f64, intersection_cost: f64) -> f64 {
        let Some(root) = self.nodes.first() else {
            return 0.0;
        };
        let ra = surface_area(root.min, root.max);
        let inv = if ra > 0.0 { 1.0 / ra } else { 0.0 };
        self.nodes
            .iter()
            .map(|n| {
                let ratio = if ra > 0.0 {
                    surface_area(n.min, n.max) * inv
                } else {
                    1.0
                };
                if n.is_leaf() {
                    ratio * n.count as f64 * intersection_cost
                } else {
                    ratio * traversal_cost
                }
            })
            .sum()
    }
}
