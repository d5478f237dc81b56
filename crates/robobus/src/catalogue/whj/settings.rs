//! What the settings operations of the WHJ catalogue share (`whj.backup`,
//! `whj.defaults`, `whj.diff`, `whj.restore`): the reads of a joint's settings, and the
//! report of a settings file read from a joint; [`ops::settings`] runs them.

use robobus_whj::{JointId, Request as Wire};
use schemars::JsonSchema;
use serde::Serialize;

use crate::catalogue::operation::{Report, RunCx};
use crate::catalogue::plan::WhjSteps;
use crate::ops::whj as ops;
use crate::ops::whj::settings::Settings;
use crate::ops::{DeviceResult, OpError};

/// What `whj.diff` compares a joint with.
#[derive(Debug, Clone)]
pub(crate) enum DiffWith {
    /// A settings file.
    File(Box<Settings>),
    /// Another joint.
    Joint(JointId),
}

/// The plan of reading a joint's settings: one read per setting (a pair as two words).
pub(super) fn settings_reads(j: JointId) -> WhjSteps {
    let mut p = WhjSteps::default();
    for info in ops::settings::settings_registers() {
        let count = if info.half == robobus_whj::registers::Half::Low {
            2
        } else {
            1
        };
        if let Ok(req) = Wire::read(j, info.addr, count) {
            p.push(req);
        }
    }
    p
}

/// The row of a settings file read from a joint (`whj.backup`, `whj.defaults`).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, JsonSchema)]
pub struct SettingsRow {
    /// The joint's model.
    pub model: String,
    /// Its firmware version, four hex digits.
    pub firmware: String,
    /// How many settings the file holds.
    pub settings: usize,
}

/// The report of `op` reading joint `j`'s settings file (`read`: `whj.backup`'s
/// [`ops::settings::backup`], `whj.defaults`' [`ops::settings::defaults`]) on the
/// station's WHJ bus `bus`.
pub(super) fn settings_run(
    cx: &RunCx<'_, '_>,
    op: &str,
    bus: Option<&str>,
    j: JointId,
    read: impl FnOnce(&crate::whj::JointBus, JointId) -> Result<Settings, OpError>,
) -> Result<Report<DeviceResult<u8, SettingsRow>, Settings>, OpError> {
    let port = cx.station.whj(bus)?;
    let s = read(port.bus(), j)?;
    Ok(settings_report(op, port.name(), j, s))
}

/// The report of settings `s` read from joint `j`: one row, the file as the summary.
fn settings_report(
    op: &str,
    bus: &str,
    j: JointId,
    s: Settings,
) -> Report<DeviceResult<u8, SettingsRow>, Settings> {
    let row = SettingsRow {
        model: s.model.clone(),
        firmware: s.firmware.clone(),
        settings: s.settings.len(),
    };
    Report::with_rows(op, bus, vec![DeviceResult::ok(j.get(), row)]).summary(s)
}
