//! One row per device for every sample a front end shows or records, whatever the family
//! and whichever sampler took it, and the recording formats (CSV and JSON lines).
//!
//! A [`SampleTable`] holds one [`SampleRow`] per watched device, in the caller's order.
//! Each sample fills it whole: from a telemetry [`Delivery`] ([`SampleTable::take`]: the
//! rows of a `whj.sample`, `wck.sample` or `robot.sample` report, matched by the device's
//! `id`, a robot file's joints by name) or from a cyclic loop's [`CycleReport`]
//! ([`SampleTable::take_cycle`]). A device that did not answer in a sample is *stale*: its
//! row keeps the values it had for a front end that wants to show them dimmed, but every
//! output of this module ([`SampleRow::now`], [`SampleTable::csv_row`],
//! [`SampleTable::json_line`]) gives `null` or an empty cell, never an older value as
//! this sample's. [`SampleTable::silent`] names the devices an exit code must report.
//!
//! [`Recorder`] writes a table's samples to a file in a [`RecordFormat`]: CSV (a comment
//! line naming the source, a header of `t_s` and three columns per device with their
//! units, then a row per sample), JSON lines (one [`SampleTable::json_line`] object per
//! sample) or MCAP (those objects and `sensor_msgs/msg/JointState` on one time base; see
//! [`SAMPLES_TOPIC`] and [`JOINT_STATES_TOPIC`]).

use std::fmt::Write as _;
use std::io::{Seek, Write};
use std::path::Path;

use robobus_whj::units::CurrentScale;

use crate::catalogue::Delivery;
use crate::ops::{ErrorKind, OpError};
use crate::station::sampler;
use crate::whj::CycleReport;

/// The unit of a table's speed column.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SpeedUnit {
    /// Revolutions per minute (WHJ joints by ID).
    Rpm,
    /// Degrees per second (wCK servos, a robot file's joints).
    DegPerS,
}

impl SpeedUnit {
    /// As shown: `RPM`, `deg/s`.
    #[must_use]
    pub const fn as_str(self) -> &'static str {
        match self {
            Self::Rpm => "RPM",
            Self::DegPerS => "deg/s",
        }
    }

    /// As a key or column suffix: `rpm`, `deg_per_s`.
    #[must_use]
    pub const fn key(self) -> &'static str {
        match self {
            Self::Rpm => "rpm",
            Self::DegPerS => "deg_per_s",
        }
    }
}

/// What a row's effort is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Effort {
    /// A WHJ joint's current, mA.
    Milliamps,
    /// A wCK servo's load, 0..=255.
    Load,
}

impl Effort {
    /// Its unit as shown and as a CSV column suffix: `mA`, `load`.
    #[must_use]
    pub const fn unit(self) -> &'static str {
        match self {
            Self::Milliamps => "mA",
            Self::Load => "load",
        }
    }

    /// Its JSON key: `current_ma`, `load`.
    #[must_use]
    pub const fn key(self) -> &'static str {
        match self {
            Self::Milliamps => "current_ma",
            Self::Load => "load",
        }
    }
}

/// One watched device: its latest values and how its samples went.
#[derive(Debug, Clone, PartialEq)]
pub struct SampleRow {
    /// Label: a robot file's joint name, or for a device by ID the name the built-in
    /// simulated robot gives it (`j3` for WHJ joint 3, `s12` for wCK servo 12), as the
    /// bridge, the studio and the recordings name joints.
    pub name: String,
    /// The device's `id` in a report's rows (a number, or a robot file's joint name).
    pub id: serde_json::Value,
    /// What its effort is (a wCK servo's load or a WHJ joint's current).
    pub effort_kind: Effort,
    /// Position, degrees.
    pub position_deg: Option<f64>,
    /// The position commanded in this sample, degrees (a played trajectory's target;
    /// written only by a table with [`SampleTable::commanded`]).
    pub target_deg: Option<f64>,
    /// Speed, in the table's [`SpeedUnit`].
    pub speed: Option<f64>,
    /// Current (mA) or load (0..=255), as [`effort_kind`](Self::effort_kind) says.
    pub effort: Option<f64>,
    /// Torque, N·m, estimated from the current (WHJ): a robot sample's `effort_nm`, or
    /// [`sampler::effort_nm`] of the current and the row's
    /// [`nm_per_a`](Self::nm_per_a); `None` for wCK and where no estimate exists.
    pub effort_nm: Option<f64>,
    /// The joint's torque constant, N·m per A (a WHJ joint by ID whose model is known:
    /// its rated torque over rated current), for the [`effort_nm`](Self::effort_nm) of
    /// samples that carry only a current.
    pub nm_per_a: Option<f64>,
    /// Drive enabled (WHJ).
    pub enabled: Option<bool>,
    /// Error text of the latest sample (`no error`, `ok`, the error bits, `timeout`).
    pub error: String,
    /// Samples it did not answer.
    pub failures: u64,
    /// Samples it answered.
    pub answered: u64,
    /// Whether it answered the latest sample (`false`: its values are older, stale).
    pub fresh: bool,
}

impl SampleRow {
    /// A row that has seen no sample yet.
    #[must_use]
    pub fn new(name: impl Into<String>, id: serde_json::Value, effort_kind: Effort) -> Self {
        Self {
            name: name.into(),
            id,
            effort_kind,
            position_deg: None,
            target_deg: None,
            speed: None,
            effort: None,
            effort_nm: None,
            nm_per_a: None,
            enabled: None,
            error: "-".into(),
            failures: 0,
            answered: 0,
            fresh: false,
        }
    }

    /// `value` if the latest sample answered, else `None` (never an older value as this
    /// sample's).
    #[must_use]
    pub fn now<T>(&self, value: Option<T>) -> Option<T> {
        value.filter(|_| self.fresh)
    }

    /// The device answered this sample (its values are set).
    pub fn got(&mut self) {
        self.fresh = true;
        self.answered += 1;
    }

    /// The device did not answer this sample: its values are stale from now on.
    pub fn missed(&mut self, why: &str) {
        self.fresh = false;
        self.failures += 1;
        why.clone_into(&mut self.error);
    }
}

/// The rows of every watched device and the sample they show (see the [module
/// docs](self)).
#[derive(Debug, Clone, PartialEq)]
pub struct SampleTable {
    /// The speed column's unit.
    pub speed_unit: SpeedUnit,
    /// One row per device, in the caller's order.
    pub rows: Vec<SampleRow>,
    /// Seconds since the start, of the latest sample.
    pub t_s: f64,
    /// Samples taken.
    pub samples: u64,
    /// Samples of the stream lost before they were taken here (the reader fell behind).
    pub lost: u64,
    /// The latest sample's read started more than one period after its slot.
    pub late: bool,
    /// The rows carry what was commanded ([`SampleRow::target_deg`]): the recordings
    /// have a target column / key / channel beside the positions read.
    pub commanded: bool,
}

impl SampleTable {
    /// A table of `rows` whose speeds are in `speed_unit`.
    #[must_use]
    pub const fn new(speed_unit: SpeedUnit, rows: Vec<SampleRow>) -> Self {
        Self {
            speed_unit,
            rows,
            t_s: 0.0,
            samples: 0,
            lost: 0,
            late: false,
            commanded: false,
        }
    }

    /// WHJ joints by ID (`j1`, ...: the built-in simulated robot's names; speed in RPM,
    /// effort the current).
    #[must_use]
    pub fn whj(ids: &[u8]) -> Self {
        Self::new(
            SpeedUnit::Rpm,
            ids.iter()
                .map(|&i| SampleRow::new(whj_name(i), i.into(), Effort::Milliamps))
                .collect(),
        )
    }

    /// wCK servos by ID (`s0`, ...: the built-in simulated robot's names; speed in
    /// degrees per second, effort the load).
    #[must_use]
    pub fn wck(ids: &[u8]) -> Self {
        Self::new(
            SpeedUnit::DegPerS,
            ids.iter()
                .map(|&i| SampleRow::new(wck_name(i), i.into(), Effort::Load))
                .collect(),
        )
    }

    /// The table with each row's torque constant ([`SampleRow::nm_per_a`], in the rows'
    /// order; a row without one keeps `None`): its samples then carry the torque
    /// estimated from the current, as the robot sample and the bridge estimate it.
    #[must_use]
    pub fn with_torque_constants(mut self, nm_per_a: &[Option<f64>]) -> Self {
        for (row, k) in self.rows.iter_mut().zip(nm_per_a) {
            row.nm_per_a = *k;
        }
        self
    }

    /// A robot file's joints by name, each with whether it is a wCK servo (speeds in
    /// degrees per second).
    #[must_use]
    pub fn robot<'a>(joints: impl IntoIterator<Item = (&'a str, bool)>) -> Self {
        Self::new(
            SpeedUnit::DegPerS,
            joints
                .into_iter()
                .map(|(name, wck)| {
                    let effort = if wck { Effort::Load } else { Effort::Milliamps };
                    SampleRow::new(name, name.into(), effort)
                })
                .collect(),
        )
    }

    /// Fills the rows from one delivery of a telemetry stream taken `t_s` seconds after
    /// the start; the link's error if the bus itself failed (a capture file that cannot be
    /// written, a bus that went away).
    ///
    /// # Errors
    ///
    /// The link's error text, when the read failed as a whole on the link or a row of the
    /// report is of kind `link`.
    pub fn take(&mut self, delivery: &Delivery, t_s: f64) -> Result<(), String> {
        let sample = &delivery.sample;
        self.begin(t_s);
        self.lost += delivery.lost;
        self.late = sample.late;
        let Some(report) = &sample.report else {
            let why = sample.error.clone().unwrap_or_default();
            if sample.failed.as_deref() == Some("link") {
                return Err(why);
            }
            // A read that could not be sent: a missed sample of every device.
            for row in &mut self.rows {
                row.missed("not sent");
            }
            return Ok(());
        };
        if let Some(e) = report.results.iter().find(|r| r["kind"] == "link") {
            return Err(e["error"].as_str().unwrap_or("link failed").to_owned());
        }
        let speed_key = match self.speed_unit {
            SpeedUnit::Rpm => "speed_rpm",
            SpeedUnit::DegPerS => "speed_deg_s",
        };
        for row in &mut self.rows {
            let Some(r) = report.results.iter().find(|r| r["id"] == row.id) else {
                row.missed("no reply");
                continue;
            };
            let wck = row.effort_kind == Effort::Load;
            match r["kind"].as_str() {
                // wCK replies carry no checksum or ID: a failed read is a missing reply.
                Some(_) if wck => row.missed("no reply"),
                Some("no-device") => row.missed("timeout"),
                Some(_) => row.missed("bad reply"),
                None => {
                    row.position_deg = r["position_deg"].as_f64();
                    row.speed = r[speed_key].as_f64();
                    row.effort = r["current_ma"].as_f64().or_else(|| r["load"].as_f64());
                    row.effort_nm = r["effort_nm"].as_f64().or_else(|| {
                        let ma = r["current_ma"].as_i64()?;
                        Some(sampler::effort_nm(ma, row.nm_per_a?, false))
                    });
                    row.enabled = r["enabled"].as_bool();
                    r["error"]
                        .as_str()
                        .unwrap_or("ok")
                        .clone_into(&mut row.error);
                    row.got();
                }
            }
        }
        Ok(())
    }

    /// Fills the rows (WHJ joints, in the loop's joint order) from a cyclic loop's cycle
    /// taken `t_s` seconds after the start; `None` (no cycle yet) counts the sample and
    /// changes no row.
    pub fn take_cycle(&mut self, report: Option<&CycleReport>, t_s: f64) {
        self.begin(t_s);
        let Some(report) = report else {
            return;
        };
        for (row, fb) in self.rows.iter_mut().zip(&report.feedback) {
            match fb {
                Some(fb) => {
                    row.position_deg = Some(fb.position.degrees());
                    row.speed = Some(match self.speed_unit {
                        SpeedUnit::Rpm => fb.speed.rpm(),
                        SpeedUnit::DegPerS => fb.speed.rpm() * 6.0,
                    });
                    let ma = fb.current.milliamps(CurrentScale::OneMilliamp);
                    #[allow(clippy::cast_precision_loss)] // |mA| < 2^53
                    let effort = ma as f64;
                    row.effort = Some(effort);
                    row.effort_nm = row.nm_per_a.map(|k| sampler::effort_nm(ma, k, false));
                    row.enabled = Some(fb.enabled);
                    row.error = fb.error.to_string();
                    row.got();
                }
                None => row.missed("no reply"),
            }
        }
    }

    /// The table of a played trajectory: `joints` of the robot file `config` by name,
    /// with what was commanded ([`SampleTable::commanded`]).
    #[must_use]
    pub fn played(config: &crate::robot::RobotConfig, joints: &[String]) -> Self {
        let is_wck = |name: &str| {
            config
                .joints
                .iter()
                .find(|j| j.name == name)
                .is_some_and(|j| config.is_wck(j))
        };
        let mut t = Self::robot(joints.iter().map(|n| (n.as_str(), is_wck(n))));
        t.commanded = true;
        t
    }

    /// Fills the rows from one tick of a played trajectory (its joints in the table's
    /// order): each row's target, and its position where the joint reported one.
    pub fn take_tick(&mut self, tick: &crate::catalogue::robot::PlayTick<'_>) {
        self.begin(tick.t_s);
        for ((row, target), at) in self.rows.iter_mut().zip(tick.targets).zip(tick.positions) {
            row.target_deg = Some(*target);
            match at {
                Some(p) => {
                    row.position_deg = Some(*p);
                    row.got();
                }
                None => row.missed("no reply"),
            }
        }
    }

    fn begin(&mut self, t_s: f64) {
        self.t_s = t_s;
        self.samples += 1;
    }

    /// The devices that stayed silent: never answered, or missed the latest sample (the
    /// values shown last were stale); each as `name (k of n samples missing)`.
    #[must_use]
    pub fn silent(&self) -> Vec<String> {
        self.rows
            .iter()
            .filter(|r| self.samples > 0 && (!r.fresh || r.answered == 0))
            .map(|r| {
                format!(
                    "{} ({} of {} samples missing)",
                    r.name, r.failures, self.samples
                )
            })
            .collect()
    }

    /// The CSV header: `t_s`, then per device `NAME_deg`, `NAME_SPEED`, `NAME_EFFORT`
    /// (a name as a column: lower case, anything but letters, digits and `_` as `_`).
    #[must_use]
    pub fn csv_header(&self) -> String {
        let mut s = String::from("t_s");
        let speed = self.speed_unit.key();
        for r in &self.rows {
            let n = column_name(&r.name);
            let _ = write!(s, ",{n}_deg");
            if self.commanded {
                let _ = write!(s, ",{n}_target_deg");
            }
            let _ = write!(s, ",{n}_{speed},{n}_{}", r.effort_kind.unit());
        }
        s
    }

    /// The latest sample as a CSV row (an empty cell for a stale value).
    #[must_use]
    pub fn csv_row(&self) -> String {
        let mut s = format!("{:.4}", self.t_s);
        let cell = |v: Option<f64>| v.map_or_else(String::new, |v| format!("{v:.4}"));
        for r in &self.rows {
            let _ = write!(s, ",{}", cell(r.now(r.position_deg)));
            if self.commanded {
                // What was sent is known whether or not the device answered.
                let _ = write!(s, ",{}", cell(r.target_deg));
            }
            let _ = write!(s, ",{},{}", cell(r.now(r.speed)), cell(r.now(r.effort)));
        }
        s
    }

    /// The latest sample as one JSON object: `t_s`, `sample`, `late`, `lost` and
    /// `channels`, one object per device (`name`, `position_deg`, `speed_rpm` or
    /// `speed_deg_per_s`, `current_ma` or `load`, `enabled`, `error`, `failures`, and
    /// `stale`: its values are then `null`).
    #[must_use]
    pub fn json_line(&self) -> String {
        let speed_key = format!("speed_{}", self.speed_unit.key());
        let channels: Vec<serde_json::Value> = self
            .rows
            .iter()
            .map(|r| {
                let mut o = serde_json::Map::new();
                o.insert("name".into(), r.name.clone().into());
                o.insert("position_deg".into(), r.now(r.position_deg).into());
                if self.commanded {
                    o.insert("target_deg".into(), r.target_deg.into());
                }
                o.insert(speed_key.clone(), r.now(r.speed).into());
                o.insert(r.effort_kind.key().into(), r.now(r.effort).into());
                o.insert("enabled".into(), r.now(r.enabled).into());
                o.insert("error".into(), r.error.clone().into());
                o.insert("failures".into(), r.failures.into());
                o.insert("stale".into(), (!r.fresh).into());
                serde_json::Value::Object(o)
            })
            .collect();
        serde_json::json!({
            "t_s": (self.t_s * 1e4).round() / 1e4,
            "sample": self.samples,
            "late": self.late,
            "lost": self.lost,
            "channels": channels,
        })
        .to_string()
    }
}

/// The name of WHJ joint `id` on its own: `j{id}`, as the built-in simulated robot's
/// file names it.
#[must_use]
pub fn whj_name(id: u8) -> String {
    format!("j{id}")
}

/// The name of wCK servo `id` on its own: `s{id}`, as the built-in simulated robot's
/// file names it.
#[must_use]
pub fn wck_name(id: u8) -> String {
    format!("s{id}")
}

/// A device name as a CSV column prefix: lower case, anything but letters, digits and `_`
/// replaced by `_` (a robot file's joint names are free text).
fn column_name(name: &str) -> String {
    name.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '_' {
                c.to_ascii_lowercase()
            } else {
                '_'
            }
        })
        .collect()
}

/// How a [`Recorder`] writes samples.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RecordFormat {
    /// CSV: a `# ` comment line naming the source, the header, a row per sample.
    Csv,
    /// JSON lines: one [`SampleTable::json_line`] object per line.
    JsonLines,
    /// MCAP: the samples (JSON) and the joint states (CDR) on two channels (see the
    /// [module docs](self)).
    Mcap,
}

impl RecordFormat {
    /// The format a file name asks for: `.csv`, `.jsonl` / `.ndjson` or `.mcap`; `None`
    /// for any other name.
    #[must_use]
    pub fn of_path(path: &Path) -> Option<Self> {
        match path.extension().and_then(|e| e.to_str()) {
            Some("csv") => Some(Self::Csv),
            Some("jsonl" | "ndjson") => Some(Self::JsonLines),
            Some("mcap") => Some(Self::Mcap),
            _ => None,
        }
    }
}

/// Where a [`Recorder`] writes.
#[derive(Debug)]
enum Sink<W: Write + Seek> {
    /// CSV or JSON lines.
    Text(W, RecordFormat),
    Mcap(Box<McapSink<W>>),
}

/// Samples written to a file as they are taken (flushed every 16 samples and at the
/// end; an MCAP file is complete, with its summary, only after [`Recorder::finish`]).
#[derive(Debug)]
pub struct Recorder<W: Write + Seek> {
    sink: Sink<W>,
    written: u64,
}

/// Samples between two flushes of a [`Recorder`].
const FLUSH_EVERY: u64 = 16;

impl Recorder<std::io::BufWriter<std::fs::File>> {
    /// Creates (or truncates) `path` and writes the format's head for `table`, whose
    /// source `heading` names (`WHJ bus can0`).
    ///
    /// # Errors
    ///
    /// [`OpError::File`]: of kind [`ErrorKind::BadInput`] when the name asks for no known
    /// format (the message names the endings allowed), of kind [`ErrorKind::Link`] when
    /// the file cannot be created or written.
    pub fn create(path: &Path, heading: &str, table: &SampleTable) -> Result<Self, OpError> {
        let fail = |kind, reason: String| OpError::File {
            path: path.to_path_buf(),
            reason,
            kind,
        };
        let format = RecordFormat::of_path(path).ok_or_else(|| {
            fail(
                ErrorKind::BadInput,
                "a recording's name ends in .csv, .jsonl, .ndjson or .mcap".into(),
            )
        })?;
        let file = std::fs::File::create(path)
            .map_err(|e| fail(ErrorKind::Link, format!("cannot create: {e}")))?;
        Self::new(std::io::BufWriter::new(file), format, heading, table)
            .map_err(|e| fail(ErrorKind::Link, format!("cannot write: {e}")))
    }
}

impl<W: Write + Seek> Recorder<W> {
    /// Writes the format's head for `table` (CSV: the `# robobus monitor: HEADING`
    /// comment, `play` for a table of what was commanded, and the header; JSON lines:
    /// nothing; MCAP: the header, the schemas, the channels and a metadata record) to
    /// `out`.
    ///
    /// # Errors
    ///
    /// The writer's error.
    pub fn new(
        mut out: W,
        format: RecordFormat,
        heading: &str,
        table: &SampleTable,
    ) -> std::io::Result<Self> {
        let sink = match format {
            RecordFormat::Csv => {
                let what = if table.commanded { "play" } else { "monitor" };
                writeln!(out, "# robobus {what}: {heading}")?;
                writeln!(out, "{}", table.csv_header())?;
                Sink::Text(out, format)
            }
            RecordFormat::JsonLines => Sink::Text(out, format),
            RecordFormat::Mcap => Sink::Mcap(Box::new(McapSink::new(out, heading, table)?)),
        };
        Ok(Self { sink, written: 0 })
    }

    /// Writes `table`'s latest sample.
    ///
    /// # Errors
    ///
    /// The writer's error.
    pub fn record(&mut self, table: &SampleTable) -> std::io::Result<()> {
        match &mut self.sink {
            Sink::Text(out, RecordFormat::Csv) => writeln!(out, "{}", table.csv_row())?,
            Sink::Text(out, _) => writeln!(out, "{}", table.json_line())?,
            Sink::Mcap(m) => m.record(table)?,
        }
        self.written += 1;
        if self.written.is_multiple_of(FLUSH_EVERY) {
            match &mut self.sink {
                Sink::Text(out, _) => out.flush()?,
                Sink::Mcap(m) => m.flush()?,
            }
        }
        Ok(())
    }

    /// Samples written.
    #[must_use]
    pub const fn written(&self) -> u64 {
        self.written
    }

    /// Flushes what is buffered and gives the writer back.
    ///
    /// # Errors
    ///
    /// The writer's error.
    pub fn finish(self) -> std::io::Result<W> {
        match self.sink {
            Sink::Text(mut out, _) => {
                out.flush()?;
                Ok(out)
            }
            Sink::Mcap(m) => {
                let mut out = m.finish()?;
                out.flush()?;
                Ok(out)
            }
        }
    }
}

mod mcap_file;

use mcap_file::McapSink;
pub use mcap_file::{
    Columns, JOINT_COMMANDS_TOPIC, JOINT_STATES_TOPIC, MAX_SAMPLES, SAMPLES_TOPIC, read_columns,
};

#[cfg(test)]
mod tests;
