//! A simulated WHJ arm served in this process: the one the monitor watches
//! (`robobus monitor --sim`, [`SimArm`]) and the one a simulated robot file opens
//! ([`ArmServer`]).

use std::f64::consts::TAU;
use std::sync::Arc;
use std::time::{Duration, Instant};

use robobus_link::MemoryBus;
use robobus_whj::JointId;
use robobus_whj::units::Position;

use crate::ops::safe::WhjJoints;
use crate::ops::whj::ServoLoop;
use crate::ops::{OpError, SafeState};
use crate::whj::{CyclicConfig, JointBus, JointBusConfig};

fn internal(what: &str, e: impl core::fmt::Display) -> OpError {
    OpError::Device(format!("simulated robot: {what}: {e}"))
}

/// Every joint of `ids` to [`SafeState::Disable`] through [`SafeState::apply`] (the one
/// safe stop), whatever happened before; a failure is logged.
fn disable_all(bus: &JointBus, ids: &[JointId]) {
    let joints: Vec<_> = ids.iter().map(|&id| bus.joint_unchecked(id)).collect();
    for f in SafeState::Disable.apply(&mut WhjJoints {
        joints: &joints,
        servo: ServoLoop::Position,
    }) {
        tracing::warn!(failure = %f, "simulated arm: safe state");
    }
}

/// Simulated WHJ30 joints served on a thread of their own over an in-process CAN FD bus
/// (stopped when dropped).
#[derive(Debug)]
pub(crate) struct ArmServer(robobus_sim::whj::Served);

impl ArmServer {
    /// Joints `ids` (simulation seed `seed`), and a client bus to them.
    pub(crate) fn start(ids: Vec<u8>, seed: u64) -> Result<(Self, JointBus), OpError> {
        use robobus_sim::whj::{Served, WhjBus, WhjModel};

        let wire = MemoryBus::new();
        let served = Served::spawn(
            "sim-whj-arm",
            WhjBus::chain(ids, WhjModel::Whj30, seed),
            wire.endpoint(),
        )
        .map_err(|e| internal("starting the simulated WHJ arm", e))?;
        let bus = JointBus::open_with(wire.endpoint(), JointBusConfig::simulated())?;
        Ok((Self(served), bus))
    }

    /// Stops serving; what the simulator served.
    fn stop(self) -> Result<robobus_sim::whj::ServeStats, OpError> {
        self.0
            .stop()
            .map(|(_, stats)| stats)
            .map_err(|e| internal("the WHJ arm", e))
    }
}

/// A simulated WHJ30 arm in this process that moves by itself: each joint follows a slow
/// sine (15° amplitude, 0.2 Hz, phase 0.5 rad per joint, starting from 0°) through a
/// 200 Hz smoothed cyclic loop, so that a monitor has something to show without hardware
/// (`robobus monitor --sim`). [`SimArm::sample`] gives the loop's latest feedback; the
/// joints are disabled and the simulator stopped when the arm is dropped.
#[derive(Debug)]
pub struct SimArm {
    ids: Vec<JointId>,
    cyc: Option<crate::whj::OwnedCyclic>,
    bus: Arc<JointBus>,
    server: Option<ArmServer>,
    start: Instant,
}

impl SimArm {
    /// Starts the simulator with joints `ids`, connects them, enables them in position
    /// mode and starts the loop.
    pub fn start(ids: &[JointId]) -> Result<Self, OpError> {
        let (server, bus) = ArmServer::start(ids.iter().map(|j| j.get()).collect(), 5)?;
        let mut arm = Self {
            ids: ids.to_vec(),
            cyc: None,
            bus: Arc::new(bus),
            server: Some(server),
            start: Instant::now(),
        };
        for &id in ids {
            let j = arm.bus.joint(id)?;
            j.disable()?;
            j.set_mode(robobus_whj::WorkMode::Position)?;
            j.enable()?;
        }
        arm.cyc = Some(arm.bus.cyclic_owned(CyclicConfig {
            smooth: Some(crate::whj::MotionLimits::default()),
            ..CyclicConfig::position(ids.to_vec(), Duration::from_millis(5))
        })?);
        arm.start = Instant::now();
        Ok(arm)
    }

    /// The joints.
    #[must_use]
    pub fn joints(&self) -> &[JointId] {
        &self.ids
    }

    /// Each joint's torque constant, N·m per A, in [`joints`](Self::joints)' order: its
    /// identified model's rated torque over rated current (the simulated WHJ30's), for a
    /// sample table's torque estimate ([`SampleTable::with_torque_constants`]).
    ///
    /// [`SampleTable::with_torque_constants`]: crate::record::SampleTable::with_torque_constants
    #[must_use]
    pub fn torque_constants(&self) -> Vec<Option<f64>> {
        self.ids
            .iter()
            .map(|&id| {
                let d = self.bus.cached_identity(id)?;
                robobus_whj::models::ProductFacts::torque_constant_of(d.model, d.reduction_ratio)
            })
            .collect()
    }

    /// The loop's latest cycle (feedback per joint, `None` for a joint that did not answer
    /// in it), after which the sine's next targets are set.
    pub fn sample(&self) -> Option<crate::whj::CycleReport> {
        let cyc = self.cyc.as_ref()?;
        let latest = cyc.latest();
        let t = self.start.elapsed().as_secs_f64();
        let targets: Vec<Position> = (0..self.ids.len())
            .filter_map(|i| {
                #[allow(clippy::cast_precision_loss)] // at most 30 joints
                let phase = i as f64 * 0.5;
                Position::from_degrees(15.0 * (TAU * 0.2 * t + phase).sin() - 15.0 * phase.sin())
                    .ok()
            })
            .collect();
        let _ = cyc.set_positions(&targets);
        latest
    }
}

impl Drop for SimArm {
    fn drop(&mut self) {
        if let Some(cyc) = self.cyc.take() {
            let _ = cyc.stop();
        }
        disable_all(&self.bus, &self.ids);
        if let Some(server) = self.server.take() {
            let _ = server.stop();
        }
    }
}
