//! Builders. [`BuildOptions`] picks one; each lives in its own file:
//! `binned_sah.rs` (Wald 2007, parallel top levels) and `lbvh.rs` (Morton order, Karras 2012's radix tree built top-down),
//! with the radix sort the LBVH needs in `radix_sort.rs`. The options are checked here; each
//! builder checks the boxes in its first pass over them (with the helpers here) and writes the
//! same depth-first [`Bvh`] layout.

mod binned_sah;
pub(crate) mod f4;
mod lbvh;
mod radix_sort;

pub use radix_sort::radix_sort_pairs;

use crate::aabb::Aabb;
use crate::bvh::{Bvh, Node, PrimBounds};
use crate::error::BvhError;
use f4::F4;

/// Which builder [`Bvh::build`] runs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Builder {
    /// Top-down binned surface-area heuristic (Wald 2007): the best trees for queries; the
    /// default.
    #[default]
    BinnedSah,
    /// Linear BVH over Morton codes (11 to 21 bits per axis; the radix tree of Karras 2012):
    /// the fastest build, trees of lower quality. Good for trees rebuilt every step.
    Lbvh,
}

/// Options of [`Bvh::build`]. The defaults suit both broadphase and ray-casting use.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BuildOptions {
    /// Which builder to run. Default: [`Builder::BinnedSah`].
    pub builder: Builder,
    /// Most primitives in one leaf (at least 1). Default: 4. The LBVH builder collapses every
    /// Morton range of at most this many primitives into a leaf; the SAH builder makes a leaf
    /// only when the SAH says splitting does not pay, which with unit costs is rare (its
    /// leaves average about 1.1 primitives), so for it this is an upper bound.
    pub max_leaf_size: u32,
    /// Number of SAH bins per axis, `2..=32` (SAH builder only). Default: 16, where Wald found
    /// quality to level off. Nodes of at most 16 primitives are not binned: they are split
    /// exactly, by a sweep over their sorted centroids (or by trying every subset up to 3).
    pub bins: u32,
    /// Use rayon for the top levels of the build (the current rayon pool). The tree is the same
    /// either way. Default: `true`.
    pub parallel: bool,
    /// SAH cost of visiting a node, relative to `intersection_cost`. Default: 1.
    pub traversal_cost: f32,
    /// SAH cost of testing one primitive. Default: 1.
    pub intersection_cost: f32,
}

impl Default for BuildOptions {
    fn default() -> Self {
        Self {
            builder: Builder::BinnedSah,
            max_leaf_size: 4,
            bins: 16,
            parallel: true,
            traversal_cost: 1.0,
            intersection_cost: 1.0,
        }
    }
}

impl BuildOptions {
    /// These options with `builder` set.
    pub fn with_builder(mut self, builder: Builder) -> Self {
        self.builder = builder;
        self
    }

    /// These options with `parallel` set.
    pub fn with_parallel(mut self, parallel: bool) -> Self {
        self.parallel = parallel;
        self
    }

    /// These options with `max_leaf_size` set.
    pub fn with_max_leaf_size(mut self, max_leaf_size: u32) -> Self {
        self.max_leaf_size = max_leaf_size;
        self
    }

    pub(crate) fn check(&self) -> Result<(), BvhError> {
        if self.max_leaf_size == 0 {
            return Err(BvhError::InvalidOptions("max_leaf_size must be at least 1"));
        }
        if !(2..=32).contains(&self.bins) {
            return Err(BvhError::InvalidOptions("bins must be in 2..=32"));
        }
        let ok = |c: f32| c.is_finite() && c > 0.0;
        if !ok(self.traversal_cost) || !ok(self.intersection_cost) {
            return Err(BvhError::InvalidOptions(
                "SAH costs must be finite and positive",
            ));
        }
        Ok(())
    }
}

/// `true` when `a` is valid ([`Aabb::is_valid`]), computed without branches.
#[inline(always)]
pub(crate) fn box_ok(a: &Aabb) -> bool {
    let (lo, hi) = (a.min_array(), a.max_array());
    let mut ok = true;
    for i in 0..3 {
        ok &= (lo[i].abs() <= f32::MAX) & (hi[i].abs() <= f32::MAX) & (lo[i] <= hi[i]);
    }
    ok
}

/// Index of the first invalid box, if any.
pub(crate) fn first_invalid(aabbs: &[Aabb]) -> Option<usize> {
    // Branch-free checks over blocks; the exact position only when a block fails.
    const BLOCK: usize = 64;
    for (b, block) in aabbs.chunks(BLOCK).enumerate() {
        if !block.iter().fold(true, |acc, a| acc & box_ok(a)) {
            return block.iter().position(|a| !box_ok(a)).map(|i| b * BLOCK + i);
        }
    }
    None
}

/// Most primitives one tree holds: nodes (up to `2n - 1` with leaves of one primitive) and
/// primitives are indexed by `u32`.
pub const MAX_PRIMITIVES: usize = 1 << 31;

/// `Ok` when a tree of `count` primitives can be built: every node index, up to `2 * count -
/// 2`, fits in a `u32`.
pub(crate) fn check_count(count: usize) -> Result<(), BvhError> {
    if count > MAX_PRIMITIVES {
        return Err(BvhError::TooManyPrimitives { count });
    }
    Ok(())
}

pub(crate) fn build(aabbs: &[Aabb], options: &BuildOptions) -> Result<Bvh, BvhError> {
    options.check()?;
    check_count(aabbs.len())?;
    if aabbs.is_empty() {
        return Ok(Bvh::default());
    }
    // Each builder checks the boxes in its first pass over them. The maps of the partial refit
    // (`Bvh::refit`) and the wide copies are left empty: made when first needed.
    match options.builder {
        Builder::BinnedSah => binned_sah::build(aabbs, options),
        Builder::Lbvh => lbvh::build(aabbs, options),
    }
    .map_err(|index| BvhError::InvalidAabb { index })
}

/// Running min/max bounds on raw arrays, used by the builders.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Bounds {
    pub min: [f32; 3],
    pub max: [f32; 3],
}

impl Bounds {
    pub const EMPTY: Bounds = Bounds {
        min: [f32::INFINITY; 3],
        max: [f32::NEG_INFINITY; 3],
    };

    #[inline(always)]
    pub fn grow(&mut self, min: &[f32; 3], max: &[f32; 3]) {
        for i in 0..3 {
            if min[i] < self.min[i] {
                self.min[i] = min[i];
            }
            if max[i] > self.max[i] {
                self.max[i] = max[i];
            }
        }
    }

    #[inline(always)]
    pub fn merged(mut self, other: &Bounds) -> Bounds {
        self.grow(&other.min, &other.max);
        self
    }

    /// The bounds of `prims`, as `grow` over each in turn would give them (bit for bit: the
    /// four-lane `min`/`max` keep the accumulated value on ties and against NaNs, as `grow`'s
    /// comparisons do), each box's corners as two vectors (`f4::prim_box`, lanes 0..3).
    #[inline]
    pub fn of_prims(prims: &[PrimBounds]) -> Bounds {
        let mut lower = F4::splat(f32::INFINITY);
        let mut upper = F4::splat(f32::NEG_INFINITY);
        for p in prims {
            let (lo, hi) = f4::prim_box(p);
            // `x.min(acc)` is `x < acc ? x : acc`: `grow`'s `if x < acc { acc = x }`.
            lower = lo.min(lower);
            upper = hi.max(upper);
        }
        let (l, u) = (lower.to_array(), upper.to_array());
        Bounds {
            min: [l[0], l[1], l[2]],
            max: [u[0], u[1], u[2]],
        }
    }
}

/// Appends `right` (a subtree built on its own, node indices relative to its start) after
/// `out`, fixing the right-child indices, and returns where it starts. Parallel builders use
/// this to join a subtree built on another thread.
pub(crate) fn append_subtree(out: &mut Vec<Node>, mut right: Vec<Node>) -> u32 {
    let base = out.len() as u32;
    for n in right.iter_mut() {
        if !n.is_leaf() {
            n.first += base;
        }
    }
    out.append(&mut right);
    base
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// A coordinate drawn from few values, so that ties, signed zeros, infinities and NaNs
    /// are common.
    fn coordinate() -> impl Strategy<Value = f32> {
        prop_oneof![
            Just(0.0f32),
            Just(-0.0f32),
            Just(1.0f32),
            Just(-1.0f32),
            Just(f32::INFINITY),
            Just(f32::NEG_INFINITY),
            Just(f32::NAN),
            -1e30f32..1e30f32,
        ]
    }

    proptest! {
        /// `of_prims` is `grow` over the boxes in turn, to the bit.
        #[test]
        fn bounds_of_prims_match_growing_one_by_one(
            prims in prop::collection::vec(
                (prop::array::uniform3(coordinate()), prop::array::uniform3(coordinate())),
                0..40,
            )
        ) {
            let prims: Vec<PrimBounds> =
                prims.into_iter().map(|(min, max)| PrimBounds { min, max }).collect();
            let mut grown = Bounds::EMPTY;
            for p in &prims {
                grown.grow(&p.min, &p.max);
            }
            let b = Bounds::of_prims(&prims);
            let bits = |v: [f32; 3]| v.map(f32::to_bits);
            prop_assert_eq!(bits(b.min), bits(grown.min));
            prop_assert_eq!(bits(b.max), bits(grown.max));
        }
    }

    /// The largest count whose node indices (up to `2n - 2`) fit in a `u32` is accepted; one
    /// more primitive is refused rather than built with wrapped indices.
    #[test]
    fn primitive_count_stops_where_node_indices_would_wrap() {
        let largest_node = |n: usize| 2 * n as u64 - 2;
        assert!(largest_node(MAX_PRIMITIVES) <= u64::from(u32::MAX));
        assert!(largest_node(MAX_PRIMITIVES + 1) > u64::from(u32::MAX));
        assert_eq!(check_count(0), Ok(()));
        assert_eq!(check_count(MAX_PRIMITIVES), Ok(()));
        assert_eq!(
            check_count(MAX_PRIMITIVES + 1),
            Err(BvhError::TooManyPrimitives {
                count: MAX_PRIMITIVES + 1
            })
        );
    }
}
