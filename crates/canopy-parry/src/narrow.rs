//! The narrow phase of one pair: parry's `DefaultQueryDispatcher` on the whole shapes for
//! convex pairs, and for triangle meshes / compounds the parts culled with canopy-core first
//! (BVH-vs-box for composite-vs-convex, BVH-vs-BVH for composite-vs-composite), each part pair
//! then handed to parry's convex-convex manifold code exactly as parry's own composite
//! routines do, with manifolds kept per part pair across updates.

use canopy_core::{BuildOptions, Builder, Bvh};
use nalgebra::{Isometry3, Unit, Vector3};
use parry3d::bounding_volume::BoundingVolume;
use parry3d::query::{DefaultQueryDispatcher, PersistentQueryDispatcher};
use parry3d::shape::Shape;

use crate::convert::{to_canopy, to_parry};
use crate::pair::{ContactPair, Manifold};
use crate::parts::Parts;

/// One side of a pair as the narrow phase sees it.
#[derive(Clone, Copy)]
pub(crate) enum Geometry<'a> {
    /// A shape parry handles whole (convex shapes).
    Convex(&'a dyn Shape),
    /// A composite: its parts and the BVH over their local boxes.
    Composite { parts: Parts<'a>, tree: &'a Bvh },
}

/// Recomputes the manifolds of `pair` for `g1` at `pose1` and `g2` at `pose2`. With
/// `persistent` false, previous manifolds and workspaces are dropped first (every manifold is
/// computed from scratch, as a fresh parry call would).
pub(crate) fn update_pair(
    pair: &mut ContactPair,
    g1: Geometry<'_>,
    g2: Geometry<'_>,
    pose1: &Isometry3<f32>,
    pose2: &Isometry3<f32>,
    prediction: f32,
    persistent: bool,
) {
    pair.pose1 = *pose1;
    pair.pose2 = *pose2;
    if !persistent {
        pair.manifolds.clear();
        pair.keys.clear();
        pair.workspace = None;
    }
    let pos12 = pose1.inv_mul(pose2);
    match (g1, g2) {
        (Geometry::Convex(s1), Geometry::Convex(s2)) => {
            let warm = warm_started(&pair.manifolds);
            let compute = |pair: &mut ContactPair| {
                let result = DefaultQueryDispatcher.contact_manifolds(
                    &pos12,
                    s1,
                    s2,
                    prediction,
                    &mut pair.manifolds,
                    &mut pair.workspace,
                );
                if result.is_err() {
                    pair.manifolds.clear();
                }
            };
            compute(pair);
            if warm && !confirmed_empty(&pair.manifolds, &pos12, s1, s2, prediction) {
                // A failed warm start: recompute cold (see `convex_convex`).
                pair.manifolds.clear();
                pair.workspace = None;
                compute(pair);
            }
        }
        (Geometry::Composite { parts, tree }, Geometry::Convex(s2)) => {
            let local = s2.compute_aabb(&pos12).loosened(prediction);
            let keys = sorted_overlaps(tree, &local).map(|p| (p, 0)).collect();
            composite_convex(pair, keys, parts, s2, &pos12, prediction, false);
        }
        (Geometry::Convex(s1), Geometry::Composite { parts, tree }) => {
            let pos21 = pos12.inverse();
            let local = s1.compute_aabb(&pos21).loosened(prediction);
            let keys = sorted_overlaps(tree, &local).map(|p| (0, p)).collect();
            composite_convex(pair, keys, parts, s1, &pos21, prediction, true);
        }
        (
            Geometry::Composite {
                parts: parts1,
                tree: tree1,
            },
            Geometry::Composite {
                parts: parts2,
                tree: tree2,
            },
        ) => {
            let keys = part_pairs(parts1, tree1, parts2, tree2, &pos12, prediction);
            composite_composite(pair, keys, parts1, parts2, &pos12, prediction);
        }
    }
    pair.touching = in_contact(&pair.manifolds, prediction);
}

/// `true` when some kept manifold has a normal for parry's GJK to start from.
fn warm_started(manifolds: &[Manifold]) -> bool {
    manifolds.iter().any(|m| m.local_n1 != Vector3::zeros())
}

/// `true` unless a "no contact" answer is suspect: when every manifold is empty, one of their
/// normals must separate `s1` from `s2` (at `pos12`, in `s1`'s frame) by more than
/// `prediction`, checked with one support point of each shape. A shape without a support map
/// is taken on trust.
fn confirmed_empty(
    manifolds: &[Manifold],
    pos12: &Isometry3<f32>,
    s1: &dyn Shape,
    s2: &dyn Shape,
    prediction: f32,
) -> bool {
    if manifolds.iter().any(|m| !m.points.is_empty()) {
        return true;
    }
    let (Some(m1), Some(m2)) = (s1.as_support_map(), s2.as_support_map()) else {
        return true;
    };
    manifolds.iter().any(|m| {
        let Some(n) = Unit::try_new(m.local_n1, 1.0e-6) else {
            return false;
        };
        let reach1 = m1.local_support_point_toward(&n).coords.dot(&n);
        let reach2 = m2.support_point_toward(pos12, &-n).coords.dot(&n);
        reach2 - reach1 > prediction
    })
}

/// Runs parry's convex-convex manifold code (`compute`) on the kept manifold of `s1` and `s2`
/// (at `pos12`, in `s1`'s frame); an unsupported pair leaves it empty. parry's GJK/EPA
/// warm-starts from the kept normal and occasionally fails from there, returning no contact
/// for touching shapes (seen: a convex part 0.24 deep in a capsule; a cone 0.07 deep in a
/// round cuboid it was 0.19 away from the update before; parry's own persistent routines lose
/// them the same way), which would be a false negative. So an empty answer after a warm start
/// is checked ([`confirmed_empty`]: two support points) and, if its normal does not separate
/// the shapes, recomputed cold, from no normal, as a fresh call would.
fn convex_convex(
    manifold: &mut Manifold,
    pos12: &Isometry3<f32>,
    s1: &dyn Shape,
    s2: &dyn Shape,
    prediction: f32,
    compute: impl Fn(&mut Manifold) -> Result<(), parry3d::query::Unsupported>,
) {
    let warm = warm_started(std::slice::from_ref(manifold));
    if compute(manifold).is_err() {
        manifold.points.clear();
    }
    if warm && !confirmed_empty(std::slice::from_ref(manifold), pos12, s1, s2, prediction) {
        manifold.local_n1 = Vector3::zeros();
        manifold.local_n2 = Vector3::zeros();
        if compute(manifold).is_err() {
            manifold.points.clear();
        }
    }
}

/// `true` when some manifold point is at most `prediction` apart. parry's polygon clipping can
/// leave points farther than that in a manifold (speculative points of a face in contact);
/// whether they appear depends on culling details, so they do not count as contact.
pub fn in_contact(manifolds: &[Manifold], prediction: f32) -> bool {
    manifolds
        .iter()
        .flat_map(|m| m.points.iter())
        .any(|p| p.dist <= prediction)
}

/// The parts of `tree` whose boxes overlap `local` (a parry box in the tree's frame), sorted.
fn sorted_overlaps(
    tree: &Bvh,
    local: &parry3d::bounding_volume::Aabb,
) -> impl Iterator<Item = u32> {
    let query = to_canopy(local);
    let mut parts: Vec<u32> = if query.is_valid() {
        tree.overlaps(&query).collect()
    } else {
        Vec::new()
    };
    parts.sort_unstable();
    parts.into_iter()
}

/// Moves the manifolds of `pair` to the new sorted `keys`: a key seen last update keeps its
/// manifold (parry's coherence), a new key gets a fresh one from `fresh`.
fn rekey(
    pair: &mut ContactPair,
    keys: Vec<(u32, u32)>,
    mut fresh: impl FnMut((u32, u32)) -> Manifold,
) {
    let old_keys = std::mem::replace(&mut pair.keys, keys);
    let old = std::mem::take(&mut pair.manifolds);
    let mut old = old_keys.into_iter().zip(old).peekable();
    pair.manifolds.reserve(pair.keys.len());
    for &key in &pair.keys {
        while old.peek().is_some_and(|(k, _)| *k < key) {
            old.next();
        }
        let manifold = match old.peek() {
            Some((k, _)) if *k == key => old.next().map(|(_, m)| m),
            _ => None,
        };
        pair.manifolds.push(manifold.unwrap_or_else(|| fresh(key)));
    }
}

/// Composite (parts) against a convex shape. `pos` maps the convex shape's frame into the
/// composite's; `flipped` says the composite is the pair's second object.
fn composite_convex(
    pair: &mut ContactPair,
    keys: Vec<(u32, u32)>,
    parts: Parts<'_>,
    convex: &dyn Shape,
    pos: &Isometry3<f32>,
    prediction: f32,
    flipped: bool,
) {
    let part_of = |key: (u32, u32)| if flipped { key.1 } else { key.0 };
    rekey(pair, keys, |key| {
        let mut m = Manifold::with_data(key.0, key.1, ());
        let part_pos = parts
            .with_part(part_of(key), &mut |p, _, _| p.copied())
            .flatten();
        if flipped {
            m.subshape_pos2 = part_pos;
        } else {
            m.subshape_pos1 = part_pos;
        }
        m
    });
    // `pos` is the convex frame in the composite frame; parry's flipped routines call the
    // convex-convex code with (convex, part) and the part's frame mapped into the convex one.
    let inv = if flipped { Some(pos.inverse()) } else { None };
    for (key, manifold) in pair.keys.iter().zip(pair.manifolds.iter_mut()) {
        parts.with_part(part_of(*key), &mut |part_pos, part, normals| {
            if let Some(pos_convex_part) = &inv {
                let pos12 = match part_pos {
                    Some(p) => pos_convex_part * p,
                    None => *pos_convex_part,
                };
                convex_convex(manifold, &pos12, convex, part, prediction, |m| {
                    DefaultQueryDispatcher.contact_manifold_convex_convex(
                        &pos12, convex, part, None, normals, prediction, m,
                    )
                });
            } else {
                let pos12 = match part_pos {
                    Some(p) => p.inv_mul(pos),
                    None => *pos,
                };
                convex_convex(manifold, &pos12, part, convex, prediction, |m| {
                    DefaultQueryDispatcher.contact_manifold_convex_convex(
                        &pos12, part, convex, normals, None, prediction, m,
                    )
                });
            }
        });
    }
}

/// The part pairs `(part1, part2)` whose boxes overlap (grown by `prediction`), sorted: the
/// parts of each side that touch the other's root box are found by BVH-vs-box; the smaller
/// set is moved into the other frame, gets a small LBVH, and meets the other tree in a
/// BVH-vs-BVH traversal.
fn part_pairs(
    parts1: Parts<'_>,
    tree1: &Bvh,
    parts2: Parts<'_>,
    tree2: &Bvh,
    pos12: &Isometry3<f32>,
    prediction: f32,
) -> Vec<(u32, u32)> {
    let (Some(root1), Some(root2)) = (tree1.root_aabb(), tree2.root_aabb()) else {
        return Vec::new();
    };
    let pos21 = pos12.inverse();
    let root2_in_1 = to_parry(&root2).transform_by(pos12).loosened(prediction);
    let root1_in_2 = to_parry(&root1).transform_by(&pos21).loosened(prediction);
    let cand1: Vec<u32> = sorted_overlaps(tree1, &root2_in_1).collect();
    let cand2: Vec<u32> = sorted_overlaps(tree2, &root1_in_2).collect();
    if cand1.is_empty() || cand2.is_empty() {
        return Vec::new();
    }
    // Move the smaller candidate set into the other side's frame.
    let (moved_parts, moved, pose, fixed_tree, second_moved) = if cand2.len() <= cand1.len() {
        (parts2, &cand2, pos12, tree1, true)
    } else {
        (parts1, &cand1, &pos21, tree2, false)
    };
    let boxes: Vec<canopy_core::Aabb> = moved
        .iter()
        .filter_map(|&p| moved_parts.part_aabb(p, pose))
        .map(|b| to_canopy(&b.loosened(prediction)))
        .collect();
    if boxes.len() != moved.len() || !boxes.iter().all(|b| b.is_valid()) {
        return Vec::new();
    }
    let options = BuildOptions::default()
        .with_builder(Builder::Lbvh)
        .with_parallel(false);
    let Ok(moved_tree) = Bvh::build(&boxes, options) else {
        return Vec::new();
    };
    let mut out = Vec::new();
    fixed_tree.pairs_with(&moved_tree, |fixed, j| {
        let other = moved[j as usize];
        out.push(if second_moved {
            (fixed, other)
        } else {
            (other, fixed)
        });
    });
    out.sort_unstable();
    out
}

/// Composite against composite, over the culled part pairs `keys`.
fn composite_composite(
    pair: &mut ContactPair,
    keys: Vec<(u32, u32)>,
    parts1: Parts<'_>,
    parts2: Parts<'_>,
    pos12: &Isometry3<f32>,
    prediction: f32,
) {
    rekey(pair, keys, |(a, b)| {
        let mut m = Manifold::with_data(a, b, ());
        m.subshape_pos1 = parts1.with_part(a, &mut |p, _, _| p.copied()).flatten();
        m.subshape_pos2 = parts2.with_part(b, &mut |p, _, _| p.copied()).flatten();
        m
    });
    // parry's routine walks the larger composite first and composes the part poses along
    // that order; the same composition is used here so that the results match bit for bit.
    let larger_second = parts1.size_sq() < parts2.size_sq();
    let pos21 = pos12.inverse();
    for (&(a, b), manifold) in pair.keys.iter().zip(pair.manifolds.iter_mut()) {
        parts1.with_part(a, &mut |part_pos1, part1, normals1| {
            parts2.with_part(b, &mut |part_pos2, part2, normals2| {
                let pos = if larger_second {
                    let pos_a = match part_pos2 {
                        Some(p) => pos12 * p,
                        None => *pos12,
                    };
                    match part_pos1 {
                        Some(p) => p.inv_mul(&pos_a),
                        None => pos_a,
                    }
                } else {
                    let pos_b = match part_pos1 {
                        Some(p) => pos21 * p,
                        None => pos21,
                    };
                    match part_pos2 {
                        Some(p) => p.inv_mul(&pos_b),
                        None => pos_b,
                    }
                    .inverse()
                };
                convex_convex(manifold, &pos, part1, part2, prediction, |m| {
                    DefaultQueryDispatcher.contact_manifold_convex_convex(
                        &pos, part1, part2, normals1, normals2, prediction, m,
                    )
                });
            });
        });
    }
}
