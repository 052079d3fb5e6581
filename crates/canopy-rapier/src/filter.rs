//! Which collider pairs the narrow phase would always discard, so that the broadphase never
//! makes them: same parent body, rigid-body types that neither collider's
//! `active_collision_types` allows, non-matching collision groups. This is exactly Rapier
//! 0.27's narrow-phase filter (`NarrowPhase::compute_contacts`), minus the user hooks and
//! joint rules, which need state the broadphase does not see.

use rapier3d::prelude::*;

/// The inputs of the pair filter for one collider.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct FilterData {
    /// The parent body's handle as (index, generation), or [`NO_PARENT`]: two `u32`, where an
    /// `Option<RigidBodyHandle>` takes 12 bytes (the proxy record's size matters: `proxy.rs`).
    parent: [u32; 2],
    pub body_type: RigidBodyType,
    pub groups: InteractionGroups,
    pub active: ActiveCollisionTypes,
}

/// [`FilterData::parent`] of a collider without a parent (Rapier's invalid handle, which no
/// body has).
const NO_PARENT: [u32; 2] = [u32::MAX; 2];

/// A parent handle as [`FilterData`] stores it.
#[inline]
fn packed(parent: Option<RigidBodyHandle>) -> [u32; 2] {
    parent.map_or(NO_PARENT, |h| {
        let (index, generation) = h.into_raw_parts();
        [index, generation]
    })
}

impl FilterData {
    /// The filter inputs of `collider`, whose parent body (if any) is `parent`.
    #[inline]
    pub fn new(collider: &Collider, parent: Option<&RigidBody>) -> Self {
        Self {
            parent: packed(collider.parent()),
            body_type: parent
                .map(|b| b.body_type())
                .unwrap_or(RigidBodyType::Fixed),
            groups: collider.collision_groups(),
            active: collider.active_collision_types(),
        }
    }

    /// `self == FilterData::new(collider, parent)` except for the parent's body type, without
    /// building the new one. A collider without a parent counts as fixed; the body type of a
    /// parent is left to the caller (it sits on another cache line of the body than what the
    /// collision box reads, so the broadphase checks it in a separate pass).
    ///
    /// Groups are compared as one 64-bit word (the same equality as the derived one, in fewer
    /// instructions: this runs once per modified collider per update).
    #[inline]
    pub fn same_as_but_body_type(&self, collider: &Collider, has_parent: bool) -> bool {
        let groups = |g: InteractionGroups| {
            u64::from(g.memberships.bits()) | u64::from(g.filter.bits()) << 32
        };
        self.parent == packed(collider.parent())
            && (has_parent || self.body_type == RigidBodyType::Fixed)
            && groups(self.groups) == groups(collider.collision_groups())
            && self.active == collider.active_collision_types()
    }

    /// The parent body's arena index, if there is a parent.
    #[inline]
    pub fn parent_index(&self) -> Option<u32> {
        (self.parent != NO_PARENT).then_some(self.parent[0])
    }

    /// `true` when the narrow phase could make contacts between the two colliders.
    #[inline]
    pub fn may_pair(&self, other: &FilterData) -> bool {
        if self.parent != NO_PARENT && self.parent == other.parent {
            return false;
        }
        (self.active.test(self.body_type, other.body_type)
            || other.active.test(self.body_type, other.body_type))
            && self.groups.test(other.groups)
    }
}

/// The three trees: colliders are sorted by how their parent body moves.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Mobility {
    /// No parent, or a fixed parent.
    Fixed = 0,
    /// Kinematic parent (position- or velocity-based).
    Kinematic = 1,
    /// Dynamic parent.
    Dynamic = 2,
}

impl Mobility {
    /// All three, in tree order.
    pub const ALL: [Mobility; 3] = [Mobility::Fixed, Mobility::Kinematic, Mobility::Dynamic];

    pub(crate) fn of(body_type: RigidBodyType) -> Self {
        match body_type {
            RigidBodyType::Fixed => Mobility::Fixed,
            RigidBodyType::Dynamic => Mobility::Dynamic,
            RigidBodyType::KinematicPositionBased | RigidBodyType::KinematicVelocityBased => {
                Mobility::Kinematic
            }
        }
    }
}

/// Summary of the colliders in one tree, to skip querying a tree none of whose members could
/// pair with a collider. It only ever over-approximates (bits are OR-ed in and reset on rebuild).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct TreeFilterSummary {
    /// Bit `t` set when a member has body type `t as u32`.
    pub body_types: u8,
    /// Union of the members' active collision types.
    pub active: u16,
}

const BODY_TYPES: [RigidBodyType; 4] = [
    RigidBodyType::Dynamic,
    RigidBodyType::Fixed,
    RigidBodyType::KinematicPositionBased,
    RigidBodyType::KinematicVelocityBased,
];

impl TreeFilterSummary {
    pub fn add(&mut self, f: &FilterData) {
        self.body_types |= 1 << f.body_type as u32;
        self.active |= f.active.bits();
    }

    /// `false` only when no member of this tree can pair with a member of `other`.
    pub fn may_pair_with_tree(&self, other: &TreeFilterSummary) -> bool {
        let (ua, ub) = (
            ActiveCollisionTypes::from_bits_truncate(self.active),
            ActiveCollisionTypes::from_bits_truncate(other.active),
        );
        BODY_TYPES.iter().any(|&ta| {
            self.body_types & (1 << ta as u32) != 0
                && BODY_TYPES.iter().any(|&tb| {
                    other.body_types & (1 << tb as u32) != 0 && (ua.test(ta, tb) || ub.test(ta, tb))
                })
        })
    }

    /// `false` only when no member of the tree can pair with a collider of filter `f`.
    pub fn may_pair_with(&self, f: &FilterData) -> bool {
        let union = ActiveCollisionTypes::from_bits_truncate(self.active);
        BODY_TYPES.iter().any(|&t| {
            self.body_types & (1 << t as u32) != 0
                && (f.active.test(f.body_type, t) || union.test(f.body_type, t))
        })
    }
}
