//! `wck.program.download` (A-1 (25)): the size of a servo's motion program.

use robobus_wck::{BaudRate, Command};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::common::run_steps;
use super::{ProgramCount, R, plan_of, sid};
use crate::catalogue::bounds::ConfirmClass;
use crate::catalogue::operation::{Confirm, OpDoc, Operation, Report, RunCx};
use crate::catalogue::{Effect, Family, Plan};
use crate::ops::DeviceResult;
use crate::ops::wck::WckPlan;

request!(cli
    /// `wck.program.download` (A-1 (25)): read a servo's motion program.
    ProgramDownload {
        /// Servo ID, 0..=30.
        #[cfg_attr(feature = "cli", arg(value_parser = crate::catalogue::wck::cli::servo_id))]
        id: u32,
    }
);

impl ProgramDownload {
    /// The one packet it sends.
    fn steps(&self) -> R<WckPlan> {
        Ok(WckPlan::one(Command::MotionRead { id: sid(self.id)? }))
    }
}

impl Operation for ProgramDownload {
    const OP: &'static str = "wck.program.download";
    const FAMILY: Family = Family::Wck;
    const DOC: OpDoc = OpDoc {
        args: "`id`",
        report: "per servo: `instructions` (how many its program holds)",
        confirm: "-",
    };
    type Row = DeviceResult<u8, ProgramCount>;
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
        let steps = self.steps()?;
        run_steps(
            cx,
            Self::OP,
            self.bus(),
            "program download",
            &steps,
            |_, r| ProgramCount::of(r?),
        )
    }
}
