//! Shape queries: shape casts (first collider hit by a shape moving at constant velocity),
//! colliders intersecting a shape, and colliders whose broadphase box meets a box.

use super::{beyond_parts_reach, finite, valid_pose, SceneQueries};
use canopy_core::Aabb;
use rapier3d::parry::query::{QueryDispatcher, ShapeCastOptions, Unsupported};
use rapier3d::parry::shape::{Compound, HeightField, TypedShape};
use rapier3d::prelude::{
    Collider, ColliderHandle, Isometry, Point, Real, Shape, ShapeCastHit, Vector,
};

fn to_canopy(aabb: &rapier3d::prelude::Aabb) -> Aabb {
    Aabb::new(aabb.mins, aabb.maxs)
}

/// The room given to a collider's box before the exit time from it is computed, relative to
/// the box's size, and in units in the last place of its largest coordinate: far more than the
/// rounding of the subtractions in the slab test, so that a grazing hit just before the true
/// exit is not cut off.
const EXIT_SLACK: Real = 1.0e-3;
const EXIT_SLACK_ULPS: Real = 16.0;

/// `b` grown by the room of [`EXIT_SLACK`] and [`EXIT_SLACK_ULPS`] (with `origin`, the moving
/// point, among the coordinates whose rounding counts).
fn exit_room(b: &Aabb, origin: &Point<Real>) -> Aabb {
    let size = b.extents().max();
    let largest = b
        .min
        .iter()
        .chain(b.max.iter())
        .chain(origin.iter())
        .fold(0.0, |m: Real, c| m.max(c.abs()));
    b.loosened(EXIT_SLACK * size + EXIT_SLACK_ULPS * Real::EPSILON * largest)
}

/// Parry's cast against a heightfield walks, cell by cell along the motion, a range of cells as
/// wide as the other shape's box grown by the target distance, once for each cell it moves on:
/// its time grows with the square of that width, and a box millions of cells wide (a huge shape
/// or target distance) never returns; nor does a box so far out (1e16 from a heightfield with
/// cells of 1.4) that its coordinates' rounding spans millions of cells. Where either width is
/// more than this many times the heightfield's own width in cells (and than
/// [`WIDE_MIN_CELLS`]), each of the heightfield's triangles is cast against instead: the casts
/// parry makes on the triangles in the box's path, and the others, which the box does not
/// reach. The factor weighs the two: the walk's cheap steps, about width times (width plus
/// the heightfield's width), against one cast per triangle, some hundred times the cost of a
/// step, for two triangles per cell.
const WIDE_FACTOR: usize = 32;
/// See [`WIDE_FACTOR`].
const WIDE_MIN_CELLS: usize = 256;

/// `dispatcher.cast_shapes(pos12, vel12, g1, g2, options)` where one of the two shapes is a
/// heightfield, or a compound with a heightfield part, and the other's box, grown by the
/// target distance, is too wide for parry's cell walk (see [`WIDE_FACTOR`]): the earliest of
/// the casts against each of its triangles (and the compound's other parts). `None` where
/// neither is such a shape.
fn cast_wide_heightfield(
    dispatcher: &dyn QueryDispatcher,
    pos12: &Isometry<Real>,
    vel12: &Vector<Real>,
    g1: &dyn Shape,
    g2: &dyn Shape,
    options: ShapeCastOptions,
) -> Option<Result<Option<ShapeCastHit>, Unsupported>> {
    // The other shape's box in the heightfield's frame, grown by the target distance, is wider
    // than the walk allows, or so far out that the rounding of its coordinates is (the walk
    // then steps through cells its times of impact, rounded alike, cannot tell apart). A NaN
    // width counts as too wide.
    let too_wide = |hf: &HeightField, other: &dyn Shape, pose: &Isometry<Real>| {
        let b = other.compute_aabb(pose);
        let e = b.extents().add_scalar(2.0 * options.target_distance);
        let largest = b.mins.coords.abs().max().max(b.maxs.coords.abs().max());
        let (cw, ch) = (hf.cell_width().abs(), hf.cell_height().abs());
        let cells = (e.x / cw)
            .max(e.z / ch)
            .max(largest * Real::EPSILON / cw.min(ch));
        let (ni, nj) = hf.num_cells_ij();
        cells.is_nan() || cells > (WIDE_FACTOR * ni.max(nj)).max(WIDE_MIN_CELLS) as Real
    };
    let earliest = |casts: &mut dyn Iterator<Item = Result<Option<ShapeCastHit>, Unsupported>>| {
        let mut best: Option<ShapeCastHit> = None;
        for hit in casts {
            if let Some(hit) = hit? {
                if best.is_none_or(|b| hit.time_of_impact < b.time_of_impact) {
                    best = Some(hit);
                }
            }
        }
        Ok(best)
    };
    // A compound with such a heightfield among its parts: each part cast by itself, through
    // this function (parry's compound cast hands its parts to its own dispatcher, walk and
    // all). The hits come back in the compound's frame.
    let wide_part = |c: &Compound, other: &dyn Shape, other_pose: &Isometry<Real>| {
        c.shapes().iter().any(|(p, s)| {
            s.as_heightfield()
                .is_some_and(|hf| too_wide(hf, other, &p.inv_mul(other_pose)))
        })
    };
    let cast = |pos12: &Isometry<Real>, vel12: &Vector<Real>, g1: &dyn Shape, g2: &dyn Shape| {
        cast_wide_heightfield(dispatcher, pos12, vel12, g1, g2, options)
            .unwrap_or_else(|| dispatcher.cast_shapes(pos12, vel12, g1, g2, options))
    };
    if let Some(c) = g1.as_compound().filter(|c| wide_part(c, g2, pos12)) {
        return Some(earliest(&mut c.shapes().iter().map(|(p, s)| {
            let (pos, vel) = (p.inv_mul(pos12), p.inverse_transform_vector(vel12));
            cast(&pos, &vel, &**s, g2).map(|hit| hit.map(|h| h.transform1_by(p)))
        })));
    }
    if let Some(c) = g2
        .as_compound()
        .filter(|c| wide_part(c, g1, &pos12.inverse()))
    {
        return Some(earliest(&mut c.shapes().iter().map(|(p, s)| {
            cast(&(pos12 * p), vel12, g1, &**s)
                .map(|hit| hit.map(|h| h.swapped().transform1_by(p).swapped()))
        })));
    }
    if let Some(hf) = g1.as_heightfield() {
        too_wide(hf, g2, pos12).then(|| {
            earliest(
                &mut hf
                    .triangles()
                    .map(|t| dispatcher.cast_shapes(pos12, vel12, &t, g2, options)),
            )
        })
    } else if let Some(hf) = g2.as_heightfield() {
        too_wide(hf, g1, &pos12.inverse()).then(|| {
            earliest(
                &mut hf
                    .triangles()
                    .map(|t| dispatcher.cast_shapes(pos12, vel12, g1, &t, options)),
            )
        })
    } else {
        None
    }
}

impl<'a> SceneQueries<'a> {
    /// The first collider hit by `shape`, starting at `shape_pos` and moving at `shape_vel`,
    /// as Rapier's `QueryPipeline::cast_shape` (witness and normal 1 on the collider, in world
    /// space). Colliders whose boxes the swept box meets are tested in the order the moving box
    /// reaches them, stopping once the next one is reached after the best hit.
    ///
    /// Where one of the two shapes is not convex (a mesh, heightfield, compound or voxels),
    /// the collider is cast against only until the moving box has left the collider's box:
    /// no hit can come later, and parry's cast against a heightfield otherwise walks its
    /// cells until the time limit, forever when there is none (`Real::MAX`). Two convex
    /// shapes are cast with the caller's limit, exactly as Rapier casts them. A negative
    /// target distance counts as 0, as parry's casts between convex shapes take it (its
    /// heightfield cast panics on one), and against a heightfield one past the two boxes'
    /// farthest points is cut to that distance (a hit at time 0 either way), as it is against
    /// any shape where that distance and the target distance together pass `f32::MAX` (parry's
    /// cast overflows there, and on some panics); a collider whose box is so far from the
    /// moving shape's that the sum passes it even then is left out. Against a heightfield,
    /// where the other shape's box is too wide or too far for parry's walk over its cells
    /// (more than 32 times the heightfield's width in cells, and 256, across or in the
    /// rounding of its coordinates), each of its triangles is cast against instead. A NaN target
    /// distance, a NaN or negative time limit, or a pose or velocity that is not finite gives
    /// `None`.
    pub fn cast_shape(
        &self,
        shape_pos: &Isometry<Real>,
        shape_vel: &Vector<Real>,
        shape: &dyn Shape,
        options: ShapeCastOptions,
    ) -> Option<(ColliderHandle, ShapeCastHit)> {
        let max_toi = options.max_time_of_impact;
        if !valid_pose(shape_pos)
            || !finite(shape_vel.iter())
            || max_toi.is_nan()
            || max_toi < 0.0
            || options.target_distance.is_nan()
        {
            return None;
        }
        let options = ShapeCastOptions {
            target_distance: options.target_distance.max(0.0),
            ..options
        };
        let start = shape.compute_aabb(shape_pos);
        // The box swept over `[0, max_toi]` (a zero velocity component moves nothing, also
        // with an infinite `max_toi`), grown by the target distance.
        let mut swept = to_canopy(&start).loosened(options.target_distance);
        for i in 0..3 {
            let d = if shape_vel[i] == 0.0 {
                0.0
            } else {
                shape_vel[i] * max_toi
            };
            if d < 0.0 {
                swept.min[i] += d;
            } else {
                swept.max[i] += d;
            }
        }
        if swept.min.iter().chain(swept.max.iter()).any(|c| c.is_nan()) {
            return None;
        }
        // Entry time of the moving box into a collider box: a ray from the box centre against
        // the collider box grown by the moving box's half extents (a Minkowski sum).
        let start_box = to_canopy(&start);
        let center = start_box.center();
        let ray = canopy_core::Ray::new(center, *shape_vel);
        let grown = |b: &Aabb, target_distance: Real| {
            let half = start.half_extents().add_scalar(target_distance);
            Aabb::new(b.min - half, b.max + half)
        };
        let entry_exit =
            |b: &Aabb, target_distance: Real| ray.clip_aabb(&grown(b, target_distance), max_toi);
        let mut candidates: Vec<(Real, Aabb, ColliderHandle, &'a Collider)> = Vec::new();
        self.cull_aabb(&swept, |id| {
            let b = self.tight(id);
            if let Some((t, _)) = entry_exit(b, options.target_distance) {
                if let Some((handle, collider)) = self.collider(id) {
                    candidates.push((t, *b, handle, collider));
                }
            }
        });
        for (handle, collider, aabb) in self.edited() {
            if let Some((t, _)) = entry_exit(&aabb, options.target_distance) {
                candidates.push((t, aabb, handle, collider));
            }
        }
        candidates.sort_by(|a, b| {
            a.0.total_cmp(&b.0)
                .then(a.2.into_raw_parts().cmp(&b.2.into_raw_parts()))
        });
        let mut best: Option<(ColliderHandle, ShapeCastHit)> = None;
        for (t, b, handle, collider) in candidates {
            if best.as_ref().is_some_and(|b| t > b.1.time_of_impact) {
                break;
            }
            // The distance between the farthest two points of the two boxes at time 0, summed
            // in f64 (the squares overflow f32 past 1.8e19), infinite past f32's range.
            let farthest = b
                .merge(&start_box)
                .extents()
                .iter()
                .map(|&e| f64::from(e) * f64::from(e))
                .sum::<f64>()
                .sqrt() as f32;
            // Two convex shapes (neither a heightfield nor a compound) skip every check that
            // concerns those.
            let convex = collider.shape().is_convex() && shape.is_convex();
            // Against a heightfield, a target distance past the farthest two points of the two
            // boxes at time 0 is cut to that distance: either gives a hit at time 0, and parry's
            // heightfield cast overflows its cell indices on a huge one. Other shapes get the
            // caller's distance, as in Rapier (parry's answers there, with the shapes already
            // within the distance, change with it: a cut would change them too), unless it
            // and that farthest distance together pass f32's range: parry's cast adds the
            // distance to the shapes' coordinates, and overflows there (its GJK then fails an
            // assertion of a finite bound and panics).
            let heightfield =
                |s: &dyn Shape| matches!(s.as_typed_shape(), TypedShape::HeightField(_));
            let overflows = |d: Real| !(farthest + d).is_finite();
            let target_distance = if (!convex
                && (heightfield(collider.shape()) || heightfield(shape)))
                || overflows(options.target_distance)
            {
                options.target_distance.min(farthest)
            } else {
                options.target_distance
            };
            // Boxes so far apart that the sum overflows even so: the collider is left out.
            if overflows(target_distance) {
                continue;
            }
            // Past the exit (with room for rounding) the boxes are apart: no hit. Two convex
            // shapes get the caller's limit, as in Rapier: parry's cast between them ends
            // on its own, and a grazing hit its tolerance finds just past the exit (shapes a
            // few thousandths farther apart than the target distance) is then Rapier's too.
            let limit = if convex {
                max_toi
            } else {
                let room = exit_room(&grown(&b, target_distance), &center);
                ray.clip_aabb(&room, max_toi)
                    .map_or(max_toi, |(_, exit)| max_toi.min(exit))
            };
            let options = ShapeCastOptions {
                max_time_of_impact: limit,
                target_distance,
                ..options
            };
            let pos = collider.position();
            let (pos12, vel12) = (
                pos.inv_mul(shape_pos),
                pos.inverse_transform_vector(shape_vel),
            );
            let wide = (!convex).then(|| {
                cast_wide_heightfield(
                    self.dispatcher,
                    &pos12,
                    &vel12,
                    collider.shape(),
                    shape,
                    options,
                )
            });
            let hit = wide.flatten().unwrap_or_else(|| {
                self.dispatcher
                    .cast_shapes(&pos12, &vel12, collider.shape(), shape, options)
            });
            if let Ok(Some(hit)) = hit {
                if best
                    .as_ref()
                    .is_none_or(|b| hit.time_of_impact < b.1.time_of_impact)
                {
                    best = Some((handle, hit.transform1_by(pos)));
                }
            }
        }
        best
    }

    /// Every collider intersecting `shape` at `shape_pos`, as Rapier's
    /// `QueryPipeline::intersect_shape`. Where one of the two shapes is made of parts (a mesh,
    /// heightfield or compound) and the two boxes' farthest points lie more than 1e19 apart,
    /// the pair is left out: parry's test between them overflows `f32` (it panics).
    pub fn intersect_shape(
        &self,
        shape_pos: Isometry<Real>,
        shape: &'a dyn Shape,
    ) -> impl Iterator<Item = (ColliderHandle, &'a Collider)> + 'a {
        if !valid_pose(&shape_pos) {
            return Vec::new().into_iter();
        }
        let aabb = to_canopy(&shape.compute_aabb(&shape_pos));
        let dispatcher = self.dispatcher;
        let intersects = |collider: &Collider, collider_box: &Aabb| {
            if beyond_parts_reach(collider.shape(), collider_box, &aabb)
                || beyond_parts_reach(shape, &aabb, collider_box)
            {
                return false;
            }
            let pos12 = shape_pos.inv_mul(collider.position());
            dispatcher.intersection_test(&pos12, shape, collider.shape()) == Ok(true)
        };
        self.colliders_in_aabb(&aabb, intersects).into_iter()
    }

    /// Every collider whose broadphase box intersects `aabb`, as Rapier's
    /// `QueryPipeline::intersect_aabb_conservative`: the boxes are those of the last update
    /// (the collider's box with prediction distance and soft-CCD motion, as Rapier stores
    /// them), so the result holds every collider whose current box meets `aabb`, and possibly
    /// a few more, and no shape test is made. Colliders
    /// edited since the last update count with their current box.
    pub fn intersect_aabb_conservative(
        &self,
        aabb: rapier3d::prelude::Aabb,
    ) -> impl Iterator<Item = (ColliderHandle, &'a Collider)> + 'a {
        self.colliders_in_aabb(&to_canopy(&aabb), |_, _| true)
            .into_iter()
    }
}
