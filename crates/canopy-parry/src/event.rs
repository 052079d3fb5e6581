//! Contact events: a pair starting or stopping to have contact points.

use crate::handle::ObjectHandle;

/// What changed for a pair during the last update. Events of one update are ordered by pair
/// (`object1`, then `object2`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum ContactEvent {
    /// The pair has contact points now and had none after the previous update.
    Started(ObjectHandle, ObjectHandle),
    /// The pair had contact points after the previous update and has none now (it moved
    /// apart, or one of its objects was removed).
    Stopped(ObjectHandle, ObjectHandle),
}

impl ContactEvent {
    /// The pair the event is about.
    pub fn objects(&self) -> (ObjectHandle, ObjectHandle) {
        match *self {
            ContactEvent::Started(a, b) | ContactEvent::Stopped(a, b) => (a, b),
        }
    }
}
