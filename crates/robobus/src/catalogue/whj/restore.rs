//! `whj.restore`: a settings file written back where the joint differs, saved to flash
//! and read back.

use robobus_wck::BaudRate;
use robobus_whj::JointId;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::settings::settings_reads;
use super::{R, joint, plan_of};
use crate::catalogue::bounds::{ConfirmClass, NON_VOLATILE_TEXT};
use crate::catalogue::operation::{Confirm, OpDoc, Operation, Report, RunCx};
use crate::catalogue::wck::request;
use crate::catalogue::{Effect, Family, Plan};
use crate::ops::whj::settings::{self as ops, RestoreStep, Settings};
use crate::ops::{DeviceResult, OpError};

request!(
    /// `whj.restore`: writes a settings file's values where the joint differs, saves them
    /// to flash and reads them back; the bus identity (ID, bit rates) is never written.
    Restore {
        /// Joint ID, 1..=30.
        joint: u32,
        /// The settings file's text.
        settings: String,
        /// Confirms the flash write (and registers of the `confirm` class).
        #[serde(default)]
        confirm: bool,
    }
);

/// What a restore did, beside its rows.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, JsonSchema)]
pub struct RestoreSummary {
    /// Registers written.
    pub written: usize,
    /// Whether the RAM table was saved to flash (only when something was written).
    pub saved: bool,
    /// The registers that differ after the restore: none but the skipped ones.
    pub differ_after: Vec<String>,
}

impl Restore {
    fn parsed(&self) -> R<(JointId, Settings)> {
        Ok((
            joint("<JOINT>", self.joint)?,
            Settings::parse(&self.settings)?,
        ))
    }
}

/// The flash write, and the registers of the `confirm` class the file sets.
fn confirm_of(s: &Settings) -> Confirm {
    let needs = ops::confirm_needed(s);
    let text = if needs.is_empty() {
        NON_VOLATILE_TEXT.into()
    } else {
        format!(
            "{NON_VOLATILE_TEXT} Where the joint differs, the file also sets {}.",
            needs
                .iter()
                .map(|(r, what)| format!("{r} (it {what})"))
                .collect::<Vec<_>>()
                .join("; ")
        )
    };
    Confirm::of(ConfirmClass::NonVolatile, text)
}

impl Operation for Restore {
    const OP: &'static str = "whj.restore";
    const FAMILY: Family = Family::Whj;
    const DOC: OpDoc = OpDoc {
        args: "`joint`, `settings`",
        report: "one row per differing setting: written or skipped (the bus identity is never \
                 written); `summary`: `written`, `saved`, `differ_after`",
        confirm: "flash (and the `confirm` registers the file sets)",
    };
    type Row = DeviceResult<u8, RestoreStep>;
    type Summary = RestoreSummary;

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
        self.parsed().map(|(_, s)| confirm_of(&s))
    }

    /// The reads, then what the run writes (noted), with the flash confirmation.
    fn plan(&self, _baud: BaudRate) -> R<Plan> {
        let (j, s) = self.parsed()?;
        let mut p = settings_reads(j);
        p.notes.push(format!(
            "then writes the file's value of each setting that differs ({} settings in \
             the file, of a {} with firmware {}; never SYS_ID or the bit rates), saves \
             them to flash and reads them back; refused while the joint is enabled, or \
             is another model or firmware",
            s.settings.len(),
            s.model,
            s.firmware
        ));
        Ok(plan_of(Self::OP, p, true, confirm_of(&s)))
    }

    fn run(&self, cx: &mut RunCx<'_, '_>) -> Result<Report<Self::Row, RestoreSummary>, OpError> {
        let (j, s) = self.parsed()?;
        let port = cx.station.whj(self.bus())?;
        let r = ops::restore(port.bus(), j, &s, self.confirm)?;
        let rows = r
            .steps
            .into_iter()
            .map(|x| DeviceResult::ok(j.get(), x))
            .collect();
        Ok(
            Report::with_rows(Self::OP, port.name(), rows).summary(RestoreSummary {
                written: r.written,
                saved: r.saved,
                differ_after: r.differ_after,
            }),
        )
    }
}
