//! `CollisionWorld`: objects (parry shapes or deformable meshes) with poses and user data,
//! updated in two phases: a canopy-core BVH over the objects' loosened boxes finds candidate
//! pairs, then parry computes their contact manifolds (see `narrow.rs`), kept across updates.

use std::time::Instant;

use canopy_core::{Aabb, BuildOptions, Builder, Bvh};
use nalgebra::{Isometry3, Point3};
use parry3d::shape::SharedShape;
use rayon::prelude::*;

use crate::coherence::Coherence;
use crate::convert::{to_canopy, to_parry};
use crate::deformable::DeformableMesh;
use crate::error::CollisionError;
use crate::event::ContactEvent;
use crate::handle::ObjectHandle;
use crate::narrow::{update_pair, Geometry};
use crate::pair::ContactPair;
use crate::parts::{build_part_tree, composite_part_aabbs, Parts};
use crate::self_contact::{self_contacts, SelfContact};
use crate::stats::UpdateStats;
use crate::validate::{check_bounds, check_pose, check_prediction, check_shape, shape_aabb};

const NONE: u32 = u32::MAX;

/// A changed object: its slot, new world box, and new triangle boxes for a deformable mesh.
type BoxChange = (u32, Aabb, Option<Vec<Aabb>>);

enum Kind {
    /// A shape parry handles whole.
    Convex(SharedShape),
    /// A `TriMesh` or `Compound`, with a canopy-core BVH over its parts' local boxes.
    Composite { shape: SharedShape, tree: Bvh },
    /// A deformable triangle mesh.
    Deformable(DeformableMesh),
}

struct Object {
    kind: Kind,
    pose: Isometry3<f32>,
    /// World box grown by the prediction of the last update.
    aabb: Aabb,
    /// Pose or vertices changed since the last update.
    dirty: bool,
    /// A deformable mesh whose vertices changed in this update: the manifolds its pairs kept
    /// describe the old triangles (parry's contact update would reuse them, as the relative
    /// pose of a triangle in the mesh's frame did not change), so those pairs start afresh.
    reshaped: bool,
}

impl Object {
    fn geometry(&self) -> Geometry<'_> {
        match &self.kind {
            Kind::Convex(shape) => Geometry::Convex(&**shape),
            Kind::Composite { shape, tree } => Geometry::Composite {
                parts: match shape.as_composite_shape() {
                    Some(c) => Parts::Shape(c),
                    None => Parts::Mesh {
                        vertices: &[],
                        indices: &[],
                        local_aabb: parry3d::bounding_volume::Aabb::new_invalid(),
                    },
                },
                tree,
            },
            Kind::Deformable(mesh) => Geometry::Composite {
                parts: mesh.parts(),
                tree: &mesh.tree,
            },
        }
    }

    /// The world box at `pose` grown by `margin` (for a deformable mesh, from its tree, whose
    /// boxes already include `margin`).
    fn world_aabb(&self, pose: &Isometry3<f32>, margin: f32) -> Aabb {
        match &self.kind {
            Kind::Convex(shape) | Kind::Composite { shape, .. } => {
                shape_aabb(&**shape, pose, margin)
            }
            Kind::Deformable(mesh) => match mesh.tree.root_aabb() {
                Some(root) => to_canopy(&to_parry(&root).transform_by(pose)),
                None => Aabb::new(
                    pose.translation.vector.into(),
                    pose.translation.vector.into(),
                ),
            },
        }
    }
}

struct Slot {
    generation: u32,
    object: Option<Object>,
}

/// A collision world: parry shapes and deformable meshes, a canopy-core broad phase and
/// parry's contact manifolds as the narrow phase.
///
/// Edits (`insert`, `set_pose`, `remove`, ...) take effect at the next [`Self::update`]; the
/// results (`contact_pairs`, `events`, `self_contacts`, `stats`) are those of the last update.
/// Results are deterministic: the same inputs give the same pairs and events, in the same
/// order, whatever the rayon thread count.
///
/// ```
/// use canopy_parry::{CollisionWorld, ContactEvent};
/// use nalgebra::Isometry3;
/// use parry3d::shape::SharedShape;
///
/// let mut world = CollisionWorld::new();
/// let a = world.insert(SharedShape::ball(1.0), Isometry3::translation(0.0, 0.0, 0.0), "a")?;
/// let b = world.insert(SharedShape::cuboid(1.0, 1.0, 1.0), Isometry3::translation(1.5, 0.0, 0.0), "b")?;
/// world.update(0.01)?;
/// let pair = world.contact_pairs().next().unwrap();
/// assert_eq!(pair.objects(), (a, b));
/// assert!((pair.min_distance().unwrap() + 0.5).abs() < 1e-5); // 0.5 deep
/// assert_eq!(world.events(), &[ContactEvent::Started(a, b)]);
///
/// world.set_pose(b, Isometry3::translation(5.0, 0.0, 0.0))?;
/// world.update(0.01)?;
/// assert_eq!(world.contact_pairs().count(), 0);
/// assert_eq!(world.events(), &[ContactEvent::Stopped(a, b)]);
///
/// assert_eq!(world.remove(b)?, "b");
/// assert!(world.set_pose(b, Isometry3::identity()).is_err()); // stale handle
/// # Ok::<(), canopy_parry::CollisionError>(())
/// ```
pub struct CollisionWorld<T = ()> {
    slots: Vec<Slot>,
    data: Vec<Option<T>>,
    free: Vec<u32>,
    len: usize,
    coherence: Coherence,
    /// Prediction of the last update (`None` before the first).
    prediction: Option<f32>,
    bvh: Bvh,
    /// Slot of each primitive of `bvh`.
    prim_slots: Vec<u32>,
    /// Primitive of each slot in `bvh` (`NONE` if not in it).
    slot_prims: Vec<u32>,
    /// Objects were inserted or removed since `bvh` was built.
    rebuild: bool,
    pairs: Vec<ContactPair>,
    events: Vec<ContactEvent>,
    self_contacts: Vec<SelfContact>,
    stats: UpdateStats,
}

impl<T> Default for CollisionWorld<T> {
    fn default() -> Self {
        Self::new()
    }
}

impl<T> CollisionWorld<T> {
    /// An empty world with [`Coherence::Persistent`] manifolds.
    pub fn new() -> Self {
        Self::with_coherence(Coherence::Persistent)
    }

    /// An empty world with the given treatment of manifolds across updates.
    pub fn with_coherence(coherence: Coherence) -> Self {
        Self {
            slots: Vec::new(),
            data: Vec::new(),
            free: Vec::new(),
            len: 0,
            coherence,
            prediction: None,
            bvh: Bvh::new(),
            prim_slots: Vec::new(),
            slot_prims: Vec::new(),
            rebuild: true,
            pairs: Vec::new(),
            events: Vec::new(),
            self_contacts: Vec::new(),
            stats: UpdateStats::default(),
        }
    }

    /// The coherence mode.
    pub fn coherence(&self) -> Coherence {
        self.coherence
    }

    /// Number of objects.
    pub fn len(&self) -> usize {
        self.len
    }

    /// `true` when the world holds no object.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Inserts a parry shape at `pose`.
    ///
    /// Supported: balls, cuboids, capsules, segments, triangles, cylinders, cones, convex
    /// polyhedra, their rounded versions, triangle meshes and compounds (which get their own
    /// canopy-core BVH over triangles / parts).
    ///
    /// # Errors
    /// [`CollisionError::InvalidPose`], [`CollisionError::DegenerateShape`] (NaN, zero or
    /// negative sizes, broken mesh indices, a convex polyhedron without faces),
    /// [`CollisionError::UnsupportedShape`], [`CollisionError::OutOfRange`],
    /// [`CollisionError::TooMany`].
    pub fn insert(
        &mut self,
        shape: SharedShape,
        pose: Isometry3<f32>,
        data: T,
    ) -> Result<ObjectHandle, CollisionError> {
        check_pose(&pose)?;
        check_shape(&*shape, true)?;
        let kind = if shape.as_composite_shape().is_some() {
            let tree = build_part_tree(&composite_part_aabbs(&*shape))?;
            Kind::Composite { shape, tree }
        } else {
            Kind::Convex(shape)
        };
        self.insert_object(kind, pose, data)
    }

    /// Inserts a deformable triangle mesh (vertices in its local frame, placed at `pose`).
    /// Move its vertices with [`Self::set_vertices`]; its self-contacts (between triangles
    /// sharing no vertex) are reported by [`Self::self_contacts`], computed fresh every update.
    /// Against other objects it behaves like a triangle mesh without pseudo-normals.
    ///
    /// ```
    /// use canopy_parry::CollisionWorld;
    /// use nalgebra::{Isometry3, Point3};
    ///
    /// let mut world = CollisionWorld::new();
    /// // Two triangles far apart, then folded onto each other.
    /// let mut vertices = vec![
    ///     Point3::new(0.0, 0.0, 0.0), Point3::new(1.0, 0.0, 0.0), Point3::new(0.0, 1.0, 0.0),
    ///     Point3::new(0.0, 0.0, 5.0), Point3::new(1.0, 0.0, 5.0), Point3::new(0.0, 1.0, 5.0),
    /// ];
    /// let cloth = world.insert_deformable(vertices.clone(), vec![[0, 1, 2], [3, 4, 5]], Isometry3::identity(), ())?;
    /// world.update(0.01)?;
    /// assert!(world.self_contacts().is_empty());
    /// for v in &mut vertices[3..] { v.z = 0.005; }
    /// world.set_vertices(cloth, &vertices)?;
    /// world.update(0.01)?;
    /// assert_eq!(world.self_contacts().len(), 1);
    /// # Ok::<(), canopy_parry::CollisionError>(())
    /// ```
    ///
    /// # Errors
    /// [`CollisionError::InvalidPose`], [`CollisionError::DegenerateShape`] (no triangle, NaN
    /// vertices, indices out of range), [`CollisionError::TooMany`].
    pub fn insert_deformable(
        &mut self,
        vertices: Vec<Point3<f32>>,
        indices: Vec<[u32; 3]>,
        pose: Isometry3<f32>,
        data: T,
    ) -> Result<ObjectHandle, CollisionError> {
        check_pose(&pose)?;
        let mesh = DeformableMesh::new(vertices, indices)?;
        self.insert_object(Kind::Deformable(mesh), pose, data)
    }

    fn insert_object(
        &mut self,
        kind: Kind,
        pose: Isometry3<f32>,
        data: T,
    ) -> Result<ObjectHandle, CollisionError> {
        let mut object = Object {
            kind,
            pose,
            aabb: Aabb::new(Point3::origin(), Point3::origin()),
            dirty: true,
            reshaped: false,
        };
        // The shape in its own frame is bounded too: a far-away shape brought back by its pose
        // would still overflow parry's local-frame arithmetic.
        check_bounds(&object.world_aabb(&Isometry3::identity(), 0.0))?;
        let aabb = object.world_aabb(&pose, self.prediction.unwrap_or(0.0));
        check_bounds(&aabb)?;
        object.aabb = aabb;
        let index = match self.free.pop() {
            Some(index) => index,
            None => {
                if self.slots.len() >= (NONE - 1) as usize {
                    return Err(CollisionError::TooMany);
                }
                self.slots.push(Slot {
                    generation: 0,
                    object: None,
                });
                self.data.push(None);
                self.slot_prims.push(NONE);
                (self.slots.len() - 1) as u32
            }
        };
        let slot = &mut self.slots[index as usize];
        slot.object = Some(object);
        self.data[index as usize] = Some(data);
        self.len += 1;
        self.rebuild = true;
        Ok(ObjectHandle::new(index, slot.generation))
    }

    fn object(&self, handle: ObjectHandle) -> Result<&Object, CollisionError> {
        self.slots
            .get(handle.index() as usize)
            .filter(|s| s.generation == handle.generation())
            .and_then(|s| s.object.as_ref())
            .ok_or(CollisionError::StaleHandle(handle))
    }

    fn object_mut(&mut self, handle: ObjectHandle) -> Result<&mut Object, CollisionError> {
        self.slots
            .get_mut(handle.index() as usize)
            .filter(|s| s.generation == handle.generation())
            .and_then(|s| s.object.as_mut())
            .ok_or(CollisionError::StaleHandle(handle))
    }

    /// `true` when `handle` names an object of this world.
    pub fn contains(&self, handle: ObjectHandle) -> bool {
        self.object(handle).is_ok()
    }

    /// Removes an object and returns its user data. Its pairs disappear at the next update
    /// (with a [`ContactEvent::Stopped`] for those in contact).
    ///
    /// # Errors
    /// [`CollisionError::StaleHandle`].
    pub fn remove(&mut self, handle: ObjectHandle) -> Result<T, CollisionError> {
        self.object(handle)?;
        let i = handle.index() as usize;
        let slot = &mut self.slots[i];
        slot.object = None;
        slot.generation = slot.generation.wrapping_add(1);
        self.free.push(handle.index());
        self.len -= 1;
        self.rebuild = true;
        self.data[i]
            .take()
            .ok_or(CollisionError::StaleHandle(handle))
    }

    /// Moves an object.
    ///
    /// # Errors
    /// [`CollisionError::StaleHandle`], [`CollisionError::InvalidPose`],
    /// [`CollisionError::OutOfRange`].
    pub fn set_pose(
        &mut self,
        handle: ObjectHandle,
        pose: Isometry3<f32>,
    ) -> Result<(), CollisionError> {
        check_pose(&pose)?;
        let margin = self.prediction.unwrap_or(0.0);
        let object = self.object_mut(handle)?;
        check_bounds(&object.world_aabb(&pose, margin))?;
        object.pose = pose;
        object.dirty = true;
        Ok(())
    }

    /// Replaces the vertices of a deformable mesh (same count, in its local frame).
    ///
    /// # Errors
    /// [`CollisionError::StaleHandle`], [`CollisionError::NotDeformable`],
    /// [`CollisionError::VertexCountMismatch`], [`CollisionError::DegenerateShape`] for a NaN
    /// or infinite vertex.
    pub fn set_vertices(
        &mut self,
        handle: ObjectHandle,
        vertices: &[Point3<f32>],
    ) -> Result<(), CollisionError> {
        let object = self.object_mut(handle)?;
        let Kind::Deformable(mesh) = &mut object.kind else {
            return Err(CollisionError::NotDeformable(handle));
        };
        mesh.set_vertices(vertices)?;
        object.dirty = true;
        Ok(())
    }

    /// The pose of an object.
    ///
    /// # Errors
    /// [`CollisionError::StaleHandle`].
    pub fn pose(&self, handle: ObjectHandle) -> Result<&Isometry3<f32>, CollisionError> {
        Ok(&self.object(handle)?.pose)
    }

    /// The parry shape of an object, `None` for a deformable mesh.
    ///
    /// # Errors
    /// [`CollisionError::StaleHandle`].
    pub fn shape(&self, handle: ObjectHandle) -> Result<Option<&SharedShape>, CollisionError> {
        Ok(match &self.object(handle)?.kind {
            Kind::Convex(shape) | Kind::Composite { shape, .. } => Some(shape),
            Kind::Deformable(_) => None,
        })
    }

    /// The current vertices of a deformable mesh (local frame).
    ///
    /// # Errors
    /// [`CollisionError::StaleHandle`], [`CollisionError::NotDeformable`].
    pub fn vertices(&self, handle: ObjectHandle) -> Result<&[Point3<f32>], CollisionError> {
        match &self.object(handle)?.kind {
            Kind::Deformable(mesh) => Ok(&mesh.vertices),
            _ => Err(CollisionError::NotDeformable(handle)),
        }
    }

    /// The triangles (vertex indices) of a deformable mesh.
    ///
    /// # Errors
    /// [`CollisionError::StaleHandle`], [`CollisionError::NotDeformable`].
    pub fn indices(&self, handle: ObjectHandle) -> Result<&[[u32; 3]], CollisionError> {
        match &self.object(handle)?.kind {
            Kind::Deformable(mesh) => Ok(&mesh.indices),
            _ => Err(CollisionError::NotDeformable(handle)),
        }
    }

    /// The user data of an object.
    ///
    /// # Errors
    /// [`CollisionError::StaleHandle`].
    pub fn data(&self, handle: ObjectHandle) -> Result<&T, CollisionError> {
        self.object(handle)?;
        self.data[handle.index() as usize]
            .as_ref()
            .ok_or(CollisionError::StaleHandle(handle))
    }

    /// The user data of an object, mutably.
    ///
    /// # Errors
    /// [`CollisionError::StaleHandle`].
    pub fn data_mut(&mut self, handle: ObjectHandle) -> Result<&mut T, CollisionError> {
        self.object(handle)?;
        self.data[handle.index() as usize]
            .as_mut()
            .ok_or(CollisionError::StaleHandle(handle))
    }

    /// The handles of all objects, in slot order.
    pub fn handles(&self) -> impl Iterator<Item = ObjectHandle> + '_ {
        self.slots.iter().enumerate().filter_map(|(i, s)| {
            s.object
                .as_ref()
                .map(|_| ObjectHandle::new(i as u32, s.generation))
        })
    }

    /// Pairs with at least one contact point after the last update, ordered by handles.
    pub fn contact_pairs(&self) -> impl Iterator<Item = &ContactPair> + '_ {
        self.pairs.iter().filter(|p| p.has_contacts())
    }

    /// All candidate pairs of the last update (overlapping loosened boxes), with or without
    /// contact points, ordered by handles.
    pub fn candidate_pairs(&self) -> &[ContactPair] {
        &self.pairs
    }

    /// The candidate pair of `a` and `b` (in either order), if any.
    pub fn pair(&self, a: ObjectHandle, b: ObjectHandle) -> Option<&ContactPair> {
        let key = (a.min(b), a.max(b));
        self.pairs
            .binary_search_by(|p| p.key().cmp(&key))
            .ok()
            .map(|i| &self.pairs[i])
    }

    /// Contact started / stopped events of the last update, ordered by pair.
    pub fn events(&self) -> &[ContactEvent] {
        &self.events
    }

    /// Self-contacts of deformable meshes found by the last update, ordered by object, then
    /// triangle pair.
    pub fn self_contacts(&self) -> &[SelfContact] {
        &self.self_contacts
    }

    /// Counters and timings of the last update.
    pub fn stats(&self) -> &UpdateStats {
        &self.stats
    }

    /// Finds the candidate pairs and computes their contact manifolds, with contacts reported
    /// up to `prediction` apart. Produces this update's events.
    ///
    /// # Errors
    /// [`CollisionError::InvalidPrediction`] for a negative, NaN or infinite `prediction`;
    /// [`CollisionError::OutOfRange`] when some box grown by `prediction` overflows. Both are
    /// found before anything is modified, so on error nothing changed. (The tree's own build
    /// and refit cannot fail on boxes checked that way; should they ever, the update returns
    /// [`CollisionError::OutOfRange`] and the next one recomputes every box and rebuilds the
    /// tree rather than trust a half-applied update.)
    pub fn update(&mut self, prediction: f32) -> Result<(), CollisionError> {
        check_prediction(prediction)?;
        let start = Instant::now();
        let all = self.prediction != Some(prediction);
        let changes = self.pending_changes(prediction, all)?;
        self.prediction = Some(prediction);
        let candidates = match self.broad_phase(changes) {
            Ok(candidates) => candidates,
            Err(e) => {
                self.prediction = None;
                self.rebuild = true;
                return Err(e);
            }
        };
        let broad_phase = start.elapsed();

        let start = Instant::now();
        let n_candidates = candidates.len();
        self.narrow_phase(candidates, prediction);
        let narrow_phase = start.elapsed();

        self.stats.broad_phase = broad_phase;
        self.stats.narrow_phase = narrow_phase;
        self.stats.candidate_pairs = n_candidates;
        self.stats.contact_pairs = self.pairs.iter().filter(|p| p.has_contacts()).count();
        self.stats.self_contacts = self.self_contacts.len();
        Ok(())
    }

    /// New world boxes (and deformable triangle boxes) for changed objects, computed and checked
    /// before anything is modified.
    fn pending_changes(
        &self,
        prediction: f32,
        all: bool,
    ) -> Result<Vec<BoxChange>, CollisionError> {
        let mut changes = Vec::new();
        for (i, slot) in self.slots.iter().enumerate() {
            let Some(object) = &slot.object else { continue };
            if !(all || object.dirty) {
                continue;
            }
            let (aabb, boxes) = match &object.kind {
                Kind::Deformable(mesh) => {
                    let boxes = mesh.pending_boxes(prediction);
                    let root = match &boxes {
                        Some(b) => b.iter().skip(1).fold(b[0], |acc, x| acc.merge(x)),
                        None => mesh.tree.root_aabb().unwrap_or(object.aabb),
                    };
                    if !root.is_valid() {
                        return Err(CollisionError::OutOfRange);
                    }
                    (
                        to_canopy(&to_parry(&root).transform_by(&object.pose)),
                        boxes,
                    )
                }
                _ => (object.world_aabb(&object.pose, prediction), None),
            };
            check_bounds(&aabb)?;
            changes.push((i as u32, aabb, boxes));
        }
        Ok(changes)
    }

    /// Applies the box changes, rebuilds or refits the object BVH and returns the candidate
    /// pairs as sorted `(slot, slot)`.
    fn broad_phase(&mut self, changes: Vec<BoxChange>) -> Result<Vec<(u32, u32)>, CollisionError> {
        let margin = self.prediction.unwrap_or(0.0);
        let mut refits = Vec::with_capacity(changes.len());
        for (slot, aabb, boxes) in changes {
            let Some(object) = self.slots[slot as usize].object.as_mut() else {
                continue;
            };
            if let (Kind::Deformable(mesh), Some(boxes)) = (&mut object.kind, boxes) {
                object.reshaped = mesh.dirty;
                mesh.apply_boxes(&boxes, margin)?;
            }
            object.aabb = aabb;
            object.dirty = false;
            let prim = self.slot_prims[slot as usize];
            if prim != NONE {
                refits.push((prim, aabb));
            }
        }
        self.stats.rebuilt = self.rebuild;
        if self.rebuild {
            for p in &mut self.slot_prims {
                *p = NONE;
            }
            self.prim_slots.clear();
            let mut boxes = Vec::with_capacity(self.len);
            for (i, slot) in self.slots.iter().enumerate() {
                if let Some(object) = &slot.object {
                    self.slot_prims[i] = self.prim_slots.len() as u32;
                    self.prim_slots.push(i as u32);
                    boxes.push(object.aabb);
                }
            }
            self.bvh = Bvh::build(&boxes, BuildOptions::default().with_builder(Builder::Lbvh))
                .map_err(|_| CollisionError::OutOfRange)?;
            self.rebuild = false;
        } else {
            self.bvh
                .refit_primitives(&refits)
                .map_err(|_| CollisionError::OutOfRange)?;
        }
        let prim_slots = &self.prim_slots;
        let mut candidates: Vec<(u32, u32)> = self
            .bvh
            .par_self_pairs()
            .into_iter()
            .map(|(a, b)| {
                let (a, b) = (prim_slots[a as usize], prim_slots[b as usize]);
                (a.min(b), a.max(b))
            })
            .collect();
        candidates.par_sort_unstable();
        Ok(candidates)
    }

    fn handle_of(&self, slot: u32) -> ObjectHandle {
        ObjectHandle::new(slot, self.slots[slot as usize].generation)
    }

    /// Matches candidates with last update's pairs, recomputes manifolds, emits events and
    /// finds deformable self-contacts.
    fn narrow_phase(&mut self, candidates: Vec<(u32, u32)>, prediction: f32) {
        let old = std::mem::take(&mut self.pairs);
        let mut events: Vec<ContactEvent> = Vec::new();
        let mut old = old.into_iter().peekable();
        let mut pairs = Vec::with_capacity(candidates.len());
        let mut was_touching = Vec::with_capacity(candidates.len());
        for (a, b) in candidates {
            let key = (self.handle_of(a), self.handle_of(b));
            let mut reused = None;
            while let Some(p) = old.peek() {
                if p.key() < key {
                    let p = old.next().expect("peeked");
                    if p.touching {
                        events.push(ContactEvent::Stopped(p.object1, p.object2));
                    }
                } else {
                    if p.key() == key {
                        reused = old.next();
                    }
                    break;
                }
            }
            let pair = reused.unwrap_or_else(|| ContactPair::new(key.0, key.1));
            was_touching.push(pair.touching);
            pairs.push(pair);
        }
        for p in old {
            if p.touching {
                events.push(ContactEvent::Stopped(p.object1, p.object2));
            }
        }

        let slots = &self.slots;
        let persistent = self.coherence == Coherence::Persistent;
        pairs.par_iter_mut().for_each(|pair| {
            let o1 = slots[pair.object1.index() as usize].object.as_ref();
            let o2 = slots[pair.object2.index() as usize].object.as_ref();
            if let (Some(o1), Some(o2)) = (o1, o2) {
                update_pair(
                    pair,
                    o1.geometry(),
                    o2.geometry(),
                    &o1.pose,
                    &o2.pose,
                    prediction,
                    persistent && !o1.reshaped && !o2.reshaped,
                );
            }
        });
        for object in self.slots.iter_mut().filter_map(|s| s.object.as_mut()) {
            object.reshaped = false;
        }
        for (pair, was) in pairs.iter().zip(was_touching) {
            if pair.touching && !was {
                events.push(ContactEvent::Started(pair.object1, pair.object2));
            } else if !pair.touching && was {
                events.push(ContactEvent::Stopped(pair.object1, pair.object2));
            }
        }
        events.sort_unstable_by_key(|e| e.objects());
        self.events = events;
        self.pairs = pairs;

        self.self_contacts.clear();
        for (i, slot) in self.slots.iter().enumerate() {
            if let Some(Object {
                kind: Kind::Deformable(mesh),
                ..
            }) = &slot.object
            {
                let handle = ObjectHandle::new(i as u32, slot.generation);
                self.self_contacts.extend(self_contacts(
                    handle,
                    &mesh.vertices,
                    &mesh.indices,
                    &mesh.tree,
                    prediction,
                ));
            }
        }
    }
}
