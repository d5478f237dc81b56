//! `whj.zero`: a joint's present position becomes 0° (register 0x0E := 1).

use robobus_wck::BaudRate;
use robobus_whj::Request as Wire;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::{JointRow, joint, plan_of};
use crate::catalogue::operation::{Confirm, OpDoc, Operation, Report, RunCx};
use crate::catalogue::plan::WhjSteps;
use crate::catalogue::wck::request;
use crate::catalogue::{Effect, Family, Plan};
use crate::ops::whj::{self as ops, ZeroReport};
use crate::ops::{DeviceResult, OpError};

request!(cli
    /// `whj.zero`: the present position becomes 0° (register 0x0E := 1).
    Zero {
        /// Joint ID, 1..=30.
        #[cfg_attr(feature = "cli", arg(value_parser = crate::catalogue::whj::cli::joint))]
        joint: u32,
    }
);

impl Operation for Zero {
    const OP: &'static str = "whj.zero";
    const FAMILY: Family = Family::Whj;
    const DOC: OpDoc = OpDoc {
        args: "`joint`",
        report: "one row: `position_deg` (read after the zero)",
        confirm: "-",
    };
    type Row = JointRow<ZeroReport>;
    type Summary = ();

    fn bus(&self) -> Option<&str> {
        self.bus.as_deref()
    }

    fn effect(&self) -> Effect {
        Effect::Configure
    }

    fn check(&self) -> Result<Confirm, OpError> {
        joint("<JOINT>", self.joint).map(|_| Confirm::NONE)
    }

    fn plan(&self, _baud: BaudRate) -> Result<Plan, OpError> {
        let mut steps = WhjSteps::default();
        steps.push(Wire::set_zero(joint("<JOINT>", self.joint)?));
        Ok(plan_of(Self::OP, steps, true, Confirm::NONE))
    }

    fn run(&self, cx: &mut RunCx<'_, '_>) -> Result<Report<Self::Row, ()>, OpError> {
        let j = joint("<JOINT>", self.joint)?;
        let port = cx.station.whj(self.bus())?;
        let row = DeviceResult::ok(j.get(), ops::zero(port.bus(), j)?);
        Ok(Report::devices(Self::OP, port.name(), vec![row]))
    }
}
