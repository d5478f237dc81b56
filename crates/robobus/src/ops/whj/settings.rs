//! A joint's settings: backup to a file, diff, and restore.
//!
//! The settings are the registers the joint keeps in flash (the register table's
//! persistence class `flash`: IDs and bit rates, limits, loop gains, modes at power-up),
//! read by name: a 32-bit pair as one value, each with its raw value and, where the
//! register has a fixed scale, its value in its unit. A [`Settings`] document carries the
//! joint's model and firmware and serializes to the documented JSON file
//! ([`SETTINGS_FORMAT`], version [`SETTINGS_VERSION`]).
//!
//! [`restore`] writes a document back onto a joint, only where the joint differs:
//!
//! - the model and firmware must be the document's (registers and their meaning differ
//!   between them);
//! - the joint must be disabled (gains and limits are not changed under a running drive);
//! - the bus identity (`SYS_ID`, the two CAN FD bit rates) is never restored (a copy of
//!   one joint's file onto another would give two joints one ID): it is reported as
//!   skipped; `whj set-id` changes an ID with its checks;
//! - a register whose safety class asks for confirmation (enable at power-up, the
//!   calibration state) needs `confirmed`; without it nothing at all is written;
//! - position limits are written in the order that never leaves them inverted;
//! - then the RAM table is saved to flash and the settings are read back: a register that
//!   does not read back as the document says fails the restore, naming it.
//!
//! [`diff`] compares two documents (two joints' backups): the registers whose raw values
//! differ; [`diff_file`] compares a joint's backup with a file, where only the registers the
//! file holds can differ.

use serde::{Deserialize, Serialize};

use robobus_whj::registers::{Half, Persistence, REGISTERS, SafetyClass, safety_class};
use robobus_whj::{JointId, RegisterInfo};

use crate::ops::OpError;
use crate::whj::{Joint, JointBus};

use super::whj;

/// The `format` of a settings file.
pub const SETTINGS_FORMAT: &str = "robobus-whj-settings";
/// The version of the settings file format this library writes and reads.
pub const SETTINGS_VERSION: u32 = 1;
/// The largest settings file read, bytes.
pub const SETTINGS_FILE_LIMIT: u64 = 256 << 10;

/// The registers a restore never writes: the joint's identity on the bus.
const BUS_IDENTITY: [&str; 3] = ["SYS_ID", "SYS_BPS_CANFD_BRT", "SYS_BPS_CANFD_DATA"];

/// One setting: a register and its value.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct Setting {
    /// The register's name (a pair by its name without `_L`).
    pub register: String,
    /// Its address, `0x14` (a pair: the low word's).
    pub addr: String,
    /// The raw value (a pair combined into an i32).
    pub raw: i64,
    /// The value in its unit, where the register has a fixed scale (for reading; a
    /// restore writes `raw`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub value: Option<f64>,
    /// The unit symbol of `value`.
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub unit: String,
}

/// A joint's settings, as a settings file holds them.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct Settings {
    /// Always [`SETTINGS_FORMAT`].
    pub format: String,
    /// The file format's version ([`SETTINGS_VERSION`]).
    pub version: u32,
    /// The joint they were read from.
    pub joint: u8,
    /// Its model, as `whj info` names it.
    pub model: String,
    /// Its firmware version, four hex digits.
    pub firmware: String,
    /// The settings, in address order.
    pub settings: Vec<Setting>,
}

impl Settings {
    /// Parses a settings file's text.
    ///
    /// # Errors
    ///
    /// [`OpError::Invalid`] naming what is wrong (not JSON, another format or version, an
    /// unknown register or one that is not a setting, a value out of its register's
    /// range).
    pub fn parse(text: &str) -> Result<Self, OpError> {
        let s: Self = serde_json::from_str(text).map_err(|e| {
            OpError::invalid("settings", "the file", format!("not a settings file: {e}"))
        })?;
        if s.format != SETTINGS_FORMAT || s.version != SETTINGS_VERSION {
            return Err(OpError::invalid(
                "settings",
                format!("format {} version {}", s.format, s.version),
                format!("expected format {SETTINGS_FORMAT} version {SETTINGS_VERSION}"),
            ));
        }
        for v in &s.settings {
            let info = setting_info(&v.register).ok_or_else(|| {
                OpError::invalid(
                    "settings",
                    &v.register,
                    "not a setting of a WHJ joint (a register kept in flash)",
                )
            })?;
            if let Some((lo, hi)) = info.range
                && !(i64::from(lo)..=i64::from(hi)).contains(&v.raw)
            {
                return Err(OpError::invalid(
                    "settings",
                    format!("{} = {}", v.register, v.raw),
                    format!("out of the register's range {lo}..={hi}"),
                ));
            }
            if i32::try_from(v.raw).is_err() {
                return Err(OpError::invalid(
                    "settings",
                    format!("{} = {}", v.register, v.raw),
                    "does not fit a register",
                ));
            }
        }
        Ok(s)
    }

    /// The setting of `register`, if the document has it.
    #[must_use]
    pub fn get(&self, register: &str) -> Option<&Setting> {
        self.settings.iter().find(|s| s.register == register)
    }
}

/// The table entry of the setting named `name` (a pair by its name without `_L`).
fn setting_info(name: &str) -> Option<&'static RegisterInfo> {
    settings_table().find(|i| display_name(i) == name)
}

/// The registers that are settings: kept in flash, one entry per value (a pair's low
/// word), in address order.
pub fn settings_registers() -> impl Iterator<Item = &'static RegisterInfo> {
    settings_table()
}

fn settings_table() -> impl Iterator<Item = &'static RegisterInfo> {
    REGISTERS
        .iter()
        .filter(|i| i.persistence == Persistence::Flash && i.half != Half::High)
}

fn display_name(info: &RegisterInfo) -> &'static str {
    if info.half == Half::Low {
        info.name.strip_suffix("_L").unwrap_or(info.name)
    } else {
        info.name
    }
}

/// Reads every setting the joint's model and firmware have (`whj backup`).
///
/// # Errors
///
/// The joint's error when it does not answer a read (the backup is all or nothing).
pub fn backup(bus: &JointBus, id: JointId) -> Result<Settings, OpError> {
    let j = bus.joint(id).map_err(whj)?;
    let identity = j.identity().map_err(whj)?;
    let mut settings = Vec::new();
    for info in settings_table() {
        if robobus_whj::registers::gated_write_allowed(info.addr, identity.model, identity.firmware)
            .is_err()
        {
            continue;
        }
        let v = j.read_register(info.name).map_err(whj)?;
        settings.push(Setting {
            register: display_name(info).to_owned(),
            addr: format!("0x{:02X}", info.addr.get()),
            raw: i64::from(v.raw),
            value: v.value,
            unit: v.unit.to_owned(),
        });
    }
    Ok(Settings {
        format: SETTINGS_FORMAT.into(),
        version: SETTINGS_VERSION,
        joint: id.get(),
        model: identity.model.to_string(),
        firmware: identity.firmware.to_string(),
        settings,
    })
}

/// The settings whose factory value the vendor documents, for a joint of `model` with
/// `firmware` (those its firmware has), as a settings document of joint `joint`: modes at
/// power-up, the speed and acceleration limits, the following-error limit, the feature
/// switches. The bus identity is left out (a restore never writes it), and so is what
/// the vendor tunes per joint and does not publish (the loop gains, the current and
/// position limits): a restore of this document leaves those as they are.
#[must_use]
pub fn documented_defaults(
    joint: u8,
    model: robobus_whj::units::Model,
    firmware: robobus_whj::units::FirmwareVersion,
) -> Settings {
    let settings = settings_table()
        .filter(|i| {
            i.access == robobus_whj::registers::Access::ReadWrite
                && !BUS_IDENTITY.contains(&i.name)
                && robobus_whj::registers::gated_write_allowed(i.addr, model, firmware).is_ok()
        })
        .filter_map(|i| {
            Some(Setting {
                register: display_name(i).to_owned(),
                addr: format!("0x{:02X}", i.addr.get()),
                raw: i64::from(i.init?),
                value: None,
                unit: String::new(),
            })
        })
        .collect();
    Settings {
        format: SETTINGS_FORMAT.into(),
        version: SETTINGS_VERSION,
        joint,
        model: model.to_string(),
        firmware: firmware.to_string(),
        settings,
    }
}

/// [`documented_defaults`] for joint `id` as it identifies itself (`whj defaults`).
///
/// # Errors
///
/// The joint's error when it does not answer its identity reads.
pub fn defaults(bus: &JointBus, id: JointId) -> Result<Settings, OpError> {
    let identity = bus.joint(id).and_then(|j| j.identity()).map_err(whj)?;
    Ok(documented_defaults(
        id.get(),
        identity.model,
        identity.firmware,
    ))
}

/// One register on which two documents differ.
#[derive(Debug, Clone, PartialEq, Serialize, schemars::JsonSchema)]
pub struct SettingDiff {
    /// The register.
    pub register: String,
    /// Its address.
    pub addr: String,
    /// Raw value in the first document (`None`: it does not have the register).
    pub a: Option<i64>,
    /// Raw value in the second.
    pub b: Option<i64>,
    /// The value in its unit in the first, where it has a scale.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub a_value: Option<f64>,
    /// The value in its unit in the second.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub b_value: Option<f64>,
    /// The unit of the values (left out when they have none).
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub unit: String,
}

/// The registers whose raw values differ between `a` and `b`, in address order (a
/// register only one of them has counts as differing).
#[must_use]
pub fn diff(a: &Settings, b: &Settings) -> Vec<SettingDiff> {
    settings_table()
        .filter_map(|info| {
            let name = display_name(info);
            let (x, y) = (a.get(name), b.get(name));
            if x.map(|s| s.raw) == y.map(|s| s.raw) {
                return None;
            }
            let any = x.or(y)?;
            Some(SettingDiff {
                register: name.to_owned(),
                addr: any.addr.clone(),
                a: x.map(|s| s.raw),
                b: y.map(|s| s.raw),
                a_value: x.and_then(|s| s.value),
                b_value: y.and_then(|s| s.value),
                unit: any.unit.clone(),
            })
        })
        .collect()
}

/// The registers on which a joint's settings (`joint`, its backup) differ from a settings
/// file (`file`), in address order, and how many of the joint's registers the file leaves
/// out. A register the file does not hold is no difference: a file may hold only some
/// registers on purpose (a `whj.defaults` file leaves out the gains, the limits and the
/// bus identity), and a restore of it leaves them as they are.
#[must_use]
pub fn diff_file(joint: &Settings, file: &Settings) -> (Vec<SettingDiff>, usize) {
    let differ = diff(joint, file)
        .into_iter()
        .filter(|d| d.b.is_some())
        .collect();
    let left_out = joint
        .settings
        .iter()
        .filter(|s| file.get(&s.register).is_none())
        .count();
    (differ, left_out)
}

/// What a restore did with one register.
#[derive(Debug, Clone, PartialEq, Serialize, schemars::JsonSchema)]
pub struct RestoreStep {
    /// The register.
    pub register: String,
    /// Its raw value before.
    pub from: i64,
    /// The document's raw value.
    pub to: i64,
    /// `written`, or why it was not: `bus identity (use whj set-id)`.
    pub action: String,
}

/// What a restore did.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RestoreReport {
    /// The registers that differed, and what was done with each.
    pub steps: Vec<RestoreStep>,
    /// Registers written.
    pub written: usize,
    /// Whether the RAM table was saved to flash (only when something was written).
    pub saved: bool,
    /// The registers that differ after the restore: none but the skipped ones.
    pub differ_after: Vec<String>,
}

/// The document's registers a restore writes only when confirmed, and what each write
/// does (for a front end's prompt); a restore asks only for those that differ.
#[must_use]
pub fn confirm_needed(settings: &Settings) -> Vec<(&'static str, &'static str)> {
    settings
        .settings
        .iter()
        .filter_map(|s| setting_info(&s.register))
        .filter(|i| !BUS_IDENTITY.contains(&display_name(i)))
        .filter_map(|i| match safety_class(i.addr) {
            SafetyClass::Confirm(what) => Some((display_name(i), what)),
            _ => None,
        })
        .collect()
}

/// Restores `settings` onto joint `id` (see the [module docs](self)).
///
/// # Errors
///
/// [`OpError::Refused`] before anything is sent: another model or firmware, a joint that
/// is enabled, a confirm-class register that differs without `confirmed`;
/// [`OpError::Device`] when a register does not read back as written; the joint's error
/// when it does not answer.
pub fn restore(
    bus: &JointBus,
    id: JointId,
    settings: &Settings,
    confirmed: bool,
) -> Result<RestoreReport, OpError> {
    let j = bus.joint(id).map_err(whj)?;
    let identity = j.identity().map_err(whj)?;
    let (model, firmware) = (identity.model.to_string(), identity.firmware.to_string());
    if model != settings.model || firmware != settings.firmware {
        return Err(OpError::Refused(format!(
            "joint {}: the settings are of a {} with firmware {}, the joint is a {model} with \
             firmware {firmware}; nothing was written",
            id.get(),
            settings.model,
            settings.firmware
        )));
    }
    if j.is_enabled().map_err(whj)? {
        return Err(OpError::Refused(format!(
            "joint {}: its drive is enabled; disable it (whj disable) before its settings \
             change; nothing was written",
            id.get()
        )));
    }
    let now = backup(bus, id)?;
    let (steps, mut writes) = plan_restore(id, &now, settings, confirmed)?;
    order_limits(&j, &mut writes)?;
    write_settings(&j, &writes)?;
    let saved = !writes.is_empty();
    if saved {
        j.save_to_flash().map_err(whj)?;
    }
    let after = backup(bus, id)?;
    let differ_after: Vec<String> = diff(&after, settings)
        .into_iter()
        .map(|d| d.register)
        .collect();
    let unexpected: Vec<&String> = differ_after
        .iter()
        .filter(|r| writes.iter().any(|(i, _)| display_name(i) == r.as_str()))
        .collect();
    if !unexpected.is_empty() {
        return Err(OpError::Device(format!(
            "joint {}: {} did not read back as written",
            id.get(),
            unexpected
                .iter()
                .map(|s| s.as_str())
                .collect::<Vec<_>>()
                .join(", ")
        )));
    }
    Ok(RestoreReport {
        written: writes.len(),
        steps,
        saved,
        differ_after,
    })
}

/// A setting to write and its raw value.
type Write = (&'static RegisterInfo, i32);

/// What a restore does with each setting on which the joint (`now`) differs from the
/// document: the steps to report and the writes to make.
fn plan_restore(
    id: JointId,
    now: &Settings,
    settings: &Settings,
    confirmed: bool,
) -> Result<(Vec<RestoreStep>, Vec<Write>), OpError> {
    let mut steps = Vec::new();
    let mut writes: Vec<Write> = Vec::new();
    for d in diff(now, settings) {
        let (Some(from), Some(to)) = (d.a, d.b) else {
            continue;
        };
        let Some(info) = setting_info(&d.register) else {
            continue;
        };
        let action = if BUS_IDENTITY.contains(&d.register.as_str()) {
            "skipped: the bus identity (whj set-id changes an ID)".to_owned()
        } else {
            match safety_class(info.addr) {
                SafetyClass::Plain => "written".to_owned(),
                SafetyClass::Confirm(what) if confirmed => {
                    format!("written (confirmed: {what})")
                }
                SafetyClass::Confirm(what) => {
                    return Err(OpError::Refused(format!(
                        "joint {}: restoring {} {what}; confirm with --yes; nothing was \
                         written",
                        id.get(),
                        d.register
                    )));
                }
                SafetyClass::Motion(why) | SafetyClass::Never(why) => {
                    format!("skipped: {why}")
                }
            }
        };
        if action.starts_with("written") {
            writes.push((info, i32::try_from(to).unwrap_or_default()));
        }
        steps.push(RestoreStep {
            register: d.register,
            from,
            to,
            action,
        });
    }
    Ok((steps, writes))
}

/// Writes `writes` in order, each through the joint's write checks.
fn write_settings(j: &Joint<'_>, writes: &[Write]) -> Result<(), OpError> {
    for &(info, raw) in writes {
        use robobus_whj::request::WriteData;
        let data = if info.half == Half::Low {
            WriteData::Pair(raw)
        } else {
            WriteData::Word(word(raw).ok_or_else(|| {
                OpError::invalid(
                    "settings",
                    format!("{} = {raw}", display_name(info)),
                    "not a 16-bit value",
                )
            })?)
        };
        super::check_joint_write(j, info.addr, data)?;
        match data {
            WriteData::Pair(v) => j.write_i32(info.addr, v),
            WriteData::Word(w) => j.write_word(info.addr, w),
            WriteData::Byte(b) => j.write_word(info.addr, u16::from(b)),
        }
        .map_err(whj)?;
    }
    Ok(())
}

/// A register word from its raw value as read (signed or unsigned 16 bits).
fn word(raw: i32) -> Option<u16> {
    (-32768..=65535).contains(&raw).then(|| {
        // In range: the low 16 bits are the word either way.
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let w = raw as u16;
        w
    })
}

/// Orders the position-limit writes so the limits are never inverted in between: the
/// new minimum first unless it lies above the present maximum.
fn order_limits(j: &Joint<'_>, writes: &mut [(&'static RegisterInfo, i32)]) -> Result<(), OpError> {
    use robobus_whj::registers::addr::{LIT_MAX_POSITION, LIT_MIN_POSITION};
    let min = writes.iter().position(|(i, _)| i.addr == LIT_MIN_POSITION);
    let max = writes.iter().position(|(i, _)| i.addr == LIT_MAX_POSITION);
    if let (Some(a), Some(b)) = (min, max) {
        let (_, present_max) = j.position_limits().map_err(whj)?;
        let new_min = writes[a].1;
        // The maximum first when the new minimum would pass the present maximum.
        let max_first = new_min > present_max.raw();
        if max_first != (b < a) {
            writes.swap(a, b);
        }
    }
    Ok(())
}
