//! Refit: new primitive boxes, same topology. Two paths:
//!
//! * Full ([`Bvh::refit`], and [`Bvh::refit_primitives`] when many primitives moved): one
//!   reverse pass over the depth-first array (children always follow their parent, so walking
//!   backwards visits children first), then a copy of every box into the wide array and the
//!   four-wide copy, where made.
//! * Partial ([`Bvh::refit_primitives`] when few primitives moved, a broadphase's usual
//!   step): the leaf of each changed primitive is marked in a bitset over the nodes (scratch
//!   kept in the tree), then the marked nodes are visited in *descending* index order
//!   (children before their parent again, as in the full pass) and each one is recomputed
//!   and marks its parent, so exactly the changed leaves and their ancestors are visited. An
//!   interior node visited writes its two children's boxes into its entry of the wide array
//!   (one cache line; the root's copies, `wide[0]`, are written with the root), and every
//!   node visited writes its box into the four-wide copy's lane that holds it, if any. The
//!   maps this needs (the leaf of each primitive, the parent and wide entry of each node:
//!   [`RefitMaps`]) are made by the first partial refit after a build.
//!
//! Every box the partial path visits is computed as the full pass computes it, and every box
//! it does not visit has inputs that did not change, so both paths give the same tree to the
//! bit: the same nodes and the same wide array. (One exception, of values: the SAH builder
//! may store a zero of the other sign than refit computes in a fresh tree, `-0.0` for `0.0`;
//! a partial refit keeps such a box where it does not reach, a full one recomputes it.)
//!
//! Marking a node's parent while visiting the node, rather than walking up from each leaf
//! first, and visiting every ancestor rather than stopping where the boxes stop changing
//! (both tried) measured fastest in time: no chain of dependent loads per change, no branch
//! on the boxes' values.

use crate::aabb::Aabb;
use crate::build::{first_invalid, Bounds};
use crate::bvh::{Bvh, Node, PrimBounds, Wide};
use crate::error::BvhError;

/// `refit_primitives` takes the partial path when `changes.len() * PARTIAL_FACTOR` is below
/// the number of nodes. Measured on random boxes (LBVH trees with leaves of 1, 4 and 8 and
/// SAH trees, over 4,000 and 50,000 boxes): in instructions (callgrind) the two paths cost
/// the same at about `changes = nodes / 2` (LBVH, leaves of 4) to `nodes / 3` (SAH); in time
/// the full pass, one streaming loop, does better than its instruction count, and on small
/// trees that fit the caches (4,000 boxes, LBVH) it wins from about `nodes / 4.5`. At
/// `nodes / 6` the partial path took 28-44% fewer instructions than the full one on every
/// tree measured, and no more time.
const PARTIAL_FACTOR: usize = 6;

/// The links from a node that the partial refit follows.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct Link {
    /// The parent node (the root: 0, never read).
    pub(crate) parent: u32,
    /// Interior node: the index of the [`Wide`] that holds its children (see [`Wide`]);
    /// leaf: 0, never read.
    pub(crate) wide: u32,
}

/// What [`Bvh::refit_primitives`] needs besides the tree, made by its first call after a
/// build that needs it and kept with the tree (a build starts with an empty one): the slot
/// map, for both paths ([`RefitMaps::make_slots`], one pass over the primitives), and the
/// rest, for the partial path only ([`RefitMaps::make_links`], one pass over the nodes).
/// 4 + 4 bytes per primitive and 8 bytes and a bit per node.
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct RefitMaps {
    /// The slot of each primitive (the inverse of `prim_indices`).
    pub(crate) slot_of: Vec<u32>,
    /// The leaf node of each primitive.
    pub(crate) leaf_of: Vec<u32>,
    /// Per node, its parent and its children's wide entry.
    pub(crate) links: Vec<Link>,
    /// One bit per node, the nodes still to recompute: scratch of the partial refit, all zero
    /// between calls.
    pub(crate) dirty: Vec<u64>,
}

impl RefitMaps {
    /// Makes `slot_of` for the primitive array `prim_indices`, unless made.
    pub(crate) fn make_slots(&mut self, prim_indices: &[u32]) {
        if self.slot_of.len() == prim_indices.len() {
            return;
        }
        self.slot_of = vec![0; prim_indices.len()];
        for (slot, &p) in prim_indices.iter().enumerate() {
            self.slot_of[p as usize] = slot as u32;
        }
    }

    /// Makes `leaf_of`, `links` and `dirty` for the depth-first `nodes` over the primitive
    /// array `prim_indices`, unless made.
    pub(crate) fn make_links(&mut self, nodes: &[Node], prim_indices: &[u32]) {
        if self.links.len() == nodes.len() && self.leaf_of.len() == prim_indices.len() {
            return;
        }
        let mut leaf_of = vec![0; prim_indices.len()];
        let mut links = vec![Link::default(); nodes.len()];
        // Interior nodes take the wide entries 1, 2, ... in depth-first order (`make_wide`).
        let mut w = 1u32;
        for (i, n) in nodes.iter().enumerate() {
            if n.is_leaf() {
                for &p in &prim_indices[n.leaf_range()] {
                    leaf_of[p as usize] = i as u32;
                }
            } else {
                links[i].wide = w;
                w += 1;
                links[i + 1].parent = i as u32;
                links[n.right() as usize].parent = i as u32;
            }
        }
        self.leaf_of = leaf_of;
        self.links = links;
        self.dirty = vec![0; nodes.len().div_ceil(64)];
    }

    /// `true` when the maps made so far are those of `nodes` over `prim_indices` (and the
    /// scratch bits are clear), for `validate`.
    pub(crate) fn matches(&self, nodes: &[Node], prim_indices: &[u32]) -> bool {
        let mut made = RefitMaps::default();
        made.make_slots(prim_indices);
        made.make_links(nodes, prim_indices);
        (self.slot_of.is_empty() || self.slot_of == made.slot_of)
            && (self.links.is_empty()
                || (self.leaf_of == made.leaf_of
                    && self.links == made.links
                    && self.dirty == made.dirty))
    }
}

/// The box of node `i` (`node`, a copy) from its primitives (leaf) or its children (interior):
/// the one expression both the full pass and the partial path compute.
#[inline(always)]
fn node_bounds(nodes: &[Node], prims: &[PrimBounds], i: usize, node: &Node) -> Bounds {
    if node.is_leaf() {
        Bounds::of_prims(&prims[node.leaf_range()])
    } else {
        let (l, r) = (&nodes[i + 1], &nodes[node.right() as usize]);
        Bounds {
            min: l.min,
            max: l.max,
        }
        .merged(&Bounds {
            min: r.min,
            max: r.max,
        })
    }
}

/// Copies the box of `n` into the wide array's copy `e` of it.
#[inline(always)]
fn set_copy(e: &mut Node, n: &Node) {
    e.min = n.min;
    e.max = n.max;
}

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

    /// Replaces the boxes of the primitives listed in `changes` (`(primitive, new box)`; when a
    /// primitive is listed more than once, its last box counts) and refits the nodes above
    /// them: the cheap path when only some primitives moved. Few changes (fewer than a sixth
    /// of the node count) recompute only the leaves holding them and their ancestors; more
    /// take one pass over all the nodes, as [`Bvh::refit`] does (without its pass over the
    /// other primitives). The tree is the same either way.
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
        self.refit.make_slots(&self.prim_indices);
        if changes.len().saturating_mul(PARTIAL_FACTOR) < self.nodes.len() {
            self.refit.make_links(&self.nodes, &self.prim_indices);
            self.refit_partial(changes);
        } else {
            let (slot_of, bounds) = (&self.refit.slot_of[..], &mut self.prim_bounds[..]);
            for (prim, aabb) in changes {
                bounds[slot_of[*prim as usize] as usize] = PrimBounds::from_aabb(aabb);
            }
            self.refit_nodes();
        }
        Ok(())
    }

    /// The partial path of [`Bvh::refit_primitives`] (see the module comment), for checked
    /// `changes` and made maps.
    pub(crate) fn refit_partial(&mut self, changes: &[(u32, Aabb)]) {
        let RefitMaps {
            slot_of,
            leaf_of,
            links,
            dirty,
        } = &mut self.refit;
        for (prim, aabb) in changes {
            let p = *prim as usize;
            self.prim_bounds[slot_of[p] as usize] = PrimBounds::from_aabb(aabb);
            let leaf = leaf_of[p] as usize;
            dirty[leaf / 64] |= 1 << (leaf % 64);
        }
        let nodes = &mut self.nodes;
        let prims = &self.prim_bounds;
        let mut wide: Option<&mut Vec<Wide>> = self.wide.get_mut();
        let mut r4 = self.ray4.get_mut();
        // Highest node first: a node's children (larger indices) are done before it, and the
        // parent a node marks (smaller index) comes later, in this word or a lower one.
        for k in (0..dirty.len()).rev() {
            let mut word = std::mem::take(&mut dirty[k]);
            while word != 0 {
                let bit = 63 - word.leading_zeros() as usize;
                word &= !(1 << bit);
                let i = k * 64 + bit;
                let node = nodes[i];
                let b = node_bounds(nodes, prims, i, &node);
                if !node.is_leaf() {
                    if let Some(wide) = wide.as_deref_mut() {
                        let e = &mut wide[links[i].wide as usize].0;
                        set_copy(&mut e[0], &nodes[i + 1]);
                        set_copy(&mut e[1], &nodes[node.right() as usize]);
                    }
                }
                nodes[i].min = b.min;
                nodes[i].max = b.max;
                if let Some(r4) = r4.as_deref_mut() {
                    r4.refresh_node(i, &nodes[i]);
                }
                if i == 0 {
                    if let Some(wide) = wide.as_deref_mut() {
                        set_copy(&mut wide[0].0[0], &nodes[0]);
                        set_copy(&mut wide[0].0[1], &nodes[0]);
                    }
                } else {
                    let p = links[i].parent as usize;
                    if p / 64 == k {
                        word |= 1 << (p % 64);
                    } else {
                        dirty[p / 64] |= 1 << (p % 64);
                    }
                }
            }
        }
    }

    /// Recomputes every node box from the stored primitive boxes.
    pub(crate) fn refit_nodes(&mut self) {
        for i in (0..self.nodes.len()).rev() {
            let node = self.nodes[i];
            let b = node_bounds(&self.nodes, &self.prim_bounds, i, &node);
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::build::{BuildOptions, Builder};
    use crate::bvh::make_wide;
    use crate::testing::rng;

    /// Every field of `n`, floats as bits (so that `-0.0 != 0.0`).
    fn bits(n: &Node) -> [u32; 8] {
        let [a, b, c] = n.min.map(f32::to_bits);
        let [d, e, f] = n.max.map(f32::to_bits);
        [a, b, c, n.first, d, e, f, n.count]
    }

    fn node_bits(nodes: &[Node]) -> Vec<[u32; 8]> {
        nodes.iter().map(bits).collect()
    }

    fn wide_bits(wide: &[Wide]) -> Vec<[[u32; 8]; 2]> {
        wide.iter()
            .map(|w| [bits(&w.0[0]), bits(&w.0[1])])
            .collect()
    }

    /// `n` random boxes, some of them points with signed zero coordinates.
    fn boxes(n: usize, seed: u64) -> Vec<Aabb> {
        let mut r = rng(seed);
        (0..n)
            .map(|i| {
                if i % 7 == 0 {
                    let p = [r(-1.0, 1.0).round(), r(-1.0, 1.0).round(), r(-1.0, 1.0)];
                    Aabb::from_arrays(p, p)
                } else {
                    let c = [r(-20.0, 20.0), r(-20.0, 20.0), r(-20.0, 20.0)];
                    let h = [r(0.0, 1.0), r(0.0, 1.0), r(0.0, 1.0)];
                    Aabb::from_arrays(
                        [c[0] - h[0], c[1] - h[1], c[2] - h[2]],
                        [c[0] + h[0], c[1] + h[1], c[2] + h[2]],
                    )
                }
            })
            .collect()
    }

    /// Runs the partial path whatever the number of changes.
    fn partial(bvh: &mut Bvh, changes: &[(u32, Aabb)]) {
        bvh.refit.make_slots(&bvh.prim_indices);
        bvh.refit.make_links(&bvh.nodes, &bvh.prim_indices);
        bvh.refit_partial(changes);
    }

    #[test]
    fn partial_refit_is_the_full_refit_and_keeps_the_copies_exact() {
        for builder in [Builder::Lbvh, Builder::BinnedSah] {
            for leaf in [1, 3, 4, 8] {
                let seed = leaf as u64 + 10 * (builder == Builder::Lbvh) as u64;
                let mut cur = boxes(2000, seed);
                let opts = BuildOptions::default()
                    .with_builder(builder)
                    .with_max_leaf_size(leaf);
                let mut bvh = Bvh::build(&cur, opts).unwrap();
                // A fresh SAH tree may hold a zero of the other sign than refit computes: one
                // full refit first, then every partial refit must give the full refit's bits.
                bvh.refit(&cur).unwrap();
                let _ = bvh.wide();
                if leaf == 4 {
                    let _ = bvh.four_wide();
                }
                let mut r = rng(seed ^ 0x5eed);
                let more = boxes(2000, seed + 100);
                for round in 0..40 {
                    // 1, a few, many (more than the threshold would send here) or all.
                    let k = [1, 2, 7, 60, 900, 2500][round % 6];
                    let changes: Vec<(u32, Aabb)> = (0..k)
                        .map(|_| {
                            let p = r(0.0, 2000.0) as u32;
                            let b = if r(0.0, 1.0) < 0.5 {
                                more[r(0.0, 2000.0) as usize]
                            } else {
                                let d = [r(-0.3, 0.3), r(-0.3, 0.3), r(-0.3, 0.3)];
                                let b = cur[p as usize];
                                Aabb::from_arrays(
                                    [b.min.x + d[0], b.min.y + d[1], b.min.z + d[2]],
                                    [b.max.x + d[0], b.max.y + d[1], b.max.z + d[2]],
                                )
                            };
                            (p, b)
                        })
                        .collect();
                    // The last box of a primitive counts.
                    for &(p, b) in &changes {
                        cur[p as usize] = b;
                    }
                    let mut full = bvh.clone();
                    full.refit(&cur).unwrap();
                    partial(&mut bvh, &changes);
                    let what = format!("{builder:?} leaf {leaf} round {round}");
                    assert_eq!(node_bits(&bvh.nodes), node_bits(&full.nodes), "{what}");
                    let wide = bvh.wide.get().expect("the refit keeps the wide array");
                    assert_eq!(wide_bits(wide), wide_bits(&make_wide(&bvh.nodes)), "{what}");
                    assert_eq!(
                        wide_bits(wide),
                        wide_bits(full.wide.get().unwrap()),
                        "{what}"
                    );
                    if let Some(r4) = bvh.ray4.get() {
                        // Debug shows the sign of a zero.
                        let full4 = full.ray4.get().unwrap();
                        assert_eq!(format!("{:?}", r4.nodes), format!("{:?}", full4.nodes));
                    }
                    assert!(bvh.refit.dirty.iter().all(|&w| w == 0), "{what}");
                    bvh.validate_with_primitives(&cur).unwrap();
                }
            }
        }
    }

    #[test]
    fn partial_refit_of_a_fresh_tree_is_the_full_refit_up_to_the_sign_of_zeros() {
        for builder in [Builder::Lbvh, Builder::BinnedSah] {
            let mut cur = boxes(1000, 7);
            let opts = BuildOptions::default().with_builder(builder);
            let mut bvh = Bvh::build(&cur, opts).unwrap();
            let _ = bvh.wide();
            let mut full = bvh.clone();
            let changes: Vec<(u32, Aabb)> = (0..20).map(|i| (i * 37, cur[i as usize])).collect();
            for &(p, b) in &changes {
                cur[p as usize] = b;
            }
            partial(&mut bvh, &changes);
            full.refit(&cur).unwrap();
            assert_eq!(bvh.nodes, full.nodes);
            let wide = bvh.wide.get().unwrap();
            assert_eq!(wide_bits(wide), wide_bits(&make_wide(&bvh.nodes)));
            bvh.validate_with_primitives(&cur).unwrap();
        }
    }

    #[test]
    fn refit_primitives_takes_the_partial_path_for_few_changes() {
        let cur = boxes(1000, 3);
        let mut bvh = Bvh::build(&cur, BuildOptions::default()).unwrap();
        // A stale box in a node that no change touches: the partial path keeps it, the full
        // path recomputes it.
        let mut maps = RefitMaps::default();
        maps.make_links(&bvh.nodes, &bvh.prim_indices);
        let last = maps.leaf_of[999] as usize;
        let probe = |k: usize| {
            let mut t = bvh.clone();
            t.nodes[last].max[0] += 1.0;
            let changes: Vec<(u32, Aabb)> = (0..k as u32).map(|i| (i, cur[i as usize])).collect();
            t.refit_primitives(&changes).unwrap();
            t.nodes[last].max[0] != bvh.nodes[last].max[0]
        };
        let nodes = bvh.nodes.len();
        assert!(probe(1));
        assert!(probe(nodes / PARTIAL_FACTOR - 1));
        assert!(!probe(nodes / PARTIAL_FACTOR + 1));
        bvh.refit_primitives(&[(0, cur[0])]).unwrap();
        bvh.validate_with_primitives(&cur).unwrap();
    }
}
