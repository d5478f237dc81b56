//! The one safe stop of both families: [`SafeState::apply`].
//!
//! The operations call it when their stop token is set or a device stops answering, the
//! robot watchdog calls it when the control loop stalls (and on Ctrl-C and drop), an
//! [`Actuator`](crate::actuator::Actuator)'s `relax` / `hold` / `apply_safe` call it on
//! their one joint, the demo on its arm, and the CLI reaches it through the operations
//! (its `--on-stop` option is the [`SafeState`]).
//!
//! What each state means per family:
//!
//! | state | wCK servos | WHJ joints |
//! |---|---|---|
//! | [`Passive`](SafeState::Passive) | a passive command per servo | drive disabled |
//! | [`Break`](SafeState::Break) | the bus-wide break (every module) | drive disabled (brake models lock the brake) |
//! | [`Hold`](SafeState::Hold) | a status read, then a move to the reported position | held in its loop: a position frame at the measured angle, or speed / current target 0 |
//! | [`Disable`](SafeState::Disable) | a passive command per servo | drive disabled |
//!
//! Every device is tried even after another failed; the failures come back one per device.

use robobus_link::ByteLink;
use robobus_wck::{ServoId, TorqueLevel};
use robobus_whj::units::TargetSpeed;
use serde::{Deserialize, Serialize};

use super::OpError;
use super::whj::ServoLoop;
use crate::wck::WckBus;
use crate::whj::Joint;

/// The safe state a bus is put in by the watchdog, a Ctrl-C stop and a drop, and at the
/// end of every robot operation of the catalogue (`robot.play`, `robot.teleop`,
/// `robot.calibrate`, `robot.teach`), finished, failed or stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum SafeState {
    /// wCK: every module passive (torque released; the shaft turns freely).
    Passive,
    /// wCK: the bus-wide break command (dynamic brake).
    Break,
    /// WHJ: a position servo frame at the actual angle (powered, holding).
    Hold,
    /// WHJ: drive disabled (brake models lock the brake).
    Disable,
}

impl SafeState {
    /// The keyword used in the TOML file.
    pub const fn keyword(self) -> &'static str {
        match self {
            Self::Passive => "passive",
            Self::Break => "break",
            Self::Hold => "hold",
            Self::Disable => "disable",
        }
    }
}

/// The devices of one bus that a safe state is brought to: [`WckServos`] or [`WhjJoints`].
pub trait SafeDevices {
    /// Whether these are WHJ joints (what a state means differs per family).
    const WHJ: bool;

    /// Brings every device to `state` (see the [module docs](self)); the failures.
    fn bring_to(&mut self, state: SafeState) -> Vec<SafeFailure>;

    /// The devices, for a report (`servo(s) 0, 1`, `joint 3`).
    fn describe(&self) -> String;
}

/// wCK servos `ids` on `bus`; a hold moves at `torque`.
#[derive(Debug)]
pub struct WckServos<'a, L: ByteLink> {
    /// The bus.
    pub bus: &'a mut WckBus<L>,
    /// The servos.
    pub ids: &'a [ServoId],
    /// Torque of a hold's move.
    pub torque: TorqueLevel,
}

/// WHJ joints, each held in the servo loop `servo` they run.
#[derive(Debug)]
pub struct WhjJoints<'a, 'b> {
    /// The joints.
    pub joints: &'a [Joint<'b>],
    /// The loop they run (what a hold sends).
    pub servo: ServoLoop,
}

/// A device a safe state failed on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case", tag = "device", content = "id")]
pub enum SafeDevice {
    /// The wCK bus as a whole (the break is one broadcast).
    WckBus,
    /// A wCK servo.
    Servo(u8),
    /// A WHJ joint.
    Joint(u8),
}

/// One device's failure to reach its safe state.
#[derive(Debug, thiserror::Error)]
#[error("{}: {error}", match .device {
    SafeDevice::WckBus => "bus break".to_string(),
    SafeDevice::Servo(id) => format!("servo {id}"),
    SafeDevice::Joint(id) => format!("joint {id}"),
})]
pub struct SafeFailure {
    /// The device.
    pub device: SafeDevice,
    /// What failed.
    pub error: OpError,
}

impl SafeState {
    /// Brings `devices` to this state, trying every device even after a failure; returns
    /// the failures (empty: every device is in the state). The one safe stop of both
    /// families (see [`ops::safe`](crate::ops::safe)).
    pub fn apply(self, devices: &mut impl SafeDevices) -> Vec<SafeFailure> {
        devices.bring_to(self)
    }

    /// What this state leaves a device of the family doing, as a report says it: `passive`,
    /// `braked`, `holding`, `disabled`.
    pub const fn outcome(self, whj: bool) -> &'static str {
        match (self, whj) {
            (Self::Hold, _) => "holding",
            (Self::Passive | Self::Disable, false) => "passive",
            (Self::Break, false) => "braked",
            (_, true) => "disabled",
        }
    }

    /// [`apply`](Self::apply) after a stop: [`OpError::Interrupted`] saying what it did, or
    /// what failed on the way.
    pub fn interrupted<D: SafeDevices>(self, devices: &mut D) -> OpError {
        let failed = self.apply(devices);
        let detail = match failed.first() {
            None => format!("{} {}", devices.describe(), self.outcome(D::WHJ)),
            Some(f) => format!(
                "could not bring {} to the safe state: {f}",
                devices.describe()
            ),
        };
        OpError::Interrupted {
            detail: Some(detail),
        }
    }
}

impl<L: ByteLink> SafeDevices for WckServos<'_, L> {
    const WHJ: bool = false;

    fn bring_to(&mut self, state: SafeState) -> Vec<SafeFailure> {
        let mut failed = Vec::new();
        let mut fail = |device, e| {
            failed.push(SafeFailure {
                device,
                error: OpError::Wck(e),
            });
        };
        match state {
            SafeState::Break => {
                if let Err(e) = self.bus.break_all() {
                    fail(SafeDevice::WckBus, e);
                }
            }
            SafeState::Passive | SafeState::Disable => {
                for &id in self.ids {
                    if let Err(e) = self.bus.servo(id).passive() {
                        fail(SafeDevice::Servo(id.get()), e);
                    }
                }
            }
            SafeState::Hold => {
                for &id in self.ids {
                    let mut servo = self.bus.servo(id);
                    let held = servo
                        .status()
                        .and_then(|s| servo.move_to(self.torque, s.position).map(drop));
                    if let Err(e) = held {
                        fail(SafeDevice::Servo(id.get()), e);
                    }
                }
            }
        }
        failed
    }

    fn describe(&self) -> String {
        format!("servo(s) {}", super::ids_text(self.ids))
    }
}

impl SafeDevices for WhjJoints<'_, '_> {
    const WHJ: bool = true;

    fn bring_to(&mut self, state: SafeState) -> Vec<SafeFailure> {
        let mut failed = Vec::new();
        for j in self.joints {
            let done = match (state, self.servo) {
                (SafeState::Hold, ServoLoop::Position) => j
                    .status()
                    .and_then(|s| j.command_position(s.position).map(drop)),
                (SafeState::Hold, ServoLoop::Speed) => j.command_speed(TargetSpeed(0)).map(drop),
                (SafeState::Hold, ServoLoop::Current) => j.command_current(0.0).map(drop),
                (SafeState::Passive | SafeState::Break | SafeState::Disable, _) => j.disable(),
            };
            if let Err(e) = done {
                failed.push(SafeFailure {
                    device: SafeDevice::Joint(j.id().get()),
                    error: OpError::Whj(e),
                });
            }
        }
        failed
    }

    fn describe(&self) -> String {
        let ids: Vec<String> = self
            .joints
            .iter()
            .map(|j| j.id().get().to_string())
            .collect();
        format!("joint {}", ids.join(", "))
    }
}
