//! The CAN FD bus model: the host and the simulated joints share one wire.
//!
//! Every frame waits until it is ready and the wire is idle; when several are waiting,
//! the lowest CAN ID wins arbitration (the host's frames included). A frame occupies the
//! wire for its exact duration with bit stuffing ([`robobus_whj::timing`]); it is received
//! by every other node at the instant its last bit (end of EOF) leaves the wire, and the
//! wire is free again after the 3-bit intermission. A joint's reply becomes ready
//! `processing_delay` after the request was received.
//!
//! Time is a [`Duration`] since the simulation started. On the virtual clock a test calls
//! [`WhjBus::request`] or [`WhjBus::run_until`] and time jumps from event to event; an
//! endpoint calls the same functions with the wall clock's time.

use core::time::Duration;
use std::collections::VecDeque;

use robobus_whj::CanFrame;
use robobus_whj::timing::{self, BitRates};

use super::config::JointConfig;
use super::end_board::SimEndBoard;
use super::joint::SimJoint;
use super::model::WhjModel;
use crate::faults::{DeviceFault, DeviceFaultKind};

/// Who put a frame on the wire.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Node {
    /// The host (a test, or the client behind an endpoint).
    Host,
    /// The joint at this index in [`WhjBus::joints`].
    Joint(usize),
    /// The end board ([`WhjBus::with_end_board`]).
    EndBoard,
}

/// A frame that occupied the wire.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct WireFrame {
    /// First bit (SOF).
    pub start: Duration,
    /// Last bit of EOF: the instant receivers have the frame.
    pub end: Duration,
    /// The frame.
    pub frame: CanFrame,
    /// The sender.
    pub source: Node,
}

/// A joint's frame as the host receives it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Delivered {
    /// The instant its last bit left the wire.
    pub at: Duration,
    /// The frame.
    pub frame: CanFrame,
}

#[derive(Debug, Clone, Copy)]
struct Pending {
    ready: Duration,
    seq: u64,
    frame: CanFrame,
    source: Node,
}

#[derive(Debug, Clone, Copy)]
struct InFlight {
    wire: WireFrame,
    /// When the wire is free again (after the intermission).
    free: Duration,
}

/// Counters of a bus.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct BusStats {
    /// Frames sent by the host.
    pub host_frames: u64,
    /// Frames sent by joints.
    pub joint_frames: u64,
    /// Total time the wire was busy.
    pub busy: Duration,
}

/// A simulated CAN FD bus with WHJ joints on it.
#[derive(Debug)]
pub struct WhjBus {
    joints: Vec<SimJoint>,
    end_board: Option<SimEndBoard>,
    rates: BitRates,
    now: Duration,
    wire_free: Duration,
    in_flight: Option<InFlight>,
    pending: Vec<Pending>,
    seq: u64,
    delivered: VecDeque<Delivered>,
    trace: Option<Vec<WireFrame>>,
    stats: BusStats,
}

impl WhjBus {
    /// A bus at 1 / 5 Mbit/s with these joints on it, at time zero.
    pub fn new(joints: Vec<SimJoint>) -> Self {
        Self {
            joints,
            end_board: None,
            rates: BitRates::WHJ,
            now: Duration::ZERO,
            wire_free: Duration::ZERO,
            in_flight: None,
            pending: Vec::new(),
            seq: 0,
            delivered: VecDeque::new(),
            trace: None,
            stats: BusStats::default(),
        }
    }

    /// A chain of joints of one model with default options; `seed` seeds each joint's
    /// measurement noise.
    pub fn chain(ids: impl IntoIterator<Item = u8>, model: WhjModel, seed: u64) -> Self {
        Self::with_configs(ids.into_iter().map(|id| JointConfig::new(id, model)), seed)
    }

    /// A bus with one joint per configuration.
    pub fn with_configs(configs: impl IntoIterator<Item = JointConfig>, seed: u64) -> Self {
        Self::new(
            configs
                .into_iter()
                .map(|cfg| SimJoint::new(cfg, seed))
                .collect(),
        )
    }

    /// Put an end board on the bus (it answers the end-board field of broadcast frames).
    #[must_use]
    pub fn with_end_board(mut self) -> Self {
        self.end_board = Some(SimEndBoard::new());
        self
    }

    /// The end board, if there is one.
    pub const fn end_board(&self) -> Option<&SimEndBoard> {
        self.end_board.as_ref()
    }

    /// The end board, if there is one.
    pub const fn end_board_mut(&mut self) -> Option<&mut SimEndBoard> {
        self.end_board.as_mut()
    }

    /// The bus's bit rates (what the host's adapter is set to).
    pub const fn rates(&self) -> BitRates {
        self.rates
    }

    /// Sets the bus to other bit rates, as reconfiguring the host's adapter does: from now
    /// on only the joints at these rates hear and answer.
    pub fn set_rates(&mut self, rates: BitRates) {
        self.rates = rates;
    }

    /// Use other bit rates (default 1 Mbit/s nominal, 5 Mbit/s data).
    #[must_use]
    pub fn with_rates(mut self, rates: BitRates) -> Self {
        self.rates = rates;
        self
    }

    /// Record every frame on the wire (see [`WhjBus::trace`]).
    #[must_use]
    pub fn with_trace(mut self) -> Self {
        self.trace = Some(Vec::new());
        self
    }

    /// The time up to which the bus has been simulated.
    pub fn now(&self) -> Duration {
        self.now
    }

    /// The joints, in the order they were given.
    pub fn joints(&self) -> &[SimJoint] {
        &self.joints
    }

    /// The joints, mutable (to inject faults or power-cycle them).
    pub fn joints_mut(&mut self) -> &mut [SimJoint] {
        &mut self.joints
    }

    /// The joint that answers to node ID `id`.
    pub fn joint(&self, id: u8) -> Option<&SimJoint> {
        self.joints.iter().find(|j| j.id() == id)
    }

    /// The joint that answers to node ID `id`, mutable.
    pub fn joint_mut(&mut self, id: u8) -> Option<&mut SimJoint> {
        self.joints.iter_mut().find(|j| j.id() == id)
    }

    /// Counters.
    pub fn stats(&self) -> BusStats {
        self.stats
    }

    /// Every frame that occupied the wire so far, if tracing is on.
    pub fn trace(&self) -> &[WireFrame] {
        self.trace.as_deref().unwrap_or(&[])
    }

    /// The host queues `frame`, ready to be sent at `at` (clamped to [`WhjBus::now`]).
    pub fn submit(&mut self, frame: CanFrame, at: Duration) {
        let ready = at.max(self.now);
        self.push(frame, ready, Node::Host);
    }

    fn push(&mut self, frame: CanFrame, ready: Duration, source: Node) {
        self.seq += 1;
        self.pending.push(Pending {
            ready,
            seq: self.seq,
            frame,
            source,
        });
    }

    /// When the next thing happens on the wire (a frame starts or ends), if anything is
    /// queued.
    pub fn next_event(&self) -> Option<Duration> {
        if let Some(f) = &self.in_flight {
            return Some(f.wire.end);
        }
        self.pending
            .iter()
            .map(|p| p.ready.max(self.wire_free))
            .min()
    }

    /// Whether nothing is queued or on the wire.
    pub fn is_idle(&self) -> bool {
        self.in_flight.is_none() && self.pending.is_empty()
    }

    /// Simulate up to `t` and return the joints' frames that reached the host by then,
    /// in wire order. Joints' mechanics are advanced to `t`.
    pub fn run_until(&mut self, t: Duration) -> Vec<Delivered> {
        loop {
            if let Some(f) = self.in_flight {
                if f.wire.end > t {
                    break;
                }
                self.in_flight = None;
                self.wire_free = f.free;
                self.deliver(&f.wire);
                continue;
            }
            let Some(earliest) = self.pending.iter().map(|p| p.ready).min() else {
                break;
            };
            let start = earliest.max(self.wire_free);
            if start > t {
                break;
            }
            // Arbitration: among the frames ready at `start`, the lowest ID wins (ties:
            // first queued).
            let Some(winner) = self
                .pending
                .iter()
                .enumerate()
                .filter(|(_, p)| p.ready <= start)
                .min_by_key(|(_, p)| (p.frame.raw_id(), p.frame.is_extended(), p.seq))
                .map(|(i, _)| i)
            else {
                break;
            };
            let p = self.pending.swap_remove(winner);
            let duration = timing::frame_duration(&p.frame, self.rates);
            let ifs = self.intermission();
            let end = start + duration.saturating_sub(ifs);
            self.in_flight = Some(InFlight {
                wire: WireFrame {
                    start,
                    end,
                    frame: p.frame,
                    source: p.source,
                },
                free: start + duration,
            });
            self.stats.busy += duration;
            match p.source {
                Node::Host => self.stats.host_frames += 1,
                Node::Joint(_) | Node::EndBoard => self.stats.joint_frames += 1,
            }
        }
        self.now = self.now.max(t);
        for j in &mut self.joints {
            j.advance(t);
        }
        self.delivered.drain(..).collect()
    }

    /// Three nominal bit times.
    fn intermission(&self) -> Duration {
        Duration::from_nanos(3_000_000_000 / u64::from(self.rates.nominal.get()))
    }

    fn deliver(&mut self, wire: &WireFrame) {
        if let Some(trace) = &mut self.trace {
            trace.push(*wire);
        }
        if wire.source != Node::Host {
            self.delivered.push_back(Delivered {
                at: wire.end,
                frame: wire.frame,
            });
        }
        for i in 0..self.joints.len() {
            // A joint at other bit rates than the bus's hears only noise.
            if wire.source == Node::Joint(i) || self.joints[i].rates() != Some(self.rates) {
                continue;
            }
            if let Some(reply) = self.joints[i].handle(&wire.frame, wire.end) {
                self.push(reply.frame, reply.ready_at, Node::Joint(i));
            }
        }
        if wire.source != Node::EndBoard
            && let Some(reply) = self
                .end_board
                .as_mut()
                .and_then(|b| b.handle(&wire.frame, wire.end))
        {
            self.push(reply.frame, reply.ready_at, Node::EndBoard);
        }
    }

    /// Run until nothing is queued or on the wire; return what reached the host.
    pub fn run_until_idle(&mut self) -> Vec<Delivered> {
        let mut out = Vec::new();
        while let Some(t) = self.next_event() {
            out.extend(self.run_until(t));
        }
        out
    }

    /// Virtual clock: send `frame` now, run until the bus is idle, return the replies.
    pub fn request(&mut self, frame: CanFrame) -> Vec<Delivered> {
        self.submit(frame, self.now);
        self.run_until_idle()
    }

    /// Virtual clock: let `d` pass; return whatever reached the host meanwhile.
    pub fn advance(&mut self, d: Duration) -> Vec<Delivered> {
        let t = self.now + d;
        self.run_until(t)
    }

    /// Applies a scheduled device fault at the bus's current time to the joint with its
    /// ID; returns whether there is one. [`DeviceFaultKind::Silent`]: it answers nothing
    /// until power-cycled; [`DeviceFaultKind::PowerCycle`]: a brown-out (RAM lost, back
    /// through power-up and the bootloader); [`DeviceFaultKind::Error`]: it latches the
    /// bits.
    pub fn apply_fault(&mut self, fault: &DeviceFault) -> bool {
        let now = self.now;
        let Some(joint) = self.joint_mut(fault.id) else {
            return false;
        };
        match fault.kind {
            DeviceFaultKind::Silent => joint.fall_silent(now),
            DeviceFaultKind::PowerCycle => joint.power_cycle(now),
            DeviceFaultKind::Error(bits) => joint.inject_error(bits, now),
        }
        true
    }

    /// Switch every joint off and on again now.
    pub fn power_cycle_all(&mut self) {
        let now = self.now;
        for j in &mut self.joints {
            j.power_cycle(now);
        }
    }
}
