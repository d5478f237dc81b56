//! The cyclic loop owning its bus ([`OwnedCyclic`]), for a front end that keeps the loop
//! on another thread (a web server, a Python binding, a pub/sub bridge).

use std::ops::Deref;
use std::sync::Arc;

use super::{Cyclic, CyclicConfig};
use crate::whj::{JointBus, WhjError};

/// A [`Cyclic`] loop that holds an `Arc` of its bus instead of a borrow: `Send`, with no
/// lifetime, so it can be moved to another thread or kept in a long-lived object. The
/// same API as [`Cyclic`]; it stops when dropped (or with [`Cyclic::stop`]).
pub type OwnedCyclic = Cyclic<'static>;

/// How a [`Cyclic`] reaches its bus: borrowed ([`JointBus::cyclic`]) or owned
/// ([`JointBus::cyclic_owned`]).
#[derive(Debug)]
pub(super) enum BusRef<'a> {
    Borrowed(&'a JointBus),
    Owned(Arc<JointBus>),
}

impl Deref for BusRef<'_> {
    type Target = JointBus;

    fn deref(&self) -> &JointBus {
        match self {
            Self::Borrowed(bus) => bus,
            Self::Owned(bus) => bus,
        }
    }
}

impl JointBus {
    /// [`JointBus::cyclic`], returning a loop that owns an `Arc` of the bus
    /// ([`OwnedCyclic`]).
    pub fn cyclic_owned(self: &Arc<Self>, config: CyclicConfig) -> Result<OwnedCyclic, WhjError> {
        let mut borrowed = self.cyclic(config)?;
        // The borrowed handle hands the running loop over: it must not stop it when it
        // is dropped here.
        borrowed.stopped = true;
        Ok(Cyclic {
            bus: BusRef::Owned(Arc::clone(self)),
            mailbox: Arc::clone(&borrowed.mailbox),
            config: borrowed.config.clone(),
            stopped: false,
        })
    }
}
