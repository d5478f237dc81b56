//! `wck.sample`: one monitor sample of servos.

use robobus_wck::{BaudRate, Command, ServoId};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::{R, each, plan_of};
use crate::catalogue::args::Ids;
use crate::catalogue::bounds::ConfirmClass;
use crate::catalogue::operation::{Confirm, OpDoc, Operation, Report, RunCx};
use crate::catalogue::{Effect, Family, Plan};
use crate::ops::{DeviceResult, OpError};
use crate::station::sampler::{WckSample, WckSampler};

request!(
    /// `wck.sample`: one monitor sample of servos (position, speed from the previous
    /// sample of the same request, load).
    Sample { /// Servo IDs.
        ids: Ids }
);

impl Sample {
    /// The servos, validated.
    fn ids(&self) -> R<Vec<ServoId>> {
        self.ids.parse("<IDS>")
    }
}

impl Operation for Sample {
    const OP: &'static str = "wck.sample";
    const FAMILY: Family = Family::Wck;
    const DOC: OpDoc = OpDoc {
        args: "`ids`",
        report: "one row per servo: `position_deg`, `speed_deg_s` (`null`: one sample has \
                 no speed), `load`; or its `kind` and `error`",
        confirm: "-",
    };
    type Row = DeviceResult<u8, WckSample>;
    type Summary = ();

    fn bus(&self) -> Option<&str> {
        self.bus.as_deref()
    }

    fn effect(&self) -> Effect {
        Effect::Read
    }

    fn check(&self) -> Result<Confirm, OpError> {
        self.ids().map(|_| Confirm::NONE)
    }

    fn plan(&self, baud: BaudRate) -> Result<Plan, OpError> {
        let plan = each(&self.ids()?, |id| Command::StatusRead { id });
        Ok(plan_of(Self::OP, &plan, baud, ConfirmClass::None))
    }

    fn run(&self, cx: &mut RunCx<'_, '_>) -> Result<Report<Self::Row, ()>, OpError> {
        let ids = self.ids()?;
        let port = cx.station.wck(self.bus())?;
        let results = WckSampler::new(&ids).sample(&mut *port.lock(), 0.0);
        Ok(Report::devices(Self::OP, port.name(), results))
    }
}
