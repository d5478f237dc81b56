//! `whj.diff`: the settings on which a joint differs from a settings file, or from
//! another joint.

use robobus_wck::BaudRate;
use robobus_whj::JointId;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::settings::{DiffWith, settings_reads};
use super::{R, joint, plan_of};
use crate::catalogue::operation::{Confirm, OpDoc, Operation, Report, RunCx};
use crate::catalogue::wck::request;
use crate::catalogue::{Effect, Family, Plan};
use crate::ops::whj::settings::{self as ops, SettingDiff};
use crate::ops::{DeviceResult, OpError};

request!(
    /// `whj.diff`: the settings on which a joint differs from a settings file, or from
    /// another joint.
    Diff {
        /// Joint ID, 1..=30.
        joint: u32,
        /// A settings file's text (what `whj.backup` gives).
        #[serde(default)]
        settings: Option<String>,
        /// Another joint to compare with, instead of a file.
        #[serde(default)]
        other: Option<u32>,
    }
);

/// What a diff found.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, JsonSchema)]
pub struct DiffSummary {
    /// How many settings differ.
    pub differ: usize,
    /// What the joint was compared with: `the file (joint N)` or `joint N`.
    pub with: String,
    /// Against a file: how many of the joint's settings the file leaves out.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub left_out: Option<usize>,
}

impl Diff {
    /// The joint and what it is compared with, validated.
    pub(crate) fn parsed(&self) -> R<(JointId, DiffWith)> {
        let j = joint("<JOINT>", self.joint)?;
        let with = match (&self.settings, self.other) {
            (Some(text), None) => DiffWith::File(Box::new(ops::Settings::parse(text)?)),
            (None, Some(o)) => {
                let o = joint("--with", o)?;
                if o == j {
                    return Err(OpError::invalid(
                        "--with",
                        o.get(),
                        "the joint itself: give another joint",
                    ));
                }
                DiffWith::Joint(o)
            }
            _ => {
                return Err(OpError::invalid(
                    "settings / other",
                    "both or neither",
                    "give one: a settings file or another joint",
                ));
            }
        };
        Ok((j, with))
    }
}

impl Operation for Diff {
    const OP: &'static str = "whj.diff";
    const FAMILY: Family = Family::Whj;
    const DOC: OpDoc = OpDoc {
        args: "`joint`, `settings` (a settings file's text) or `other` (a joint)",
        report: "one row per setting that differs (`a`, `b`, values and unit); against a file \
                 only the settings it holds, `summary.left_out` counting the joint's settings \
                 it leaves out",
        confirm: "-",
    };
    type Row = DeviceResult<u8, SettingDiff>;
    type Summary = DiffSummary;

    fn bus(&self) -> Option<&str> {
        self.bus.as_deref()
    }

    fn effect(&self) -> Effect {
        Effect::Read
    }

    fn check(&self) -> R<Confirm> {
        self.parsed().map(|_| Confirm::NONE)
    }

    /// The reads of the joint's settings (and the other joint's).
    fn plan(&self, _baud: BaudRate) -> R<Plan> {
        let (j, with) = self.parsed()?;
        let mut p = settings_reads(j);
        if let DiffWith::Joint(o) = &with {
            for (_, step) in settings_reads(*o).steps {
                p.push(step);
            }
        }
        p.notes.push(
            "reads the settings and lists those whose raw values differ (against a file, \
             only the settings it holds; those it leaves out are counted)"
                .into(),
        );
        Ok(plan_of(Self::OP, p, true, Confirm::NONE))
    }

    fn run(&self, cx: &mut RunCx<'_, '_>) -> Result<Report<Self::Row, DiffSummary>, OpError> {
        let (j, with) = self.parsed()?;
        let port = cx.station.whj(self.bus())?;
        let bus = port.bus();
        let a = ops::backup(bus, j)?;
        // Against a file, only the registers it holds: what it leaves out is counted.
        let (d, with, left_out) = match with {
            DiffWith::File(s) => {
                let (d, left_out) = ops::diff_file(&a, &s);
                (d, format!("the file (joint {})", s.joint), Some(left_out))
            }
            DiffWith::Joint(o) => {
                let d = ops::diff(&a, &ops::backup(bus, o)?);
                (d, format!("joint {}", o.get()), None)
            }
        };
        let summary = DiffSummary {
            differ: d.len(),
            with,
            left_out,
        };
        let rows = d
            .into_iter()
            .map(|x| DeviceResult::ok(j.get(), x))
            .collect();
        Ok(Report::with_rows(Self::OP, port.name(), rows).summary(summary))
    }
}
