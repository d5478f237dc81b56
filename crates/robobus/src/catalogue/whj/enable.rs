//! `whj.enable`: the drive enable register (0x0A) := 1, the state read back (also how
//! `whj.disable` runs).

use robobus_wck::BaudRate;
use robobus_whj::Request as Wire;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::{JointRow, bus_report, each, joint_list, moved, plan_of};
use crate::catalogue::args::Ids;
use crate::catalogue::operation::{Confirm, OpDoc, Operation, Report, RunCx};
use crate::catalogue::wck::request;
use crate::catalogue::{Effect, Family, Moved, Plan};
use crate::ops::OpError;
use crate::ops::whj::{self as ops, EnableReport, ServoLoop};

request!(cli
    /// `whj.enable`: register 0x0A := 1.
    Enable {
        /// Joint IDs, e.g. `1-7`.
        #[cfg_attr(feature = "cli", arg(value_parser = crate::catalogue::whj::cli::joints))]
        joints: Ids,
    }
);

/// The report of `whj.enable` / `whj.disable` on `joints`: each joint's state read back.
pub(super) fn run(
    op: &str,
    bus: Option<&str>,
    joints: &Ids,
    on: bool,
    cx: &RunCx<'_, '_>,
) -> Result<Report<JointRow<EnableReport>, ()>, OpError> {
    let ids = joint_list(joints)?;
    bus_report(cx, op, bus, |b| Ok(ops::enable(b, &ids, on)))
}

/// The plan of `whj.enable` / `whj.disable` on `joints`.
pub(super) fn plan(op: &str, joints: &Ids, on: bool) -> Result<Plan, OpError> {
    let ids = joint_list(joints)?;
    Ok(plan_of(
        op,
        each(&ids, |j| Wire::enable(j, on)),
        true,
        Confirm::NONE,
    ))
}

pub(super) const DOC_REPORT: &str = "per joint: `enabled`, `error` (the state read back; a joint left in \
                          the other state, or enabled with error bits, fails)";

impl Operation for Enable {
    const OP: &'static str = "whj.enable";
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
        Effect::Motion
    }

    fn moved(&self) -> Result<Option<Moved>, OpError> {
        self.check()?;
        let ids = self.joints.parse::<robobus_whj::JointId>("joints")?;
        Ok(Some(moved(
            self.bus(),
            ids.iter().map(|j| j.get()).collect(),
            ServoLoop::Position,
        )))
    }

    fn check(&self) -> Result<Confirm, OpError> {
        joint_list(&self.joints).map(|_| Confirm::NONE)
    }

    fn plan(&self, _baud: BaudRate) -> Result<Plan, OpError> {
        plan(Self::OP, &self.joints, true)
    }

    fn run(&self, cx: &mut RunCx<'_, '_>) -> Result<Report<Self::Row, ()>, OpError> {
        run(Self::OP, self.bus(), &self.joints, true, cx)
    }
}
