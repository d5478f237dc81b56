//! What the session has seen, as plain values: [`BusHealth`] (counters and controller
//! state) and [`JointTelemetry`] per joint, together a [`BusTelemetry`]. The session owns one
//! and records every frame into it; its driver publishes a copy
//! (`Session::poll_telemetry`).

use std::time::Instant;

use robobus_whj::registers::{self, UniqueId};
use robobus_whj::units::{ActualSpeed, Current, Position, Temperature, Voltage};
use robobus_whj::{ErrorCode, JointId, Reply};

use super::BusState;

/// Counters and state of the bus itself.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct BusHealth {
    /// Controller state now.
    pub state: BusState,
    /// Bus-off reports received.
    pub bus_off_events: u64,
    /// Error-passive reports received.
    pub error_passive_events: u64,
    /// Other bus-error reports (warning, no ACK, protocol errors, restarts).
    pub other_bus_errors: u64,
    /// Times the bus recovered from bus-off or error passive.
    pub recoveries: u64,
    /// The last bus or link error message.
    pub last_error: Option<String>,
    /// Frames sent.
    pub frames_sent: u64,
    /// Frames received.
    pub frames_received: u64,
    /// Received frames no request was waiting for, or that answer another request than
    /// the one waiting (other hosts' traffic, stray frames); they are ignored.
    pub unmatched: u64,
    /// Received frames that came while an attempt that had timed out on their reply ID
    /// could still be answered: late replies, never credited (a request they fall beside
    /// is made again rather than taken for two joints at one ID).
    pub late: u64,
    /// Received frames that are not valid joint replies.
    pub malformed: u64,
    /// Requests answered by two different replies (two nodes at one ID).
    pub duplicates: u64,
}

/// The latest values the client saw from one joint (servo feedback, status, register
/// reads, broadcast feedback), in wire units with typed conversions.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct JointTelemetry {
    /// When anything last arrived from this joint.
    pub updated: Option<Instant>,
    /// Actual position (0.0001° counts).
    pub position: Option<Position>,
    /// Actual speed (0.02 RPM counts).
    pub speed: Option<ActualSpeed>,
    /// Actual current (1 or 2 mA counts by model).
    pub current: Option<Current>,
    /// Drive enabled.
    pub enabled: Option<bool>,
    /// Error bits.
    pub error: Option<ErrorCode>,
    /// Bus voltage (0.01 V counts).
    pub voltage: Option<Voltage>,
    /// Temperature (0.1 °C counts).
    pub temperature: Option<Temperature>,
    /// Replies received from this joint.
    pub replies: u64,
    /// The unique ID (0x2A..0x2F) last read from this joint ID.
    pub unique_id: Option<UniqueId>,
    /// Two different unique IDs answered reads at this joint ID: two joints share the ID
    /// (the first seen and the differing one).
    pub unique_id_conflict: Option<(UniqueId, UniqueId)>,
}

/// A snapshot of everything the client knows: bus health and per-joint values.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct BusTelemetry {
    /// Bus counters and state.
    pub bus: BusHealth,
    joints: [JointTelemetry; 31],
}

impl BusTelemetry {
    /// The latest values of one joint.
    pub fn joint(&self, id: JointId) -> &JointTelemetry {
        // IDs are 1..=30, so the index is always in bounds; fall back to slot 0 anyway.
        self.joints
            .get(usize::from(id.get()))
            .unwrap_or(&self.joints[0])
    }

    fn joint_mut(&mut self, id: JointId) -> Option<&mut JointTelemetry> {
        self.joints.get_mut(usize::from(id.get()))
    }

    /// Copies from `source` the joints whose bit (`1 << ID`) is set in `joints`, and the
    /// bus health if `bus`.
    pub(crate) fn copy_from(&mut self, source: &Self, joints: u32, bus: bool) {
        if bus {
            self.bus.clone_from(&source.bus);
        }
        for (k, (to, from)) in self.joints.iter_mut().zip(&source.joints).enumerate() {
            if joints & (1 << k) != 0 {
                *to = *from;
            }
        }
    }

    pub(crate) fn record(&mut self, reply: &Reply, now: Instant) {
        let Some(t) = self.joint_mut(reply.joint()) else {
            return;
        };
        t.updated = Some(now);
        t.replies += 1;
        match reply {
            Reply::ServoFeedback { feedback: f, .. } => {
                t.position = Some(f.position);
                t.speed = Some(f.speed);
                t.current = Some(f.current);
                t.enabled = Some(f.is_enabled());
                t.error = Some(f.error);
            }
            Reply::Status { status: s, .. } => {
                t.position = Some(s.position);
                t.current = s.current.or(t.current);
                t.enabled = Some(s.is_enabled());
                t.error = Some(s.error);
                t.voltage = Some(s.voltage);
                t.temperature = Some(s.temperature);
            }
            Reply::BroadcastFeedback { feedback: f, .. } => {
                t.position = Some(f.position);
                t.speed = Some(f.speed);
                t.current = Some(f.current);
                t.enabled = Some(f.is_enabled());
                t.error = Some(f.error);
                t.voltage = Some(f.voltage);
                t.temperature = Some(f.temperature);
            }
            Reply::Read { addr, words, .. } => {
                if *addr == registers::addr::MOT_MODEL_ID && words.len() >= 6 {
                    let mut id = [0u16; 6];
                    for (slot, w) in id.iter_mut().zip(words.as_slice()) {
                        *slot = *w;
                    }
                    let id = UniqueId(id);
                    match t.unique_id {
                        Some(seen) if seen != id && t.unique_id_conflict.is_none() => {
                            t.unique_id_conflict = Some((seen, id));
                        }
                        _ => t.unique_id = Some(id),
                    }
                }
                if let Some(p) = reply.actual_position() {
                    t.position = Some(p);
                }
                if let Some(e) = reply.error_code() {
                    t.error = Some(e);
                }
                if let Some(e) = reply.enabled() {
                    t.enabled = Some(e);
                }
            }
            _ => {}
        }
    }
}
