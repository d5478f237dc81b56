//! `wck.backup`: a servo's settings, as a settings file.

use robobus_wck::BaudRate;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::{IdRow, plan_of, settings_reads, sid};
use crate::catalogue::bounds::ConfirmClass;
use crate::catalogue::operation::{Confirm, OpDoc, Operation, Report, RunCx};
use crate::catalogue::{Effect, Family, Plan};
use crate::ops::OpError;
use crate::ops::wck::WckPlan;
use crate::ops::wck::settings::{self as wsettings, WckSettings};

request!(cli
    /// `wck.backup`: a servo's settings (gains, I gain, speed, over-load, boundaries) as
    /// the settings file (the report's `summary`).
    Backup {
        /// Servo ID, 0..=30.
        #[cfg_attr(feature = "cli", arg(value_parser = crate::catalogue::wck::cli::servo_id))]
        id: u32,
    }
);

impl Operation for Backup {
    const OP: &'static str = "wck.backup";
    const FAMILY: Family = Family::Wck;
    const DOC: OpDoc = OpDoc {
        args: "`id`",
        report: "one row, the settings file's fields (`format`, `version`, `servo`, \
                 `p_gain`, `d_gain`, `i_gain`, `speed`, `accel`, `overload`, `lower`, \
                 `upper`); `summary` is the settings file",
        confirm: "-",
    };
    type Row = IdRow<WckSettings>;
    type Summary = WckSettings;

    fn bus(&self) -> Option<&str> {
        self.bus.as_deref()
    }

    fn effect(&self) -> Effect {
        Effect::Read
    }

    fn check(&self) -> Result<Confirm, OpError> {
        sid(self.id).map(|_| Confirm::NONE)
    }

    fn plan(&self, baud: BaudRate) -> Result<Plan, OpError> {
        let mut plan = WckPlan::default();
        settings_reads(&mut plan, sid(self.id)?);
        Ok(plan_of(Self::OP, &plan, baud, ConfirmClass::None))
    }

    fn run(
        &self,
        cx: &mut RunCx<'_, '_>,
    ) -> Result<Report<IdRow<WckSettings>, WckSettings>, OpError> {
        let id = sid(self.id)?;
        let port = cx.station.wck(self.bus())?;
        let s = wsettings::backup(&mut *port.lock(), id)?;
        let row = IdRow {
            id: id.get(),
            value: s,
        };
        Ok(Report::with_rows(Self::OP, port.name(), vec![row]).summary(s))
    }
}
