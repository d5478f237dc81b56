//! A wCK servo's settings: backup to a file, diff, restore, and the factory settings.
//!
//! The settings are what a servo keeps in its EEPROM and can report: the P and D gains,
//! the I gain, the speed level and acceleration range, the over-load threshold and the
//! movement boundaries. A [`WckSettings`] document serializes to the documented JSON
//! file ([`WCK_SETTINGS_FORMAT`], version [`WCK_SETTINGS_VERSION`]); wCK servos report no
//! model or firmware, so a file names only the servo it was read from. The servo's ID
//! and baud rate are its identity on the bus (`wck set-id`, `wck set-baud`), not
//! settings.
//!
//! [`restore`] writes a document back where the servo differs, one EEPROM write per
//! group that differs (gains, I gain, speed, over-load, boundaries; each verified by the
//! servo's read-back), then reads the settings again. [`WckSettings::factory`] is the
//! manual's default parameter settings, what a factory reset restores.

use robobus_link::ByteLink;
use robobus_wck::{
    Accel, Boundaries, DGain, IGain, Overload, PGain, Position, RangeError, ServoId, Speed,
};
use serde::{Deserialize, Serialize};

use crate::ops::OpError;
use crate::wck::{Gains, SpeedAccel, WckBus};

/// The `format` of a wCK settings file.
pub const WCK_SETTINGS_FORMAT: &str = "robobus-wck-settings";
/// The version of the wCK settings file format.
pub const WCK_SETTINGS_VERSION: u32 = 1;
/// The largest wCK settings file read, bytes.
pub const WCK_SETTINGS_FILE_LIMIT: u64 = 64 << 10;

/// A servo's settings, as a settings file holds them (raw values as the manual gives
/// them).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct WckSettings {
    /// Always [`WCK_SETTINGS_FORMAT`].
    #[serde(with = "format_tag")]
    #[schemars(schema_with = "format_tag::schema")]
    pub format: (),
    /// The file format's version ([`WCK_SETTINGS_VERSION`]).
    pub version: u32,
    /// The servo they were read from (`None`: the factory settings).
    pub servo: Option<u8>,
    /// P gain, 1..=254.
    pub p_gain: u8,
    /// D gain, 0..=254.
    pub d_gain: u8,
    /// I gain, 0..=10.
    pub i_gain: u8,
    /// Speed level, 0..=30 (0: no limit).
    pub speed: u8,
    /// Acceleration range, 20..=100.
    pub accel: u8,
    /// Over-load threshold code, 33..=199 (400..=1800 mA).
    pub overload: u8,
    /// Lower movement boundary, 0..=254.
    pub lower: u8,
    /// Upper movement boundary, 0..=254.
    pub upper: u8,
}

/// Writes and checks the constant `format` field.
mod format_tag {
    use serde::{Deserialize, Deserializer, Serializer};

    #[allow(clippy::trivially_copy_pass_by_ref)] // the signature serde's `with` calls
    pub(super) fn serialize<S: Serializer>(_: &(), s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(super::WCK_SETTINGS_FORMAT)
    }

    /// The schema of the field: the one text it holds.
    pub(super) fn schema(_: &mut schemars::SchemaGenerator) -> schemars::Schema {
        schemars::json_schema!({"type": "string", "const": super::WCK_SETTINGS_FORMAT})
    }

    pub(super) fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<(), D::Error> {
        let s = String::deserialize(d)?;
        if s == super::WCK_SETTINGS_FORMAT {
            Ok(())
        } else {
            Err(serde::de::Error::custom(format!(
                "format {s}: expected {}",
                super::WCK_SETTINGS_FORMAT
            )))
        }
    }
}

/// One group of settings on which two documents differ.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, schemars::JsonSchema)]
pub struct WckSettingDiff {
    /// The group: `gains`, `i_gain`, `speed`, `overload` or `bounds`.
    pub setting: &'static str,
    /// Its values in the first document (`p_gain=20 d_gain=30`).
    pub a: String,
    /// Its values in the second.
    pub b: String,
}

/// What a restore did with one group that differed.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, schemars::JsonSchema)]
pub struct WckRestoreStep {
    /// The group.
    pub setting: &'static str,
    /// Its values before.
    pub from: String,
    /// The document's values, now written.
    pub to: String,
}

/// What a restore did.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct WckRestoreReport {
    /// The groups written (only those that differed).
    pub steps: Vec<WckRestoreStep>,
    /// EEPROM writes made.
    pub written: usize,
}

/// The typed values of a document, checked.
struct Typed {
    gains: Gains,
    i: IGain,
    speed: SpeedAccel,
    overload: Overload,
    bounds: Boundaries,
}

impl WckSettings {
    /// The manual's default parameter settings: what a factory reset restores.
    #[must_use]
    pub const fn factory() -> Self {
        Self {
            format: (),
            version: WCK_SETTINGS_VERSION,
            servo: None,
            p_gain: PGain::DEFAULT.get(),
            d_gain: DGain::DEFAULT.get(),
            i_gain: IGain::DEFAULT.get(),
            speed: Speed::DEFAULT.get(),
            accel: Accel::DEFAULT.get(),
            overload: Overload::DEFAULT.get(),
            lower: Boundaries::DEFAULT.lower().get(),
            upper: Boundaries::DEFAULT.upper().get(),
        }
    }

    /// Parses a settings file's text, every value checked against its range.
    ///
    /// # Errors
    ///
    /// [`OpError::Invalid`] naming what is wrong.
    pub fn parse(text: &str) -> Result<Self, OpError> {
        let s: Self = serde_json::from_str(text).map_err(|e| {
            OpError::invalid(
                "settings",
                "the file",
                format!("not a wCK settings file: {e}"),
            )
        })?;
        if s.version != WCK_SETTINGS_VERSION {
            return Err(OpError::invalid(
                "settings",
                format!("version {}", s.version),
                format!("expected version {WCK_SETTINGS_VERSION}"),
            ));
        }
        s.typed()?;
        Ok(s)
    }

    fn typed(&self) -> Result<Typed, OpError> {
        let bad = |e: RangeError| OpError::invalid("settings", e.value, e.to_string());
        let bounds = Boundaries::new(
            Position::new(self.lower).map_err(bad)?,
            Position::new(self.upper).map_err(bad)?,
        )
        .map_err(|e| {
            OpError::invalid(
                "settings",
                format!("{}..{}", self.lower, self.upper),
                e.to_string(),
            )
        })?;
        Ok(Typed {
            gains: Gains {
                p: PGain::new(self.p_gain).map_err(bad)?,
                d: DGain::new(self.d_gain).map_err(bad)?,
            },
            i: IGain::new(self.i_gain).map_err(bad)?,
            speed: SpeedAccel {
                speed: Speed::new(self.speed).map_err(bad)?,
                accel: Accel::new(self.accel).map_err(bad)?,
            },
            overload: Overload::new(self.overload).map_err(bad)?,
            bounds,
        })
    }

    /// Each group's name and its values as text.
    fn groups(&self) -> [(&'static str, String); 5] {
        [
            (
                "gains",
                format!("p_gain={} d_gain={}", self.p_gain, self.d_gain),
            ),
            ("i_gain", format!("i_gain={}", self.i_gain)),
            (
                "speed",
                format!("speed={} accel={}", self.speed, self.accel),
            ),
            (
                "overload",
                format!(
                    "overload={} ({} mA)",
                    self.overload,
                    Overload::new(self.overload).map_or(0, Overload::milliamps)
                ),
            ),
            (
                "bounds",
                format!("lower={} upper={}", self.lower, self.upper),
            ),
        ]
    }
}

/// Reads a servo's settings (`wck backup`).
///
/// # Errors
///
/// The servo's error when it does not answer a read (all or nothing).
pub fn backup<L: ByteLink>(bus: &mut WckBus<L>, id: ServoId) -> Result<WckSettings, OpError> {
    let mut s = bus.servo(id);
    let gains = s.gains()?;
    let i = s.i_gain()?;
    let speed = s.speed()?;
    let overload = s.overload()?;
    let bounds = s.boundaries()?;
    Ok(WckSettings {
        format: (),
        version: WCK_SETTINGS_VERSION,
        servo: Some(id.get()),
        p_gain: gains.p.get(),
        d_gain: gains.d.get(),
        i_gain: i.get(),
        speed: speed.speed.get(),
        accel: speed.accel.get(),
        overload: overload.get(),
        lower: bounds.lower().get(),
        upper: bounds.upper().get(),
    })
}

/// The groups of settings on which `a` and `b` differ.
#[must_use]
pub fn diff(a: &WckSettings, b: &WckSettings) -> Vec<WckSettingDiff> {
    a.groups()
        .into_iter()
        .zip(b.groups())
        .filter(|((_, x), (_, y))| x != y)
        .map(|((setting, a), (_, b))| WckSettingDiff { setting, a, b })
        .collect()
}

/// Writes `settings` onto servo `id` where it differs (see the [module docs](self)).
///
/// # Errors
///
/// [`OpError::Invalid`] for a document out of range (nothing sent); the servo's error
/// when a write or its read-back fails (the groups before it are written);
/// [`OpError::Device`] when the settings read afterwards still differ.
pub fn restore<L: ByteLink>(
    bus: &mut WckBus<L>,
    id: ServoId,
    settings: &WckSettings,
) -> Result<WckRestoreReport, OpError> {
    let want = settings.typed()?;
    let now = backup(bus, id)?;
    let differ = diff(&now, settings);
    let mut steps = Vec::new();
    for d in differ {
        let mut s = bus.servo(id);
        match d.setting {
            "gains" => s.set_gains(want.gains)?,
            "i_gain" => s.set_i_gain(want.i)?,
            "speed" => s.set_speed(want.speed)?,
            "overload" => s.set_overload(want.overload)?,
            _ => s.set_boundaries(want.bounds)?,
        }
        steps.push(WckRestoreStep {
            setting: d.setting,
            from: d.a,
            to: d.b,
        });
    }
    let after = backup(bus, id)?;
    let left = diff(&after, settings);
    if !left.is_empty() {
        return Err(OpError::Device(format!(
            "servo {}: {} did not read back as written",
            id.get(),
            left.iter()
                .map(|d| d.setting)
                .collect::<Vec<_>>()
                .join(", ")
        )));
    }
    Ok(WckRestoreReport {
        written: steps.len(),
        steps,
    })
}
