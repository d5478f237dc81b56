//! Handles from a bus: [`JointBus::joint`] and its kin make [`Joint`]s, and
//! [`OwnedJoint`] is a joint that holds a share of its bus (no lifetime, `Send`), for
//! front ends that keep it on another thread.

use core::time::Duration;
use std::sync::Arc;

use robobus_whj::JointId;

use super::Joint;
use crate::whj::{JointBus, WhjError};

/// A joint handle that owns a share of its bus (`Arc<JointBus>`): `Send + Sync + 'static`,
/// so a web server, a Python binding or a bridge can keep it. [`OwnedJoint::joint`] lends
/// the full [`Joint`] API; the identity comes from the bus's cache.
#[derive(Debug, Clone)]
pub struct OwnedJoint {
    bus: Arc<JointBus>,
    id: JointId,
}

impl OwnedJoint {
    /// The joint's ID.
    pub const fn id(&self) -> JointId {
        self.id
    }

    /// The bus.
    pub const fn bus(&self) -> &Arc<JointBus> {
        &self.bus
    }

    /// The joint's handle (no frames: the identity is cached in the bus).
    pub fn joint(&self) -> Joint<'_> {
        self.bus.joint_unchecked(self.id)
    }
}

impl JointBus {
    /// Connects to joint `id`: releases it from the bootloader (`IAP_FLAG := 0`, repeated
    /// for up to [`JointBusConfig::connect_timeout`]; harmless if the application already
    /// runs) and reads its identity. A joint that never answers gives
    /// [`WhjError::Silent`], which names the likely causes (IAP, ID, bit rate).
    ///
    /// [`JointBusConfig::connect_timeout`]: crate::whj::JointBusConfig::connect_timeout
    pub fn joint(&self, id: JointId) -> Result<Joint<'_>, WhjError> {
        Joint::connect(self, id)
    }

    /// Connects many joints at once ([`JointBus::joint`] for each, with the IAP releases
    /// pipelined: an absent joint costs the connect timeout once for the whole batch, not
    /// once per joint). Results in `ids` order.
    pub fn joints(&self, ids: &[JointId]) -> Vec<Result<Joint<'_>, WhjError>> {
        Joint::connect_many(self, ids, self.config().connect_timeout)
    }

    /// [`JointBus::joints`] waiting at most `timeout` for the joints to answer instead of
    /// [`JointBusConfig::connect_timeout`] (a scan: a joint in its bootloader answers the
    /// release at once, an absent ID must not cost seconds).
    ///
    /// [`JointBusConfig::connect_timeout`]: crate::whj::JointBusConfig::connect_timeout
    pub fn joints_within(
        &self,
        ids: &[JointId],
        timeout: Duration,
    ) -> Vec<Result<Joint<'_>, WhjError>> {
        Joint::connect_many(self, ids, timeout)
    }

    /// A handle for joint `id` without the connect handshake (for a joint known to run its
    /// application). Its identity is read on first use, once per bus (the bus keeps it, so
    /// a handle made every sample costs no extra frames).
    pub fn joint_unchecked(&self, id: JointId) -> Joint<'_> {
        Joint::unchecked(self, id)
    }

    /// Connects joint `id` ([`JointBus::joint`]) and returns a handle that owns (a share
    /// of) the bus, for front ends that keep a joint for a long time or on another thread.
    pub fn owned_joint(self: &Arc<Self>, id: JointId) -> Result<OwnedJoint, WhjError> {
        self.joint(id)?;
        Ok(OwnedJoint {
            bus: Arc::clone(self),
            id,
        })
    }
}
