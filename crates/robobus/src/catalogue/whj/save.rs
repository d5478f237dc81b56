//! `whj.save`: the register table saved to flash (needs `confirm`).

use robobus_wck::BaudRate;
use robobus_whj::Request as Wire;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::{JointRow, bus_report, each, joint_list, plan_of};
use crate::catalogue::args::Ids;
use crate::catalogue::bounds::{ConfirmClass, NON_VOLATILE_TEXT};
use crate::catalogue::operation::{Confirm, OpDoc, Operation, Report, RunCx};
use crate::catalogue::wck::request;
use crate::catalogue::{Effect, Family, Plan};
use crate::ops::OpError;
use crate::ops::whj::{self as ops, SaveReport};

request!(cli
    /// `whj.save`: save the register table to flash; needs `confirm`.
    Save {
        /// Joint IDs, e.g. `1-7`.
        #[cfg_attr(feature = "cli", arg(value_parser = crate::catalogue::whj::cli::joints))]
        joints: Ids,
        /// Confirms the flash write.
        #[serde(default)]
        #[cfg_attr(feature = "cli", arg(skip))]
        confirm: bool,
    }
);

impl Operation for Save {
    const OP: &'static str = "whj.save";
    const FAMILY: Family = Family::Whj;
    const DOC: OpDoc = OpDoc {
        args: "`joints`, `confirm`",
        report: "per joint: `saved` (refused while a joint is enabled)",
        confirm: "flash",
    };
    type Row = JointRow<SaveReport>;
    type Summary = ();

    fn bus(&self) -> Option<&str> {
        self.bus.as_deref()
    }

    fn effect(&self) -> Effect {
        Effect::Configure
    }

    fn confirmed(&self) -> bool {
        self.confirm
    }

    fn confirm(&mut self) {
        self.confirm = true;
    }

    fn check(&self) -> Result<Confirm, OpError> {
        joint_list(&self.joints)?;
        Ok(Confirm::of(ConfirmClass::NonVolatile, NON_VOLATILE_TEXT))
    }

    fn plan(&self, _baud: BaudRate) -> Result<Plan, OpError> {
        let ids = joint_list(&self.joints)?;
        let mut steps = each(&ids, Wire::save_to_flash);
        steps
            .notes
            .push("the joints must be disabled; each needs ~50 ms to write flash".into());
        Ok(plan_of(Self::OP, steps, true, self.check()?))
    }

    fn run(&self, cx: &mut RunCx<'_, '_>) -> Result<Report<Self::Row, ()>, OpError> {
        let ids = joint_list(&self.joints)?;
        bus_report(cx, Self::OP, self.bus(), |b| Ok(ops::save(b, &ids)))
    }
}
