//! `whj.disable`: the drive enable register (0x0A) := 0, the state read back.

use robobus_wck::BaudRate;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::enable::{DOC_REPORT, plan, run};
use super::{JointRow, joint_list};
use crate::catalogue::args::Ids;
use crate::catalogue::operation::{Confirm, OpDoc, Operation, Report, RunCx};
use crate::catalogue::wck::request;
use crate::catalogue::{Effect, Family, Plan};
use crate::ops::OpError;
use crate::ops::whj::EnableReport;

request!(cli
    /// `whj.disable`: register 0x0A := 0.
    Disable {
        /// Joint IDs, e.g. `1-7`.
        #[cfg_attr(feature = "cli", arg(value_parser = crate::catalogue::whj::cli::joints))]
        joints: Ids,
    }
);

impl Operation for Disable {
    const OP: &'static str = "whj.disable";
    const FAMILY: Family = Family::Whj;
    const DOC: OpDoc = OpDoc {
        args: "`joints`",
        report: DOC_REPORT,
        confirm: "-",
    };
    type Row = JointRow<EnableReport>;
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
        plan(Self::OP, &self.joints, false)
    }

    fn run(&self, cx: &mut RunCx<'_, '_>) -> Result<Report<Self::Row, ()>, OpError> {
        run(Self::OP, self.bus(), &self.joints, false, cx)
    }
}
