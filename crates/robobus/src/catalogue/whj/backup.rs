//! `whj.backup`: every setting of a joint, as a settings file.

use robobus_wck::BaudRate;
use robobus_whj::JointId;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::settings::{SettingsRow, settings_reads, settings_run};
use super::{R, joint, plan_of};
use crate::catalogue::operation::{Confirm, OpDoc, Operation, Report, RunCx};
use crate::catalogue::plan::WhjSteps;
use crate::catalogue::wck::request;
use crate::catalogue::{Effect, Family, Plan};
use crate::ops::whj::settings::{self as ops, Settings};
use crate::ops::{DeviceResult, OpError};

request!(cli
    /// `whj.backup`: every setting of a joint (the registers it keeps in flash), as the
    /// settings file (the report's `summary`).
    Backup {
        /// Joint ID, 1..=30.
        #[cfg_attr(feature = "cli", arg(value_parser = crate::catalogue::whj::cli::joint))]
        joint: u32,
    }
);

impl Backup {
    fn joint(&self) -> R<JointId> {
        joint("<JOINT>", self.joint)
    }
}

impl Operation for Backup {
    const OP: &'static str = "whj.backup";
    const FAMILY: Family = Family::Whj;
    const DOC: OpDoc = OpDoc {
        args: "`joint`",
        report: "model, firmware, settings count; `summary` is the settings file (every \
                 register the joint keeps in flash, raw and in its unit)",
        confirm: "-",
    };
    type Row = DeviceResult<u8, SettingsRow>;
    type Summary = Settings;

    fn bus(&self) -> Option<&str> {
        self.bus.as_deref()
    }

    fn effect(&self) -> Effect {
        Effect::Read
    }

    fn check(&self) -> R<Confirm> {
        self.joint().map(|_| Confirm::NONE)
    }

    fn plan(&self, _baud: BaudRate) -> R<Plan> {
        let mut p: WhjSteps = settings_reads(self.joint()?);
        p.notes.push(
            "reads every setting (the registers kept in flash) the joint's model and \
             firmware have; the report's summary is the settings file"
                .into(),
        );
        Ok(plan_of(Self::OP, p, true, Confirm::NONE))
    }

    fn run(&self, cx: &mut RunCx<'_, '_>) -> Result<Report<Self::Row, Settings>, OpError> {
        settings_run(cx, Self::OP, self.bus(), self.joint()?, ops::backup)
    }
}
