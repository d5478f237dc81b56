//! `whj.defaults`: the settings whose factory value the vendor documents for a joint's
//! model and firmware, as a settings file for `whj.restore`.

use robobus_wck::BaudRate;
use robobus_whj::registers::addr;
use robobus_whj::{JointId, Request as Wire};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::settings::{SettingsRow, settings_run};
use super::{R, joint, plan_of};
use crate::catalogue::operation::{Confirm, OpDoc, Operation, Report, RunCx};
use crate::catalogue::plan::WhjSteps;
use crate::catalogue::wck::request;
use crate::catalogue::{Effect, Family, Plan};
use crate::ops::whj::settings::{self as ops, Settings};
use crate::ops::{DeviceResult, OpError};

request!(cli
    /// `whj.defaults`: the settings whose factory value the vendor documents, for the
    /// joint's model and firmware, as a settings file (the report's `summary`) that
    /// `whj.restore` writes back (the joints have no factory reset of their own).
    Defaults {
        /// Joint ID, 1..=30.
        #[cfg_attr(feature = "cli", arg(value_parser = crate::catalogue::whj::cli::joint))]
        joint: u32,
    }
);

impl Defaults {
    fn joint(&self) -> R<JointId> {
        joint("<JOINT>", self.joint)
    }
}

impl Operation for Defaults {
    const OP: &'static str = "whj.defaults";
    const FAMILY: Family = Family::Whj;
    const DOC: OpDoc = OpDoc {
        args: "`joint`",
        report: "model, firmware, settings count; `summary` is a settings file of the values \
                 the vendor documents for that model and firmware (modes at power-up, speed \
                 and acceleration limits, following error, feature switches; not the gains \
                 and current and position limits tuned per joint, nor the ID and bit rates), \
                 for `whj.restore`: the joints have no factory reset",
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

    /// The identity reads (model, firmware); nothing is written.
    fn plan(&self, _baud: BaudRate) -> R<Plan> {
        let j = self.joint()?;
        let mut p = WhjSteps::default();
        for (addr, count) in [(addr::SYS_MODEL_TYPE, 1), (addr::SYS_FW_VERSION, 1)] {
            if let Ok(req) = Wire::read(j, addr, count) {
                p.push(req);
            }
        }
        p.notes.push(
            "reads the joint's model and firmware (as it connects); the report's summary is \
             the settings file of the values the vendor documents for them (modes at \
             power-up, speed and acceleration limits, following error, feature switches; not \
             the gains, current and position limits the vendor tunes per joint, nor the ID \
             and bit rates); `whj.restore` writes it back"
                .into(),
        );
        Ok(plan_of(Self::OP, p, true, Confirm::NONE))
    }

    fn run(&self, cx: &mut RunCx<'_, '_>) -> Result<Report<Self::Row, Settings>, OpError> {
        settings_run(cx, Self::OP, self.bus(), self.joint()?, ops::defaults)
    }
}
