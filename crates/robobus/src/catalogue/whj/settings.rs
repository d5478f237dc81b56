//! The settings requests of the WHJ catalogue (`whj.backup`, `whj.defaults`, `whj.diff`,
//! `whj.restore`) and their plans; [`ops::settings`] runs them.

use robobus_whj::{JointId, Request as Wire};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::{Job, Prepared, R, joint, prepared};
use crate::catalogue::bounds::{ConfirmClass, NON_VOLATILE_TEXT};
use crate::catalogue::plan::WhjSteps;
use crate::catalogue::wck::request;
use crate::ops::OpError;
use crate::ops::whj as ops;

request!(
    /// `whj.backup`: every setting of a joint (the registers it keeps in flash), as the
    /// settings file (the report's `summary`).
    Backup { /// Joint ID, 1..=30.
        joint: u32 }
);
request!(
    /// `whj.defaults`: the settings whose factory value the vendor documents, for the
    /// joint's model and firmware, as a settings file (the report's `summary`) that
    /// `whj.restore` writes back (the joints have no factory reset of their own).
    Defaults { /// Joint ID, 1..=30.
        joint: u32 }
);
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
/// What `whj.diff` compares a joint with.
#[derive(Debug, Clone)]
pub(crate) enum DiffWith {
    /// A settings file.
    File(Box<ops::settings::Settings>),
    /// Another joint.
    Joint(JointId),
}

/// The plan of reading a joint's settings: one read per setting (a pair as two words).
fn settings_reads(j: JointId) -> WhjSteps {
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

/// `whj.backup`: the reads of every setting.
pub(super) fn backup(r: &Backup) -> R<Prepared> {
    let j = joint("<JOINT>", r.joint)?;
    let mut p = settings_reads(j);
    p.notes.push(
        "reads every setting (the registers kept in flash) the joint's model and \
         firmware have; the report's summary is the settings file"
            .into(),
    );
    Ok(prepared(p, Job::Backup(j)))
}

/// `whj.defaults`: the identity reads (model, firmware); nothing is written.
pub(super) fn defaults(r: &Defaults) -> R<Prepared> {
    let j = joint("<JOINT>", r.joint)?;
    let mut p = WhjSteps::default();
    for (addr, count) in [
        (robobus_whj::registers::addr::SYS_MODEL_TYPE, 1),
        (robobus_whj::registers::addr::SYS_FW_VERSION, 1),
    ] {
        if let Ok(req) = Wire::read(j, addr, count) {
            p.push(req);
        }
    }
    p.notes.push(
        "reads the joint's model and firmware (as it connects); the report's summary is the \
         settings file of the values the vendor documents for them (modes at power-up, speed \
         and acceleration limits, following error, feature switches; not the gains, current \
         and position limits the vendor tunes per joint, nor the ID and bit rates); \
         `whj.restore` writes it back"
            .into(),
    );
    Ok(prepared(p, Job::Defaults(j)))
}

/// `whj.diff`: the reads of the joint's settings (and the other joint's).
pub(super) fn diff(r: &Diff) -> R<Prepared> {
    let j = joint("<JOINT>", r.joint)?;
    let with = match (&r.settings, r.other) {
        (Some(text), None) => DiffWith::File(Box::new(ops::settings::Settings::parse(text)?)),
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
    Ok(prepared(p, Job::Diff(j, with)))
}

/// `whj.restore`: the reads, then what the run writes (noted), with the flash confirmation.
pub(super) fn restore(r: &Restore) -> R<Prepared> {
    let j = joint("<JOINT>", r.joint)?;
    let s = ops::settings::Settings::parse(&r.settings)?;
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
    let needs = ops::settings::confirm_needed(&s);
    let mut pr = prepared(p, Job::Restore(j, Box::new(s)));
    pr.confirm = ConfirmClass::NonVolatile;
    pr.confirm_text = if needs.is_empty() {
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
    pr.confirmed = r.confirm;
    Ok(pr)
}
