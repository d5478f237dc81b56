//! `whj.mode`: the work mode register (0x30) written, the mode read back.

use robobus_wck::BaudRate;
use robobus_whj::Request as Wire;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::{JointRow, ModeName, bus_report, each, joint_list, plan_of, work_mode};
use crate::catalogue::args::Ids;
use crate::catalogue::operation::{Confirm, OpDoc, Operation, Report, RunCx};
use crate::catalogue::wck::request;
use crate::catalogue::{Effect, Family, Plan};
use crate::ops::OpError;
use crate::ops::whj::{self as ops, ModeReport};

request!(cli
    /// `whj.mode`: work mode (register 0x30).
    Mode {
        /// Joint IDs, e.g. `1-7`.
        #[cfg_attr(feature = "cli", arg(value_parser = crate::catalogue::whj::cli::joints))]
        joints: Ids,
        /// The mode: `open-loop`, `current`, `speed` or `position`.
        mode: ModeName,
    }
);

impl Operation for Mode {
    const OP: &'static str = "whj.mode";
    const FAMILY: Family = Family::Whj;
    const DOC: OpDoc = OpDoc {
        args: "`joints`, `mode` (open-loop, current, speed, position)",
        report: "per joint: `mode` (read back; a joint that reports another mode fails)",
        confirm: "-",
    };
    type Row = JointRow<ModeReport>;
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
        let mode = work_mode(self.mode);
        let steps = each(&ids, |j| Wire::set_mode(j, mode));
        Ok(plan_of(Self::OP, steps, true, Confirm::NONE))
    }

    fn run(&self, cx: &mut RunCx<'_, '_>) -> Result<Report<Self::Row, ()>, OpError> {
        let ids = joint_list(&self.joints)?;
        bus_report(cx, Self::OP, self.bus(), |b| {
            Ok(ops::set_mode(b, &ids, work_mode(self.mode)))
        })
    }
}
