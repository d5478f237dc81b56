//! `wck.program.upload` (A-1 (24), EEPROM): a motion program stored in a servo, which
//! starts running it at once.

use robobus_wck::{BaudRate, Command};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::common::run_steps;
use super::{ProgramCount, R, confirm_of, moved, plan_of, program, sid};
use crate::catalogue::bounds::ConfirmClass;
use crate::catalogue::operation::{Confirm, OpDoc, Operation, Report, RunCx};
use crate::catalogue::{Effect, Family, Moved, Plan};
use crate::ops::DeviceResult;
use crate::ops::wck::WckPlan;

request!(cli
    /// `wck.program.upload` (A-1 (24), EEPROM): store a motion program; needs `confirm`.
    ProgramUpload {
        /// Servo ID, 0..=30.
        #[cfg_attr(feature = "cli", arg(value_parser = crate::catalogue::wck::cli::servo_id))]
        id: u32,
        /// The program in its text form (what a program file holds).
        #[cfg_attr(feature = "cli", arg(skip))]
        program: String,
        /// Confirms the EEPROM write.
        #[serde(default)]
        #[cfg_attr(feature = "cli", arg(skip))]
        confirm: bool,
    }
);

impl ProgramUpload {
    /// The one packet it sends.
    fn steps(&self) -> R<WckPlan> {
        Ok(WckPlan::one(Command::MotionWrite {
            id: sid(self.id)?,
            program: program(&self.program)?,
        }))
    }
}

impl Operation for ProgramUpload {
    const OP: &'static str = "wck.program.upload";
    const FAMILY: Family = Family::Wck;
    const DOC: OpDoc = OpDoc {
        args: "`id`, `program` (text form)",
        report: "per servo: `instructions` (the count read back)",
        confirm: "EEPROM",
    };
    type Row = DeviceResult<u8, ProgramCount>;
    type Summary = ();

    fn bus(&self) -> Option<&str> {
        self.bus.as_deref()
    }

    /// An uploaded program starts at once: the servo runs it by itself.
    fn effect(&self) -> Effect {
        Effect::Motion
    }

    fn moved(&self) -> R<Option<Moved>> {
        self.steps()?;
        Ok(Some(moved(self.bus(), vec![sid(self.id)?.get()])))
    }

    fn confirmed(&self) -> bool {
        self.confirm
    }

    fn confirm(&mut self) {
        self.confirm = true;
    }

    fn check(&self) -> R<Confirm> {
        self.steps()?;
        Ok(confirm_of(ConfirmClass::NonVolatile))
    }

    fn plan(&self, baud: BaudRate) -> R<Plan> {
        Ok(plan_of(
            Self::OP,
            &self.steps()?,
            baud,
            ConfirmClass::NonVolatile,
        ))
    }

    fn run(&self, cx: &mut RunCx<'_, '_>) -> R<Report<Self::Row, ()>> {
        let steps = self.steps()?;
        run_steps(
            cx,
            Self::OP,
            self.bus(),
            "program upload",
            &steps,
            |_, r| ProgramCount::of(r?),
        )
    }
}
