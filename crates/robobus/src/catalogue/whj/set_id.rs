//! `whj.set-id`: a joint's new ID, saved to flash.

use robobus_wck::BaudRate;
use robobus_whj::JointId;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::{R, joint, joint_report, plan_of};
use crate::catalogue::bounds::{ConfirmClass, NON_VOLATILE_TEXT};
use crate::catalogue::operation::{Confirm, OpDoc, Operation, Report, RunCx};
use crate::catalogue::plan::WhjSteps;
use crate::catalogue::wck::request;
use crate::catalogue::{Effect, Family, Plan};
use crate::ops::whj::{self as hops, SetIdReport};
use crate::ops::{DeviceResult, OpError};

request!(cli
    /// `whj.set-id`: new ID, saved to flash; needs `confirm`.
    SetId {
        /// Current joint ID, 1..=30.
        #[cfg_attr(feature = "cli", arg(value_parser = crate::catalogue::whj::cli::joint))]
        joint: u32,
        /// New joint ID, 1..=30.
        #[cfg_attr(feature = "cli", arg(value_parser = crate::catalogue::whj::cli::joint))]
        new_id: u32,
        /// Confirms the ID change.
        #[serde(default)]
        #[cfg_attr(feature = "cli", arg(skip))]
        confirm: bool,
    }
);

impl SetId {
    fn ids(&self) -> R<(JointId, JointId)> {
        Ok((
            joint("<JOINT>", self.joint)?,
            joint("<NEW_ID>", self.new_id)?,
        ))
    }
}

/// What an ID change needs confirmed.
fn confirm() -> Confirm {
    Confirm::of(ConfirmClass::Id, NON_VOLATILE_TEXT)
}

impl Operation for SetId {
    const OP: &'static str = "whj.set-id";
    const FAMILY: Family = Family::Whj;
    const DOC: OpDoc = OpDoc {
        args: "`joint`, `new_id`",
        report: "set-id report",
        confirm: "ID",
    };
    type Row = DeviceResult<u8, SetIdReport>;
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

    fn check(&self) -> R<Confirm> {
        let (j, new_id) = self.ids()?;
        hops::plan_set_id(j, new_id)?;
        Ok(confirm())
    }

    fn plan(&self, _baud: BaudRate) -> R<Plan> {
        let (j, new_id) = self.ids()?;
        let (frames, note) = hops::plan_set_id(j, new_id)?;
        let mut p = WhjSteps::default();
        for f in frames {
            p.push(f);
        }
        p.notes.push(note);
        Ok(plan_of(Self::OP, p, true, confirm()))
    }

    fn run(&self, cx: &mut RunCx<'_, '_>) -> Result<Report<Self::Row, ()>, OpError> {
        let (j, new_id) = self.ids()?;
        joint_report(cx, Self::OP, self.bus(), j, |b| hops::set_id(b, j, new_id))
    }
}
