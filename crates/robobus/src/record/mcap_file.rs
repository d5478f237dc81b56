//! Samples as MCAP (the container Foxglove, `ros2 bag` and the `mcap` tools open), on two
//! channels with one time base (each message's log and publish time is the sample's:
//! the recording's start on the wall clock plus its `t_s`):
//!
//! - [`SAMPLES_TOPIC`]: every sample as the JSON object of [`SampleTable::json_line`]
//!   (message encoding `json`, a `jsonschema` schema), every device with its failures
//!   and staleness, the units in its keys;
//! - [`JOINT_STATES_TOPIC`]: `sensor_msgs/msg/JointState` in CDR (message encoding
//!   `cdr`, schema `ros2msg`), with the devices that answered that sample, named as the
//!   bridge names them (a robot file's joint names; a device by ID as the built-in
//!   simulated robot names it, `j1`, `s0`): position in radians, velocity in radians per
//!   second, effort the torque in N·m the bridge publishes ([`SampleRow::effort_nm`],
//!   estimated from a WHJ joint's current by [`sampler::effort_nm`]), `NaN` where there is
//!   none (a wCK servo's load is not a torque; it is in the samples channel, as is the
//!   current). A sample no device answered has none.
//!
//! A metadata record `robobus` names the source (`heading`) and the speed unit.

use std::collections::BTreeMap;
use std::io::{Seek, Write};

use mcap::records::{MessageHeader, Metadata};

#[cfg(doc)]
use super::{SampleRow, sampler};
use super::{SampleTable, SpeedUnit};
use crate::cdr::{JointState, Time};

/// The topic of the samples (JSON).
pub const SAMPLES_TOPIC: &str = "/robobus/samples";
/// The topic of the joint states (CDR).
pub const JOINT_STATES_TOPIC: &str = "/joint_states";
/// The topic of what was commanded, as joint states (CDR; only in a recording of a
/// table with [`SampleTable::commanded`]: every joint's target position each sample).
pub const JOINT_COMMANDS_TOPIC: &str = "/robobus/joint_commands";

/// The JSON Schema of a samples message.
const SAMPLE_SCHEMA: &str = r#"{
  "title": "robobus sample",
  "type": "object",
  "properties": {
    "t_s": {"type": "number", "description": "seconds since the recording started"},
    "sample": {"type": "integer"},
    "late": {"type": "boolean"},
    "lost": {"type": "integer"},
    "channels": {
      "type": "array",
      "items": {
        "type": "object",
        "properties": {
          "name": {"type": "string"},
          "position_deg": {"type": ["number", "null"]},
          "target_deg": {"type": ["number", "null"]},
          "speed_rpm": {"type": ["number", "null"]},
          "speed_deg_per_s": {"type": ["number", "null"]},
          "current_ma": {"type": ["number", "null"]},
          "load": {"type": ["number", "null"]},
          "enabled": {"type": ["boolean", "null"]},
          "error": {"type": "string"},
          "failures": {"type": "integer"},
          "stale": {"type": "boolean"}
        }
      }
    }
  }
}"#;

/// `sensor_msgs/msg/JointState` with its dependencies, as ROS 2 bags store it.
const JOINT_STATE_MSG: &str = "\
std_msgs/Header header
string[] name
float64[] position
float64[] velocity
float64[] effort
================================================================================
MSG: std_msgs/Header
builtin_interfaces/Time stamp
string frame_id
================================================================================
MSG: builtin_interfaces/Time
int32 sec
uint32 nanosec
";

/// An MCAP recording being written.
pub(super) struct McapSink<W: Write + Seek> {
    writer: mcap::Writer<W>,
    samples: u16,
    joint_states: u16,
    /// The commands' channel, in a recording of what was commanded.
    joint_commands: Option<u16>,
    /// The recording's start, ns since the Unix epoch.
    start_ns: u64,
    sequence: u32,
}

impl<W: Write + Seek> std::fmt::Debug for McapSink<W> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("McapSink")
            .field("start_ns", &self.start_ns)
            .field("sequence", &self.sequence)
            .finish_non_exhaustive()
    }
}

fn io(e: mcap::McapError) -> std::io::Error {
    match e {
        mcap::McapError::Io(e) => e,
        e => std::io::Error::other(e),
    }
}

impl<W: Write + Seek> McapSink<W> {
    /// Starts the file: header, schemas, channels and the metadata record.
    pub(super) fn new(out: W, heading: &str, table: &SampleTable) -> std::io::Result<Self> {
        let mut writer = mcap::WriteOptions::new()
            .profile("ros2")
            .library(concat!("robobus ", env!("CARGO_PKG_VERSION")))
            .create(out)
            .map_err(io)?;
        let none = BTreeMap::new();
        let schema = writer
            .add_schema("robobus/Sample", "jsonschema", SAMPLE_SCHEMA.as_bytes())
            .map_err(io)?;
        let samples = writer
            .add_channel(schema, SAMPLES_TOPIC, "json", &none)
            .map_err(io)?;
        let schema = writer
            .add_schema(
                "sensor_msgs/msg/JointState",
                "ros2msg",
                JOINT_STATE_MSG.as_bytes(),
            )
            .map_err(io)?;
        let joint_states = writer
            .add_channel(schema, JOINT_STATES_TOPIC, "cdr", &none)
            .map_err(io)?;
        let joint_commands = if table.commanded {
            Some(
                writer
                    .add_channel(schema, JOINT_COMMANDS_TOPIC, "cdr", &none)
                    .map_err(io)?,
            )
        } else {
            None
        };
        writer
            .write_metadata(&Metadata {
                name: "robobus".into(),
                metadata: BTreeMap::from([
                    ("source".into(), heading.to_owned()),
                    ("speed_unit".into(), table.speed_unit.as_str().to_owned()),
                ]),
            })
            .map_err(io)?;
        let start_ns = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX));
        Ok(Self {
            writer,
            samples,
            joint_states,
            joint_commands,
            start_ns,
            sequence: 0,
        })
    }

    /// Writes `table`'s latest sample on both channels.
    pub(super) fn record(&mut self, table: &SampleTable) -> std::io::Result<()> {
        // Whole nanoseconds since the start; a negative or absurd `t_s` counts as 0.
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let offset_ns = (table.t_s.clamp(0.0, 1e9) * 1e9).round() as u64;
        let at = self.start_ns.saturating_add(offset_ns);
        let header = |channel_id, sequence| MessageHeader {
            channel_id,
            sequence,
            log_time: at,
            publish_time: at,
        };
        self.writer
            .write_to_known_channel(
                &header(self.samples, self.sequence),
                table.json_line().as_bytes(),
            )
            .map_err(io)?;
        if let Some(state) = joint_state(table, at) {
            self.writer
                .write_to_known_channel(&header(self.joint_states, self.sequence), &state.encode())
                .map_err(io)?;
        }
        if let Some(channel) = self.joint_commands
            && let Some(command) = joint_command(table, at)
        {
            self.writer
                .write_to_known_channel(&header(channel, self.sequence), &command.encode())
                .map_err(io)?;
        }
        self.sequence = self.sequence.wrapping_add(1);
        Ok(())
    }

    /// Writes the summary and the footer and gives the writer back.
    pub(super) fn finish(mut self) -> std::io::Result<W> {
        self.writer.finish().map_err(io)?;
        Ok(self.writer.into_inner())
    }

    /// Flushes what is buffered (the file stays open for more).
    pub(super) fn flush(&mut self) -> std::io::Result<()> {
        self.writer.flush().map_err(io)
    }
}

/// An empty joint state stamped `at_ns`.
fn stamped(at_ns: u64) -> JointState {
    JointState {
        stamp: Time {
            sec: i32::try_from(at_ns / 1_000_000_000).unwrap_or(0),
            // Below 1e9.
            nanosec: (at_ns % 1_000_000_000) as u32,
        },
        ..JointState::default()
    }
}

/// What `table`'s latest sample commanded, as a joint state stamped `at_ns` (positions
/// only, radians); `None` when nothing was.
fn joint_command(table: &SampleTable, at_ns: u64) -> Option<JointState> {
    let mut msg = stamped(at_ns);
    for row in &table.rows {
        let Some(deg) = row.target_deg else {
            continue;
        };
        msg.name.push(row.name.clone());
        msg.position.push(deg.to_radians());
    }
    (!msg.name.is_empty()).then_some(msg)
}

/// The joint state of the devices that answered `table`'s latest sample, stamped `at_ns`;
/// `None` when none did.
fn joint_state(table: &SampleTable, at_ns: u64) -> Option<JointState> {
    let to_rad_s = |v: f64| match table.speed_unit {
        SpeedUnit::Rpm => v * core::f64::consts::TAU / 60.0,
        SpeedUnit::DegPerS => v.to_radians(),
    };
    let mut msg = stamped(at_ns);
    for row in table.rows.iter().filter(|r| r.fresh) {
        let Some(deg) = row.position_deg else {
            continue;
        };
        msg.name.push(row.name.clone());
        msg.position.push(deg.to_radians());
        msg.velocity.push(row.speed.map_or(f64::NAN, to_rad_s));
        msg.effort.push(row.effort_nm.unwrap_or(f64::NAN));
    }
    (!msg.name.is_empty()).then_some(msg)
}

/// The samples of an MCAP recording ([`SAMPLES_TOPIC`]) as the CSV form's columns: the
/// times (`t_s`) and, per device, `NAME_deg` (and `NAME_target_deg` in a recording of
/// what was commanded), `NAME_SPEED` and `NAME_EFFORT` with the units of the keys
/// (`null` of a stale value: `None`).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Columns {
    /// Seconds since the recording started, one per sample.
    pub time: Vec<f64>,
    /// Column name and one value per sample.
    pub signals: Vec<(String, Vec<Option<f64>>)>,
}

/// The keys of a samples message's device object that are columns, and their suffixes.
const VALUE_KEYS: [(&str, &str); 6] = [
    ("position_deg", "deg"),
    ("target_deg", "target_deg"),
    ("speed_rpm", "rpm"),
    ("speed_deg_per_s", "deg_per_s"),
    ("current_ma", "mA"),
    ("load", "load"),
];

/// The most samples read back from one recording.
pub const MAX_SAMPLES: usize = 1 << 22;

/// Reads the samples of an MCAP recording as the CSV form's columns.
///
/// # Errors
///
/// The reason, when the bytes are not MCAP, hold no samples channel, a message is not a
/// samples object, or a sample names other devices than the first (the recording of one
/// run names the same devices throughout); more than [`MAX_SAMPLES`] samples.
pub fn read_columns(bytes: &[u8]) -> Result<Columns, String> {
    let mut cols = Columns::default();
    let mut names: Vec<String> = Vec::new();
    let stream = mcap::MessageStream::new(bytes).map_err(|e| format!("not MCAP: {e}"))?;
    for message in stream {
        let m = message.map_err(|e| format!("not MCAP: {e}"))?;
        if m.channel.topic != SAMPLES_TOPIC {
            continue;
        }
        if cols.time.len() >= MAX_SAMPLES {
            return Err(format!("more than {MAX_SAMPLES} samples"));
        }
        let k = cols.time.len() + 1;
        let v: serde_json::Value = serde_json::from_slice(&m.data)
            .map_err(|e| format!("sample {k} on {SAMPLES_TOPIC}: not JSON: {e}"))?;
        let t = v["t_s"]
            .as_f64()
            .ok_or_else(|| format!("sample {k} on {SAMPLES_TOPIC}: no t_s"))?;
        let devices = v["channels"]
            .as_array()
            .ok_or_else(|| format!("sample {k} on {SAMPLES_TOPIC}: no channels"))?;
        let mut row: Vec<(String, Option<f64>)> = Vec::new();
        for d in devices {
            let name = super::column_name(d["name"].as_str().unwrap_or_default());
            for (key, unit) in VALUE_KEYS {
                if d.get(key).is_none() {
                    continue;
                }
                row.push((format!("{name}_{unit}"), d[key].as_f64()));
            }
        }
        let these: Vec<String> = row.iter().map(|(n, _)| n.clone()).collect();
        if cols.time.is_empty() {
            names = these;
            cols.signals = names.iter().map(|n| (n.clone(), Vec::new())).collect();
        } else if these != names {
            return Err(format!(
                "sample {k} on {SAMPLES_TOPIC} has other columns ({}) than the first ({})",
                these.join(","),
                names.join(",")
            ));
        }
        cols.time.push(t);
        for ((_, values), (_, v)) in cols.signals.iter_mut().zip(row) {
            values.push(v);
        }
    }
    if cols.time.is_empty() {
        return Err(format!("no samples on {SAMPLES_TOPIC}"));
    }
    Ok(cols)
}
