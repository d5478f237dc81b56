//! `wck.move` (A-1 (1)): a position move of one servo; it replies its status before the
//! move.

use robobus_wck::{BaudRate, Command, Reply};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::common::{degrees, moved_servo, run_steps};
use super::{R, plan_of, pos, sid, torque};
use crate::catalogue::bounds::ConfirmClass;
use crate::catalogue::operation::{Confirm, OpDoc, Operation, Report, RunCx};
use crate::catalogue::{Effect, Family, Moved, Plan};
use crate::ops::DeviceResult;
use crate::ops::wck::WckPlan;

request!(cli
    /// `wck.move` (A-1 (1)): position move of one servo.
    Move {
        /// Servo ID, 0..=30.
        #[cfg_attr(feature = "cli", arg(value_parser = crate::catalogue::wck::cli::servo_id))]
        id: u32,
        /// Target position, 0..=254.
        #[cfg_attr(feature = "cli", arg(value_parser = crate::catalogue::wck::cli::position))]
        position: u32,
        /// Torque level, 0 (maximum) ..= 4 (minimum).
        #[serde(default)]
        #[cfg_attr(feature = "cli", arg(long, default_value = "0", value_parser = crate::catalogue::wck::cli::torque))]
        torque: u32,
    }
);

/// A move: its target, and the servo's status before it (its reply).
#[derive(Debug, Clone, PartialEq, Serialize, JsonSchema)]
pub struct MoveRow {
    /// The target position, 0..=254.
    pub target_position: u8,
    /// The same in degrees.
    pub target_degrees: f64,
    /// The torque level, 0..=4.
    pub torque: u8,
    /// The load before the move.
    pub load_before: u8,
    /// The position before the move, 0..=254.
    pub position_before: u8,
    /// The same in degrees.
    pub degrees_before: f64,
}

impl Move {
    /// The move's packet.
    fn steps(&self) -> R<WckPlan> {
        Ok(WckPlan::one(Command::Move {
            id: sid(self.id)?,
            torque: torque(self.torque)?,
            position: pos("<POSITION>", self.position)?,
        }))
    }
}

impl Operation for Move {
    const OP: &'static str = "wck.move";
    const FAMILY: Family = Family::Wck;
    const DOC: OpDoc = OpDoc {
        args: "`id`, `position` (0..=254), `torque` (0..=4)",
        report: "`target_position`, `target_degrees`, `torque`; the status before the move: \
                 `load_before`, `position_before`, `degrees_before`",
        confirm: "-",
    };
    type Row = DeviceResult<u8, MoveRow>;
    type Summary = ();

    fn bus(&self) -> Option<&str> {
        self.bus.as_deref()
    }

    fn effect(&self) -> Effect {
        Effect::Motion
    }

    fn moved(&self) -> R<Option<Moved>> {
        self.steps()?;
        Ok(Some(moved_servo(self.bus(), self.id)))
    }

    fn check(&self) -> R<Confirm> {
        self.steps().map(|_| Confirm::NONE)
    }

    fn plan(&self, baud: BaudRate) -> R<Plan> {
        Ok(plan_of(Self::OP, &self.steps()?, baud, ConfirmClass::None))
    }

    fn run(&self, cx: &mut RunCx<'_, '_>) -> R<Report<Self::Row, ()>> {
        run_steps(
            cx,
            Self::OP,
            self.bus(),
            "move",
            &self.steps()?,
            |c, reply| match (c, reply?) {
                (
                    Command::Move {
                        position: target,
                        torque,
                        ..
                    },
                    Reply::Status { load, position },
                ) => Some(MoveRow {
                    target_position: target.get(),
                    target_degrees: degrees(*target),
                    torque: torque.get(),
                    load_before: load.get(),
                    position_before: position.get(),
                    degrees_before: degrees(position),
                }),
                _ => None,
            },
        )
    }
}
