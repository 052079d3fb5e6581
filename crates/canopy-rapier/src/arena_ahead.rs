//! Prefetching for the examine loop: where the colliders a few indices ahead, and their parent
//! bodies, lie in Rapier's sets. Each set keeps its elements in one array of equal-sized entries
//! (its arena), so an element's address is a linear function of its index, learned each update
//! from up to eight elements the set hands out (the array moves when it grows). That layout is
//! Rapier's, not a promise, so the prediction only ever feeds a prefetch hint: a wrong address
//! costs a wasted load, never a wrong result, and nothing is read through it. A sample that
//! disagrees, or a stride that cannot be an entry's, turns the prefetching off for the update.
//!
//! Inside a physics step the solver and the narrow phase run between two broadphase updates, so
//! the examine loop finds the colliders and bodies out of the caches; asked for ahead, they
//! arrive while the loop works on the colliders before them (`compare --scene balls`, the builds
//! with and without taking turns: the examine phase 3 to 9% faster, the ratio's median 2.82x ->
//! 2.94x and 2.87x -> 2.92x over six and eight pairs of runs; within noise in a fast hour).

use crate::broad_phase::prefetch_line;
use crate::proxy::Proxy;
use rapier3d::prelude::*;

/// The examine loop asks for the collider this many indices ahead of the one it examines.
const COLLIDER_AHEAD: usize = 8;

/// ... and for the parent body of the collider this many indices ahead (the proxy record gives
/// the parent's index, so no collider is read for it).
const BODY_AHEAD: usize = 4;

/// How many samples `ExamineAhead::learn` looks at, at most.
const SAMPLES: usize = 8;

/// The address of element `index` of an arena: `base + index * stride` (wrapping).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Stride {
    base: usize,
    stride: usize,
}

impl Stride {
    /// From samples `(index, address)` of one arena whose element type takes `size` bytes: the
    /// stride of the first two with different indices, when it is a whole number of bytes per
    /// index between `size` and `2 * size` (an entry holds the element and its generation) and
    /// every other sample lies where it predicts.
    fn learn(samples: &[(usize, usize)], size: usize) -> Option<Self> {
        let &(i0, a0) = samples.first()?;
        let &(i1, a1) = samples.iter().find(|&&(i, _)| i != i0)?;
        let (lo, hi) = if i0 < i1 {
            ((i0, a0), (i1, a1))
        } else {
            ((i1, a1), (i0, a0))
        };
        let bytes = hi.1.checked_sub(lo.1)?;
        let steps = hi.0 - lo.0;
        if bytes % steps != 0 {
            return None;
        }
        let stride = bytes / steps;
        if stride < size || stride > 2 * size {
            return None;
        }
        let learned = Self {
            base: lo.1.wrapping_sub(lo.0.wrapping_mul(stride)),
            stride,
        };
        samples
            .iter()
            .all(|&(i, a)| learned.address(i) == a)
            .then_some(learned)
    }

    #[inline(always)]
    fn address(&self, index: usize) -> usize {
        self.base.wrapping_add(index.wrapping_mul(self.stride))
    }
}

/// Where the examine loop's colliders and their parents lie, for one update.
#[derive(Clone, Copy, Debug)]
pub(crate) struct ExamineAhead {
    colliders: Stride,
    bodies: Option<Stride>,
}

impl ExamineAhead {
    /// Learned from the first few colliders of `indices` (the modified ones, in index order,
    /// each with its handle from `handle`) and their parents; `None` when the colliders'
    /// layout could not be learned.
    pub(crate) fn learn(
        colliders: &ColliderSet,
        bodies: &RigidBodySet,
        indices: impl Iterator<Item = u32>,
        handle: impl Fn(u32) -> ColliderHandle,
    ) -> Option<Self> {
        let mut collider_samples = [(0, 0); SAMPLES];
        let mut body_samples = [(0, 0); SAMPLES];
        let (mut nc, mut nb) = (0, 0);
        for i in indices.take(SAMPLES) {
            let Some(c) = colliders.get(handle(i)) else {
                continue;
            };
            collider_samples[nc] = (i as usize, c as *const Collider as usize);
            nc += 1;
            if let Some((h, b)) = c.parent().and_then(|h| Some((h, bodies.get(h)?))) {
                body_samples[nb] = (
                    h.into_raw_parts().0 as usize,
                    b as *const RigidBody as usize,
                );
                nb += 1;
            }
        }
        Some(Self {
            colliders: Stride::learn(&collider_samples[..nc], std::mem::size_of::<Collider>())?,
            bodies: Stride::learn(&body_samples[..nb], std::mem::size_of::<RigidBody>()),
        })
    }

    /// Asks for the collider `COLLIDER_AHEAD` indices after `index` (the lines the examine loop
    /// reads: all of its entry), and for the parent of the one `BODY_AHEAD` after it: only
    /// the lines the loop reads there, each asked for once. In rapier 0.27 those are the body's
    /// first line (the soft-CCD prediction), its last (the body type, in its last 16 bytes) and
    /// the line just after it (the arena entry's generation, which the set's lookup checks).
    /// The 400-byte body spans seven lines; asking for two lines from its start and two from
    /// its end, as before, fetched one or two that nothing reads and missed the generation's
    /// for every other body (`tools/ab`, old / new: `balls` 1.041 over 25 runs,
    /// `many_kinematics` 1.087, `many_pyramids` 1.070, `pyramid` 1.053, `boxes` and
    /// `spawn_storm` unchanged).
    #[inline(always)]
    pub(crate) fn prefetch(&self, index: usize, proxies: &[Option<Proxy>]) {
        let c = self.colliders.address(index + COLLIDER_AHEAD);
        // Every line of the collider's 176 bytes and of the generation after them, whatever
        // their alignment: the two-line requests from its first and its 129th byte, as before,
        // left out the middle line of colliders that start a line (the same lines otherwise,
        // so no change in `tools/ab` on `balls`, `many_kinematics` or `pyramid`).
        let size = std::mem::size_of::<Collider>();
        let mut at = 0;
        while at < size {
            prefetch_line(c.wrapping_add(at));
            at += 64;
        }
        prefetch_line(c.wrapping_add(size));
        if let (Some(bodies), Some(Some(p))) = (self.bodies, proxies.get(index + BODY_AHEAD)) {
            if let Some(j) = p.filter.parent_index() {
                let b = bodies.address(j as usize);
                prefetch_line(b);
                prefetch_line(body_last_byte(b));
                prefetch_line(body_last_byte(b).wrapping_add(1));
            }
        }
    }
}

/// The address of the last byte of the body at `body`: Rapier's `RigidBody` keeps its one-byte
/// fields (body type, dominance, enabled) in its last 16 bytes, on another line than the fields
/// the collision box reads, and its arena puts the entry's generation right after it. Only ever
/// a prefetch hint: where that layout differs, the fields are read as before, only without the
/// head start.
#[inline(always)]
pub(crate) fn body_last_byte(body: usize) -> usize {
    body.wrapping_add(std::mem::size_of::<RigidBody>() - 1)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn strides_are_learned_only_from_consistent_samples() {
        let s = Stride::learn(&[(3, 1000), (5, 1400), (4, 1200)], 180).expect("consistent");
        assert_eq!((s.address(0), s.address(10)), (400, 2400));
        // Unordered samples, and repeated indices, are fine.
        assert_eq!(
            Stride::learn(&[(5, 1400), (5, 1400), (3, 1000)], 180),
            Some(s)
        );
        // A third sample off the line, a stride too small or too large, a fraction of a byte
        // per index, addresses going down, or a single index: nothing learned.
        assert_eq!(Stride::learn(&[(3, 1000), (5, 1400), (4, 1208)], 180), None);
        assert_eq!(Stride::learn(&[(3, 1000), (5, 1400)], 201), None);
        assert_eq!(Stride::learn(&[(3, 1000), (5, 1400)], 99), None);
        assert_eq!(Stride::learn(&[(3, 1000), (6, 1400)], 100), None);
        assert_eq!(Stride::learn(&[(3, 1400), (5, 1000)], 180), None);
        assert_eq!(Stride::learn(&[(3, 1000), (3, 1000)], 180), None);
        assert_eq!(Stride::learn(&[], 180), None);
    }

    #[test]
    fn the_layout_of_rapiers_sets_is_learned() {
        let (bodies, colliders, row) = crate::broad_phase::ball_row(20, RigidBodyType::Dynamic);
        let handles: Vec<ColliderHandle> = row.iter().map(|&b| bodies[b].colliders()[0]).collect();
        let ahead = ExamineAhead::learn(&colliders, &bodies, 0..20u32, |i| handles[i as usize])
            .expect("learned");
        for &h in &handles {
            let i = h.into_raw_parts().0 as usize;
            let c = &colliders[h];
            assert_eq!(ahead.colliders.address(i), c as *const Collider as usize);
            let parent = c.parent().expect("parent");
            let b = &bodies[parent];
            let bodies_stride = ahead.bodies.expect("bodies learned");
            assert_eq!(
                bodies_stride.address(parent.into_raw_parts().0 as usize),
                b as *const RigidBody as usize
            );
        }
    }
}
