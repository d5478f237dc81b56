//! `wck.status` (A-1 (3)): load and position of servos.

use robobus_wck::{BaudRate, Command, Reply};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::common::{degrees, run_steps};
use super::{R, each, plan_of};
use crate::catalogue::args::Ids;
use crate::catalogue::bounds::ConfirmClass;
use crate::catalogue::operation::{Confirm, OpDoc, Operation, Report, RunCx};
use crate::catalogue::{Effect, Family, Plan};
use crate::ops::DeviceResult;
use crate::ops::wck::WckPlan;

request!(cli
    /// `wck.status` (A-1 (3)): load and position of servos.
    Status {
        /// Servo IDs: IDs and ranges, e.g. `3` or `0-5,7` (in JSON also an array, `[0, 1]`).
        #[cfg_attr(feature = "cli", arg(value_parser = crate::catalogue::wck::cli::servo_ids))]
        ids: Ids,
    }
);

/// A servo's status.
#[derive(Debug, Clone, PartialEq, Serialize, JsonSchema)]
pub struct StatusRow {
    /// Its load.
    pub load: u8,
    /// Its position, 0..=254.
    pub position: u8,
    /// The same in degrees.
    pub degrees: f64,
}

impl Status {
    /// A status read per servo.
    fn steps(&self) -> R<WckPlan> {
        Ok(each(&self.ids.parse("<IDS>")?, |id| Command::StatusRead {
            id,
        }))
    }
}

impl Operation for Status {
    const OP: &'static str = "wck.status";
    const FAMILY: Family = Family::Wck;
    const DOC: OpDoc = OpDoc {
        args: "`ids`",
        report: "per servo: `load`, `position`, `degrees`",
        confirm: "-",
    };
    type Row = DeviceResult<u8, StatusRow>;
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
            "status",
            &self.steps()?,
            |_, reply| match reply? {
                Reply::Status { load, position } => Some(StatusRow {
                    load: load.get(),
                    position: position.get(),
                    degrees: degrees(position),
                }),
                _ => None,
            },
        )
    }
}
