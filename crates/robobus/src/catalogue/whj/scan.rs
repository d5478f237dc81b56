//! `whj.scan`: every ID of a list probed, each joint that answers identified and checked
//! for a second joint at its ID.

use robobus_wck::BaudRate;
use robobus_whj::{JointId, Request as Wire};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::{JointRow, R, each, plan_of};
use crate::catalogue::args::Ids;
use crate::catalogue::operation::{Confirm, OpDoc, Operation, Report, RunCx};
use crate::catalogue::wck::request;
use crate::catalogue::{Effect, Family, Plan};
use crate::ops::whj::{self as ops, Duplicate, IdentityReport};
use crate::ops::{ErrorKind, OpError};

fn default_scan_joints() -> Ids {
    Ids::Text("1-30".into())
}

request!(cli
    /// `whj.scan`: find joints (identity of every ID).
    Scan {
        /// Joint IDs to try.
        #[serde(default = "default_scan_joints")]
        #[cfg_attr(feature = "cli", arg(long, default_value = "1-30", value_parser = crate::catalogue::whj::cli::joints))]
        joints: Ids,
    }
);

/// The summary of `whj.scan`.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, JsonSchema)]
pub struct ScanSummary {
    /// The IDs more than one joint answers (each with the two unique IDs heard).
    pub duplicates: Vec<Duplicate>,
    /// How many IDs were probed.
    pub probed: usize,
}

impl Scan {
    fn ids(&self) -> R<Vec<JointId>> {
        self.joints.parse_sorted::<JointId>("--joints")
    }
}

impl Operation for Scan {
    const OP: &'static str = "whj.scan";
    const FAMILY: Family = Family::Whj;
    const DOC: OpDoc = OpDoc {
        args: r#"`joints`="1-30""#,
        report: "one row per joint that answered: `model`, `firmware`, `node_id`, \
                 `reduction`, `unique_id` (or its failure); `summary`: `duplicates` (`id`, \
                 `unique_ids`), `probed`. No joint, a duplicate ID or a stop fails the run \
                 (what was found stays)",
        confirm: "-",
    };
    type Row = JointRow<IdentityReport>;
    type Summary = ScanSummary;

    fn bus(&self) -> Option<&str> {
        self.bus.as_deref()
    }

    fn effect(&self) -> Effect {
        Effect::Read
    }

    fn check(&self) -> Result<Confirm, OpError> {
        self.ids().map(|_| Confirm::NONE)
    }

    /// The scan is the connect: no connect note heads its plan.
    fn plan(&self, _baud: BaudRate) -> Result<Plan, OpError> {
        let mut steps = each(&self.ids()?, Wire::read_identity);
        steps.notes.push(
            "reads signature, ID, model and firmware of each ID; a joint that answers is \
             present"
                .into(),
        );
        Ok(plan_of(Self::OP, steps, false, Confirm::NONE))
    }

    fn run(&self, cx: &mut RunCx<'_, '_>) -> Result<Report<Self::Row, ScanSummary>, OpError> {
        let ids = self.ids()?;
        let port = cx.station.whj(self.bus())?;
        let name = port.name();
        let r = ops::scan(port.bus(), &ids, cx.control)?;
        let mut out = Report::devices_with(Self::OP, name, r.found).summary(ScanSummary {
            duplicates: r.duplicates,
            probed: r.probed,
        });
        let duplicates = out.summary.as_ref().map_or(&[][..], |s| &s.duplicates[..]);
        let failure = if let Some(why) = &r.stopped {
            // What it found before the stop stays in the report.
            Some((ErrorKind::Interrupted, format!("{name}: {why}")))
        } else if out.results.is_empty() {
            let tried: Vec<String> = ids.iter().map(|j| j.get().to_string()).collect();
            Some((
                ErrorKind::NoDevice,
                format!("no joint answered on IDs {}", tried.join(",")),
            ))
        } else if !duplicates.is_empty() && out.failed.is_none() {
            let each: Vec<String> = duplicates
                .iter()
                .map(|d| {
                    format!(
                        "ID {} is answered by two joints (unique IDs {} and {})",
                        d.id, d.unique_ids[0], d.unique_ids[1]
                    )
                })
                .collect();
            Some((ErrorKind::Device, each.join("; ")))
        } else {
            None
        };
        if let Some((kind, error)) = failure {
            out.failed = Some(kind);
            out.error = Some(error);
        }
        Ok(out)
    }
}
