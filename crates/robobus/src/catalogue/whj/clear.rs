//! `whj.clear`: latched errors cleared (register 0x0F := 1), the error bits read before
//! and after.

use robobus_wck::BaudRate;
use robobus_whj::Request as Wire;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::{JointRow, bus_report, each, joint_list, plan_of};
use crate::catalogue::args::Ids;
use crate::catalogue::operation::{Confirm, OpDoc, Operation, Report, RunCx};
use crate::catalogue::wck::request;
use crate::catalogue::{Effect, Family, Plan};
use crate::ops::OpError;
use crate::ops::whj::{self as ops, ClearReport};

request!(cli
    /// `whj.clear`: clear latched errors (0x0F := 1).
    Clear {
        /// Joint IDs, e.g. `1-7`.
        #[cfg_attr(feature = "cli", arg(value_parser = crate::catalogue::whj::cli::joints))]
        joints: Ids,
    }
);

impl Operation for Clear {
    const OP: &'static str = "whj.clear";
    const FAMILY: Family = Family::Whj;
    const DOC: OpDoc = OpDoc {
        args: "`joints`",
        report: "per joint: `error_before`, `error_after` (bits whose cause persists stay set)",
        confirm: "-",
    };
    type Row = JointRow<ClearReport>;
    type Summary = ();

    fn bus(&self) -> Option<&str> {
        self.bus.as_deref()
    }

    fn effect(&self) -> Effect {
        Effect::Configure
    }

    fn check(&self) -> Result<Confirm, OpError> {
        joint_list(&self.joints).map(|_| Confirm::NONE)
    }

    fn plan(&self, _baud: BaudRate) -> Result<Plan, OpError> {
        let ids = joint_list(&self.joints)?;
        let steps = each(&ids, Wire::clear_error);
        Ok(plan_of(Self::OP, steps, true, Confirm::NONE))
    }

    fn run(&self, cx: &mut RunCx<'_, '_>) -> Result<Report<Self::Row, ()>, OpError> {
        let ids = joint_list(&self.joints)?;
        bus_report(cx, Self::OP, self.bus(), |b| Ok(ops::clear(b, &ids)))
    }
}
