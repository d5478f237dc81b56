//! `wck.scan`: find servos: a status read of every ID (at the bus's rate, or at every
//! rate the wCK supports), an ID that several modules answer confirmed by repeated
//! probes.

use robobus_wck::BaudRate;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::{R, plan_of};
use crate::catalogue::args::Ids;
use crate::catalogue::bounds::ConfirmClass;
use crate::catalogue::operation::{Confirm, OpDoc, Operation, Report, RunCx};
use crate::catalogue::{Effect, Family, Plan};
use crate::error::ErrorKind;
use crate::ops::wck::{self as wops, Found, ScanArgs, ScanOpReport, SharedId};

fn default_scan_ids() -> Ids {
    Ids::Text("0-30".into())
}

request!(cli
    /// `wck.scan`: find servos (status read of every ID).
    Scan {
        /// IDs to try: IDs and ranges, e.g. `0-5,7` (in JSON also an array, `[0, 1]`).
        #[serde(default = "default_scan_ids")]
        #[cfg_attr(feature = "cli", arg(long, default_value = "0-30", value_parser = crate::catalogue::wck::cli::servo_ids))]
        ids: Ids,
        /// Try every baud rate the wCK supports, not only the bus's.
        #[serde(default)]
        #[cfg_attr(feature = "cli", arg(long))]
        all_bauds: bool,
    }
);

/// The whole scan.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, JsonSchema)]
pub struct ScanSummary {
    /// The rates tried, bit/s.
    pub bauds_tried: Vec<u32>,
    /// IDs answered by more than one module.
    pub duplicates: Vec<SharedId>,
}

impl Scan {
    /// What to scan, starting at the bus's rate `baud`.
    fn args(&self, baud: BaudRate) -> R<ScanArgs> {
        Ok(ScanArgs::new(
            self.ids.parse("--ids")?,
            baud,
            self.all_bauds,
        ))
    }
}

impl Operation for Scan {
    const OP: &'static str = "wck.scan";
    const FAMILY: Family = Family::Wck;
    const DOC: OpDoc = OpDoc {
        args: r#"`ids`="0-30", `all_bauds`"#,
        report: "one row per servo found: `baud`, `load`, `position`, `degrees`; `summary`: \
                 `bauds_tried`, `duplicates` (`id`, `baud`, `evidence`: an ID several modules \
                 answer, a device failure); nothing found is `no-device`, a stop keeps what \
                 was found",
        confirm: "-",
    };
    type Row = Found;
    type Summary = ScanSummary;

    fn bus(&self) -> Option<&str> {
        self.bus.as_deref()
    }

    fn effect(&self) -> Effect {
        Effect::Read
    }

    fn check(&self) -> R<Confirm> {
        self.args(BaudRate::B115200).map(|_| Confirm::NONE)
    }

    /// Every probe, as if no servo answered (a servo that answers gets its reads).
    fn plan(&self, baud: BaudRate) -> R<Plan> {
        let scan = self.args(baud)?;
        Ok(plan_of(
            Self::OP,
            &scan.plan(&|_, _| false),
            baud,
            ConfirmClass::None,
        ))
    }

    fn run(&self, cx: &mut RunCx<'_, '_>) -> R<Report<Found, ScanSummary>> {
        let port = cx.station.wck(self.bus())?;
        let name = port.name().to_owned();
        let mut guard = port.lock();
        let bus = &mut *guard;
        let args = self.args(bus.baud())?;
        let r = wops::scan(bus, &args, cx.control)?;
        let (kind, error) = match failure(&name, &args, &r) {
            Some((kind, error)) => (Some(kind), Some(error)),
            None => (None, None),
        };
        let mut out = Report::with_rows(Self::OP, &name, r.found).summary(ScanSummary {
            bauds_tried: r.bauds_tried,
            duplicates: r.duplicates,
        });
        (out.failed, out.error) = (kind, error);
        Ok(out)
    }
}

/// How the scan failed: stopped (what it found stays in the report), an ID more than one
/// module answers (a device fault), or nothing answered.
fn failure(name: &str, args: &ScanArgs, r: &ScanOpReport) -> Option<(ErrorKind, String)> {
    if let Some(why) = &r.stopped {
        Some((ErrorKind::Interrupted, format!("{name}: {why}")))
    } else if !r.duplicates.is_empty() {
        let ids: Vec<String> = r
            .duplicates
            .iter()
            .map(|d| format!("ID {} at {} bit/s", d.id, d.baud))
            .collect();
        Some((
            ErrorKind::Device,
            format!(
                "{name}: more than one module answers at {}; give each module its own ID",
                ids.join(", ")
            ),
        ))
    } else if r.is_empty() {
        let rates: Vec<String> = args.bauds.iter().map(ToString::to_string).collect();
        Some((
            ErrorKind::NoDevice,
            format!(
                "{name}: no servo answered at any of the scanned IDs ({}) at {}; check \
                 power, wiring and the baud rate (--all-bauds tries every rate)",
                crate::ops::ids_text(&args.ids),
                rates.join(", ")
            ),
        ))
    } else {
        None
    }
}
