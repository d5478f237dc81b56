//! `whj.info`: a joint's identity, unique ID, work mode and position limits.

use robobus_wck::BaudRate;
use robobus_whj::Request as Wire;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::{JointRow, joint, joint_report, plan_of};
use crate::catalogue::operation::{Confirm, OpDoc, Operation, Report, RunCx};
use crate::catalogue::plan::WhjSteps;
use crate::catalogue::wck::request;
use crate::catalogue::{Effect, Family, Plan};
use crate::ops::OpError;
use crate::ops::whj::{self as ops, InfoReport};

request!(cli
    /// `whj.info`: identity, unique ID and position limits of a joint.
    Info {
        /// Joint ID, 1..=30.
        #[cfg_attr(feature = "cli", arg(value_parser = crate::catalogue::whj::cli::joint))]
        joint: u32,
    }
);

impl Operation for Info {
    const OP: &'static str = "whj.info";
    const FAMILY: Family = Family::Whj;
    const DOC: OpDoc = OpDoc {
        args: "`joint`",
        report: "one row: `model`, `firmware`, `node_id`, `reduction`, `unique_id`, `mode`, \
                 `min_deg`, `max_deg`",
        confirm: "-",
    };
    type Row = JointRow<InfoReport>;
    type Summary = ();

    fn bus(&self) -> Option<&str> {
        self.bus.as_deref()
    }

    fn effect(&self) -> Effect {
        Effect::Read
    }

    fn check(&self) -> Result<Confirm, OpError> {
        joint("<JOINT>", self.joint).map(|_| Confirm::NONE)
    }

    fn plan(&self, _baud: BaudRate) -> Result<Plan, OpError> {
        let j = joint("<JOINT>", self.joint)?;
        let mut steps = WhjSteps::default();
        steps.push(Wire::read_identity(j));
        steps.push(Wire::read_unique_id(j));
        steps.push(Wire::read_position_limits(j));
        steps.push(Wire::StatusQuery { joint: j });
        Ok(plan_of(Self::OP, steps, true, Confirm::NONE))
    }

    fn run(&self, cx: &mut RunCx<'_, '_>) -> Result<Report<Self::Row, ()>, OpError> {
        let j = joint("<JOINT>", self.joint)?;
        joint_report(cx, Self::OP, self.bus(), j, |b| ops::info(b, j))
    }
}
