//! `wck.read10` (A-1 (27)): the 10-bit position of a servo.

use robobus_wck::{BaudRate, Command, ExtServoId, Reply};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::common::{round2, run_steps};
use super::{R, byte, plan_of};
use crate::catalogue::bounds::ConfirmClass;
use crate::catalogue::operation::{Confirm, OpDoc, Operation, Report, RunCx};
use crate::catalogue::{Effect, Family, Plan};
use crate::ops::DeviceResult;
use crate::ops::wck::WckPlan;

request!(cli
    /// `wck.read10` (A-1 (27)): 10-bit position of a servo.
    Read10 {
        /// Servo ID, 0..=253.
        #[cfg_attr(feature = "cli", arg(value_parser = crate::catalogue::wck::cli::ext_servo_id))]
        id: u32,
    }
);

/// A servo's 10-bit position.
#[derive(Debug, Clone, PartialEq, Serialize, JsonSchema)]
pub struct Read10Row {
    /// The position, 0..=1023.
    pub position10: u16,
    /// The same in degrees.
    pub degrees: f64,
}

impl Read10 {
    /// The read's packet.
    fn steps(&self) -> R<WckPlan> {
        Ok(WckPlan::one(Command::Read10 {
            id: byte("<ID>", self.id, ExtServoId::new)?,
        }))
    }
}

impl Operation for Read10 {
    const OP: &'static str = "wck.read10";
    const FAMILY: Family = Family::Wck;
    const DOC: OpDoc = OpDoc {
        args: "`id`",
        report: "`position10`, `degrees`",
        confirm: "-",
    };
    type Row = DeviceResult<u8, Read10Row>;
    type Summary = ();

    fn bus(&self) -> Option<&str> {
        self.bus.as_deref()
    }

    fn effect(&self) -> Effect {
        Effect::Read
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
            "read10",
            &self.steps()?,
            |_, reply| match reply? {
                Reply::Position10(p) => Some(Read10Row {
                    position10: p.get(),
                    degrees: round2(p.degrees()),
                }),
                _ => None,
            },
        )
    }
}
