//! `wck.diff`: the settings on which a servo differs from a settings file, the factory
//! settings, or another servo.

use robobus_wck::{BaudRate, ServoId};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::{IdRow, R, plan_of, settings_of, settings_reads, sid};
use crate::catalogue::args::byte;
use crate::catalogue::bounds::ConfirmClass;
use crate::catalogue::operation::{Confirm, OpDoc, Operation, Report, RunCx};
use crate::catalogue::{Effect, Family, Plan};
use crate::ops::OpError;
use crate::ops::wck::WckPlan;
use crate::ops::wck::settings::{self as wsettings, WckSettingDiff, WckSettings};

request!(cli
    /// `wck.diff`: the settings on which a servo differs from a settings file, the
    /// factory settings, or another servo.
    Diff {
        /// Servo ID, 0..=30.
        #[cfg_attr(feature = "cli", arg(value_parser = crate::catalogue::wck::cli::servo_id))]
        id: u32,
        /// A settings file's text (what `wck.backup` gives).
        #[serde(default)]
        #[cfg_attr(feature = "cli", arg(skip))]
        settings: Option<String>,
        /// Compare with the manual's factory settings.
        #[serde(default)]
        #[cfg_attr(feature = "cli", arg(long, conflicts_with = "other"))]
        factory: bool,
        /// Compare with this servo, 0..=30.
        #[serde(default)]
        #[cfg_attr(feature = "cli", arg(long = "with", value_name = "ID", value_parser = crate::catalogue::wck::cli::servo_id))]
        other: Option<u32>,
    }
);

/// What a `wck.diff` found.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, JsonSchema)]
pub struct DiffSummary {
    /// How many groups differ.
    pub differ: usize,
    /// What the servo was compared with (`the factory settings`, `the file (servo 3)`,
    /// `servo 4`).
    pub with: String,
}

/// What a servo is compared with.
enum With {
    /// A settings file, or the factory settings.
    File(WckSettings),
    /// Another servo.
    Servo(ServoId),
}

impl Diff {
    /// The servo and what it is compared with, validated.
    fn parsed(&self) -> R<(ServoId, With)> {
        let id = sid(self.id)?;
        let with = match (
            settings_of(self.settings.as_ref(), self.factory)?,
            self.other,
        ) {
            (Some(s), None) => With::File(s),
            (None, Some(o)) => {
                let o = byte("--with", o, ServoId::new)?;
                if o == id {
                    return Err(OpError::invalid("--with", o.get(), "the servo itself"));
                }
                With::Servo(o)
            }
            _ => {
                return Err(OpError::invalid(
                    "settings / factory / other",
                    "none or several",
                    "give one: a settings file, the factory settings or another servo",
                ));
            }
        };
        Ok((id, with))
    }
}

impl Operation for Diff {
    const OP: &'static str = "wck.diff";
    const FAMILY: Family = Family::Wck;
    const DOC: OpDoc = OpDoc {
        args: "`id`, `settings` (a settings file's text), `factory` or `other` (a servo)",
        report: "one row per group that differs (`setting`, `a`, `b`); `summary`: \
                 `differ`, `with`",
        confirm: "-",
    };
    type Row = IdRow<WckSettingDiff>;
    type Summary = DiffSummary;

    fn bus(&self) -> Option<&str> {
        self.bus.as_deref()
    }

    fn effect(&self) -> Effect {
        Effect::Read
    }

    fn check(&self) -> Result<Confirm, OpError> {
        self.parsed().map(|_| Confirm::NONE)
    }

    fn plan(&self, baud: BaudRate) -> Result<Plan, OpError> {
        let (id, with) = self.parsed()?;
        let mut plan = WckPlan::default();
        settings_reads(&mut plan, id);
        if let With::Servo(o) = with {
            settings_reads(&mut plan, o);
        }
        Ok(plan_of(Self::OP, &plan, baud, ConfirmClass::None))
    }

    fn run(
        &self,
        cx: &mut RunCx<'_, '_>,
    ) -> Result<Report<IdRow<WckSettingDiff>, DiffSummary>, OpError> {
        let (id, with) = self.parsed()?;
        let port = cx.station.wck(self.bus())?;
        let mut bus = port.lock();
        let a = wsettings::backup(&mut bus, id)?;
        let (b, with) = match with {
            With::File(s) => (
                s,
                s.servo.map_or_else(
                    || "the factory settings".into(),
                    |n| format!("the file (servo {n})"),
                ),
            ),
            With::Servo(o) => (
                wsettings::backup(&mut bus, o)?,
                format!("servo {}", o.get()),
            ),
        };
        let rows: Vec<_> = wsettings::diff(&a, &b)
            .into_iter()
            .map(|value| IdRow {
                id: id.get(),
                value,
            })
            .collect();
        let summary = DiffSummary {
            differ: rows.len(),
            with,
        };
        Ok(Report::with_rows(Self::OP, port.name(), rows).summary(summary))
    }
}
