//! `wck.restore`: a settings file (or the factory settings) written into a servo's
//! EEPROM where it differs.

use robobus_wck::{BaudRate, ServoId};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::{IdRow, R, confirm_of, plan_of, settings_of, settings_reads, sid};
use crate::catalogue::bounds::ConfirmClass;
use crate::catalogue::operation::{Confirm, OpDoc, Operation, Report, RunCx};
use crate::catalogue::{Effect, Family, Plan};
use crate::ops::OpError;
use crate::ops::wck::WckPlan;
use crate::ops::wck::settings::{self as wsettings, WckRestoreStep, WckSettings};

request!(cli
    /// `wck.restore`: writes a settings file (or the factory settings) into a servo's
    /// EEPROM where it differs, each write verified; needs `confirm`.
    Restore {
        /// Servo ID, 0..=30.
        #[cfg_attr(feature = "cli", arg(value_parser = crate::catalogue::wck::cli::servo_id))]
        id: u32,
        /// A settings file's text.
        #[serde(default)]
        #[cfg_attr(feature = "cli", arg(skip))]
        settings: Option<String>,
        /// Restore the factory settings (the manual's A-5) instead of a file.
        #[serde(default)]
        #[cfg_attr(feature = "cli", arg(long))]
        factory: bool,
        /// Confirms the EEPROM writes.
        #[serde(default)]
        #[cfg_attr(feature = "cli", arg(skip))]
        confirm: bool,
    }
);

/// What a `wck.restore` wrote.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, JsonSchema)]
pub struct RestoreSummary {
    /// EEPROM writes made (one per group that differed).
    pub written: usize,
}

impl Restore {
    /// The servo and the settings to write, validated.
    fn parsed(&self) -> R<(ServoId, WckSettings)> {
        let id = sid(self.id)?;
        let s = settings_of(self.settings.as_ref(), self.factory)?.ok_or_else(|| {
            OpError::invalid(
                "settings / factory",
                "neither",
                "give a settings file or the factory settings",
            )
        })?;
        Ok((id, s))
    }
}

impl Operation for Restore {
    const OP: &'static str = "wck.restore";
    const FAMILY: Family = Family::Wck;
    const DOC: OpDoc = OpDoc {
        args: "`id`, `settings` or `factory`",
        report: "one row per group written (`setting`, `from`, `to`; only those that \
                 differ, each verified); `summary`: `written`",
        confirm: "EEPROM",
    };
    type Row = IdRow<WckRestoreStep>;
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

    fn check(&self) -> Result<Confirm, OpError> {
        self.parsed()?;
        Ok(confirm_of(ConfirmClass::NonVolatile))
    }

    fn plan(&self, baud: BaudRate) -> Result<Plan, OpError> {
        let (id, _) = self.parsed()?;
        let mut plan = WckPlan::default();
        settings_reads(&mut plan, id);
        plan.notes.push(
            "then one EEPROM write (about 121 ms, verified by the servo's read-back) per \
             group that differs: gains, I gain, speed, over-load, boundaries; then the \
             settings are read again"
                .into(),
        );
        Ok(plan_of(Self::OP, &plan, baud, ConfirmClass::NonVolatile))
    }

    fn run(
        &self,
        cx: &mut RunCx<'_, '_>,
    ) -> Result<Report<IdRow<WckRestoreStep>, RestoreSummary>, OpError> {
        let (id, s) = self.parsed()?;
        let port = cx.station.wck(self.bus())?;
        let r = wsettings::restore(&mut *port.lock(), id, &s)?;
        let rows = r
            .steps
            .into_iter()
            .map(|value| IdRow {
                id: id.get(),
                value,
            })
            .collect();
        let summary = RestoreSummary { written: r.written };
        Ok(Report::with_rows(Self::OP, port.name(), rows).summary(summary))
    }
}
