//! `wck.move10` (A-1 (26)): a 10-bit position move; the servo replies its 10-bit
//! position before the move.

use robobus_wck::{BaudRate, Command, DataByte, ExtServoId, Position10, Reply};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::common::{moved_servo, round2, run_steps};
use super::{R, byte, plan_of};
use crate::catalogue::bounds::ConfirmClass;
use crate::catalogue::operation::{Confirm, OpDoc, Operation, Report, RunCx};
use crate::catalogue::{Effect, Family, Moved, Plan};
use crate::ops::wck::WckPlan;
use crate::ops::{DeviceResult, OpError};

request!(cli
    /// `wck.move10` (A-1 (26)): 10-bit position move.
    Move10 {
        /// Servo ID, 0..=253.
        #[cfg_attr(feature = "cli", arg(value_parser = crate::catalogue::wck::cli::ext_servo_id))]
        id: u32,
        /// Target position, 0..=1023.
        #[cfg_attr(feature = "cli", arg(value_parser = crate::catalogue::wck::cli::position10))]
        position: u32,
        /// Torque, 0..=254 (a full data byte, as the manual gives it).
        #[serde(default)]
        #[cfg_attr(feature = "cli", arg(long, default_value = "0", value_parser = crate::catalogue::wck::cli::data_byte))]
        torque: u32,
    }
);

/// A 10-bit move: its target, and the servo's position before it (its reply).
#[derive(Debug, Clone, PartialEq, Serialize, JsonSchema)]
pub struct Move10Row {
    /// The target position, 0..=1023.
    pub target_position10: u16,
    /// The same in degrees.
    pub target_degrees: f64,
    /// The torque, 0..=254.
    pub torque: u8,
    /// The position before the move, 0..=1023.
    pub position10_before: u16,
    /// The same in degrees.
    pub degrees_before: f64,
}

impl Move10 {
    /// The move's packet.
    fn steps(&self) -> R<WckPlan> {
        Ok(WckPlan::one(Command::Move10 {
            id: byte("<ID>", self.id, ExtServoId::new)?,
            torque: byte("--torque", self.torque, DataByte::new)?,
            position: Position10::new(u16::try_from(self.position).unwrap_or(u16::MAX))
                .map_err(|e| OpError::invalid("<POSITION>", self.position, e.to_string()))?,
        }))
    }
}

impl Operation for Move10 {
    const OP: &'static str = "wck.move10";
    const FAMILY: Family = Family::Wck;
    const DOC: OpDoc = OpDoc {
        args: "`id` (0..=253), `position` (0..=1023), `torque` (0..=254)",
        report: "`target_position10`, `target_degrees`, `torque`; the position before the \
                 move: `position10_before`, `degrees_before`",
        confirm: "-",
    };
    type Row = DeviceResult<u8, Move10Row>;
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
            "move10",
            &self.steps()?,
            |c, reply| match (c, reply?) {
                (
                    Command::Move10 {
                        position, torque, ..
                    },
                    Reply::Position10(before),
                ) => Some(Move10Row {
                    target_position10: position.get(),
                    target_degrees: round2(position.degrees()),
                    torque: torque.get(),
                    position10_before: before.get(),
                    degrees_before: round2(before.degrees()),
                }),
                _ => None,
            },
        )
    }
}
