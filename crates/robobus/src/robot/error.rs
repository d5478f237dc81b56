//! Why a robot operation failed: [`RobotError`] and the kind a front end matches on.

#[cfg(doc)]
use super::Robot;
use super::{Interface, StopCause};
use crate::actuator::ActuatorError;
use crate::error::ErrorKind;
use crate::wck::WckError;

/// Why a robot operation failed.
#[derive(Debug, thiserror::Error)]
pub enum RobotError {
    /// The robot file is not valid TOML or does not fit the format.
    #[error("robot file, line {line}, column {column}: {message}")]
    Parse {
        /// 1-based line (0 if unknown).
        line: usize,
        /// 1-based column (0 if unknown).
        column: usize,
        /// What is wrong (names the field).
        message: String,
    },
    /// A value in the robot description is out of range or inconsistent.
    #[error("{item}: {field} = {value} is invalid; expected {expected}")]
    Invalid {
        /// The joint or bus (`"joint knee"`, `"bus legs"`).
        item: String,
        /// The field.
        field: &'static str,
        /// The value found.
        value: String,
        /// What is allowed.
        expected: String,
    },
    /// The robot file cannot be read.
    #[error("cannot read robot file {path}: {source}")]
    Io {
        /// The path.
        path: String,
        /// The OS error.
        #[source]
        source: std::io::Error,
    },
    /// A wCK bus cannot be opened.
    #[error("bus {bus}: {source}")]
    OpenWck {
        /// The bus name.
        bus: String,
        /// The error (names the port).
        #[source]
        source: Box<WckError>,
    },
    /// A WHJ bus or its link cannot be opened.
    #[error("bus {bus}: cannot open {what}: {detail}")]
    OpenWhj {
        /// The bus name.
        bus: String,
        /// What was being opened (`"UDP bus 239.74.163.2:43113"`, `"SocketCAN can0"`).
        what: String,
        /// The error.
        detail: String,
    },
    /// A bus of an `*-external` kind was not supplied to the builder.
    #[error("bus {bus} has kind = \"{kind}\": supply it with RobotBuilder::{method}")]
    MissingBus {
        /// The bus name.
        bus: String,
        /// Its kind.
        kind: &'static str,
        /// The builder method that supplies it.
        method: &'static str,
    },
    /// A bus supplied to the builder is not in the file, or is of the other family.
    #[error("bus {bus}: a {supplied} bus was supplied, but the robot file {found}")]
    WrongBus {
        /// The bus name.
        bus: String,
        /// `"wCK"` or `"WHJ"`.
        supplied: &'static str,
        /// What the file says.
        found: String,
    },
    /// A joint index past the robot's joints.
    #[error("no joint #{index}: the robot's joints are {names} (#0 on)")]
    NoSuchJoint {
        /// The index asked for.
        index: usize,
        /// The joints, in order.
        names: String,
    },
    /// `command` got a different number of targets than there are joints.
    #[error("{got} targets given for {expected} joints ({names}); nothing sent")]
    TargetCount {
        /// Number of joints.
        expected: usize,
        /// Number of targets.
        got: usize,
        /// The joints, in order.
        names: String,
    },
    /// A joint operation failed (names the joint).
    #[error(transparent)]
    Actuator(#[from] ActuatorError),
    /// The robot is in its safe state; commands are refused until [`Robot::resume`].
    #[error("robot is in its safe state ({cause}); nothing sent; call Robot::resume")]
    SafeStopped {
        /// Why it stopped.
        cause: StopCause,
    },
    /// The watchdog thread cannot be started.
    #[error("cannot start the watchdog thread: {0}")]
    Watchdog(String),
    /// A joint was asked for an interface the robot file does not give it; nothing sent.
    #[error(
        "joint {joint} has no {interface} interface (the robot file gives it: {has}); nothing sent"
    )]
    NoInterface {
        /// The joint.
        joint: String,
        /// The interface asked for.
        interface: Interface,
        /// The interfaces it has.
        has: String,
    },
    /// A target for an interface the joint is not commanded in now; nothing sent.
    #[error(
        "joint {joint} is commanded in {active}, not {asked}: switch it with \
         Robot::set_interface first; nothing sent"
    )]
    WrongInterface {
        /// The joint.
        joint: String,
        /// The interface of the target.
        asked: Interface,
        /// The interface the joint is in.
        active: Interface,
    },
    /// A velocity or effort target the joint cannot take; nothing sent.
    #[error("joint {joint}: {interface} target {value} {} is invalid; expected {expected}; nothing sent", .interface.unit())]
    Target {
        /// The joint.
        joint: String,
        /// The interface.
        interface: Interface,
        /// The target, in the interface's unit.
        value: f64,
        /// What is allowed.
        expected: String,
    },
    /// The host's protection stopped a joint during this command (a stall, a collision,
    /// heat, a runaway under effort): the fault names the joint, the quantity, the limit
    /// and the time; the joint was brought to rest through the one guard (`stopped`
    /// says how). Every later command is refused until [`Robot::clear_protection`].
    #[error("{fault}; {stopped}; every later command is refused until Robot::clear_protection")]
    Protection {
        /// The fault that stopped it.
        fault: Box<crate::ops::protect::Fault>,
        /// What the stop did (`its drive disabled (...)`, `held where it stands`).
        stopped: String,
    },
    /// A command (or an interface switch) while a joint is stopped by the host's
    /// protection; nothing sent.
    #[error(
        "the host's protection stopped joint {} ({fault}); nothing sent; call \
         Robot::clear_protection once the cause is cleared", .fault.joint
    )]
    ProtectionStopped {
        /// The fault that stopped the joint.
        fault: Box<crate::ops::protect::Fault>,
    },
    /// An interface switch of a joint that is not at rest; nothing sent.
    #[error("joint {joint} cannot switch from {from} to {to} while it moves: {why}; nothing sent")]
    Moving {
        /// The joint.
        joint: String,
        /// Its interface now.
        from: Interface,
        /// The interface asked for.
        to: Interface,
        /// What moves.
        why: String,
    },
}

impl RobotError {
    /// What kind of failure this is.
    pub fn kind(&self) -> ErrorKind {
        match self {
            Self::Parse { .. }
            | Self::Invalid { .. }
            | Self::Io { .. }
            | Self::MissingBus { .. }
            | Self::WrongBus { .. }
            | Self::NoSuchJoint { .. }
            | Self::TargetCount { .. }
            | Self::NoInterface { .. }
            | Self::Target { .. } => ErrorKind::BadInput,
            Self::OpenWck { source, .. } => source.kind(),
            Self::OpenWhj { .. } => ErrorKind::NoDevice,
            Self::Actuator(e) => e.kind(),
            Self::SafeStopped { .. }
            | Self::WrongInterface { .. }
            | Self::Moving { .. }
            | Self::ProtectionStopped { .. } => ErrorKind::Refused,
            Self::Protection { .. } => ErrorKind::Device,
            Self::Watchdog(_) => ErrorKind::NotAvailable,
        }
    }
}
