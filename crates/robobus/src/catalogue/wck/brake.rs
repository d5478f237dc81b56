//! `wck.brake` (A-1 (6)): break mode (a dynamic brake) on every servo of the bus, by one
//! broadcast packet that every module answers at once.

use robobus_wck::{BaudRate, Command, Reply};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::common::{All, degrees, run_steps};
use super::{R, plan_of};
use crate::catalogue::bounds::ConfirmClass;
use crate::catalogue::operation::{Confirm, OpDoc, Operation, Report, RunCx};
use crate::catalogue::{Effect, Family, Plan};
use crate::ops::DeviceResult;
use crate::ops::wck::{BREAK_CLEAN, BREAK_COLLIDED, WckPlan};

request!(cli
    /// `wck.brake` (A-1 (6)): break mode on every servo of the bus.
    Brake {}
);

/// What the break's reply tells (`id` `"all"`).
#[derive(Debug, Clone, PartialEq, Serialize, JsonSchema)]
#[serde(untagged)]
pub enum BrakeRow {
    /// Two plausible bytes came back.
    Heard {
        /// The ID the reply names.
        answered_by: u8,
        /// The position it names, 0..=254.
        position: u8,
        /// The same in degrees.
        degrees: f64,
        /// What that means on a shared bus.
        meaning: String,
    },
    /// Bytes came back garbled: several modules answered at once.
    Collided {
        /// `collided (several modules answered)`.
        reply: String,
        /// What that means.
        meaning: String,
    },
}

/// What a garbled break reply says under `reply`.
const COLLIDED: &str = "collided (several modules answered)";

impl Operation for Brake {
    const OP: &'static str = "wck.brake";
    const FAMILY: Family = Family::Wck;
    const DOC: OpDoc = OpDoc {
        args: "-",
        report: "one row, `id` `all`: `answered_by`, `position`, `degrees` and `meaning`, \
                 or (replies collided) `reply` and `meaning`",
        confirm: "-",
    };
    type Row = DeviceResult<All, BrakeRow>;
    type Summary = ();

    fn bus(&self) -> Option<&str> {
        self.bus.as_deref()
    }

    fn effect(&self) -> Effect {
        Effect::Configure
    }

    fn check(&self) -> R<Confirm> {
        Ok(Confirm::NONE)
    }

    fn plan(&self, baud: BaudRate) -> R<Plan> {
        Ok(plan_of(
            Self::OP,
            &WckPlan::one(Command::Break),
            baud,
            ConfirmClass::None,
        ))
    }

    fn run(&self, cx: &mut RunCx<'_, '_>) -> R<Report<Self::Row, ()>> {
        let plan = WckPlan::one(Command::Break);
        run_steps(
            cx,
            Self::OP,
            self.bus(),
            "brake",
            &plan,
            |_, reply| match reply {
                Some(Reply::Break { id, position }) => Some(BrakeRow::Heard {
                    answered_by: id.get(),
                    position: position.get(),
                    degrees: degrees(position),
                    meaning: BREAK_CLEAN.to_owned(),
                }),
                None => Some(BrakeRow::Collided {
                    reply: COLLIDED.to_owned(),
                    meaning: BREAK_COLLIDED.to_owned(),
                }),
                Some(_) => None,
            },
        )
    }
}
