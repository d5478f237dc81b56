//! CDR, as ROS 2 puts its messages on the wire, for the few messages robobus speaks (the
//! Zenoh bridge, MCAP recordings): `sensor_msgs/msg/JointState`,
//! `std_msgs/msg/Float64MultiArray`, `trajectory_msgs/msg/JointTrajectory`, the
//! `control_msgs/msg/JointTrajectoryControllerState` a trajectory's progress is published in
//! and `diagnostic_msgs/msg/DiagnosticArray` ([`diagnostics`]).
//!
//! A payload is the 4-byte encapsulation header (`00 01 00 00`: CDR, little endian; `00 00
//! 00 00`: big endian), then the body. Every primitive is aligned to its own size, counted
//! from the end of the header; a string is a `u32` length that counts its NUL, the bytes,
//! then the NUL; a sequence is a `u32` count, then its elements.
//!
//! The encoder writes zero padding and nothing after the last field. The decoder reads
//! what DDS writers really send: it ignores what the padding holds (Fast DDS leaves
//! non-zero bytes there) and any bytes after the message. Everything it reads is bounded
//! ([`MAX_PAYLOAD`], [`MAX_ELEMENTS`], [`MAX_STRING`]), and a count is checked against the
//! bytes left before anything is allocated, so no payload can make it panic or grow memory
//! beyond its own size.

use thiserror::Error;

pub mod diagnostics;
pub use diagnostics::{DiagnosticArray, DiagnosticStatus, KeyValue};

/// The encapsulation header of little-endian CDR.
pub const CDR_LE: [u8; 4] = [0x00, 0x01, 0x00, 0x00];
/// The largest payload decoded, bytes.
pub const MAX_PAYLOAD: usize = 1 << 20;
/// The most elements of one sequence (joint names, positions, array data).
pub const MAX_ELEMENTS: usize = 4096;
/// The longest string, bytes (without its NUL).
pub const MAX_STRING: usize = 1024;
/// The most points of one trajectory.
pub const MAX_TRAJECTORY_POINTS: usize = 10_000;

/// `builtin_interfaces/msg/Time`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Time {
    /// Seconds since the Unix epoch.
    pub sec: i32,
    /// Nanoseconds, 0..1e9.
    pub nanosec: u32,
}

impl Time {
    /// The time `unix_ms` milliseconds after the epoch (0 for a value that does not fit).
    pub fn from_unix_ms(unix_ms: f64) -> Self {
        if !(0.0..f64::from(i32::MAX) * 1e3).contains(&unix_ms) {
            return Self::default();
        }
        let ns = (unix_ms * 1e6).round();
        // In range: checked above (and 1e9 fits a u32).
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        Self {
            sec: (ns / 1e9).floor() as i32,
            nanosec: (ns % 1e9) as u32,
        }
    }
}

/// `builtin_interfaces/msg/Duration`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Duration {
    /// Whole seconds (may be negative).
    pub sec: i32,
    /// Nanoseconds, 0..1e9 (read as they come; [`Duration::as_secs_f64`] takes them as
    /// they are).
    pub nanosec: u32,
}

impl Duration {
    /// Seconds, `sec + nanosec / 1e9`.
    #[must_use]
    pub fn as_secs_f64(self) -> f64 {
        f64::from(self.sec) + f64::from(self.nanosec) / 1e9
    }

    /// The duration of `s` seconds, to the nanosecond (0 for a value that is not finite or
    /// does not fit an `i32` of seconds).
    #[must_use]
    pub fn from_secs_f64(s: f64) -> Self {
        if !(s.is_finite() && (f64::from(i32::MIN)..f64::from(i32::MAX)).contains(&s)) {
            return Self::default();
        }
        let sec = s.floor();
        // In range: checked above; the fraction is in 0..1 s.
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let nanosec = (((s - sec) * 1e9).round() as u32).min(999_999_999);
        #[allow(clippy::cast_possible_truncation)]
        Self {
            sec: sec as i32,
            nanosec,
        }
    }
}

impl Time {
    /// Seconds since the epoch, `sec + nanosec / 1e9`; `None` for the zero stamp (which a
    /// trajectory's header means as "now").
    #[must_use]
    pub fn as_unix_s(self) -> Option<f64> {
        (self != Self::default()).then(|| f64::from(self.sec) + f64::from(self.nanosec) / 1e9)
    }
}

/// `trajectory_msgs/msg/JointTrajectoryPoint`.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct JointTrajectoryPoint {
    /// Positions, rad, one per joint name (or none).
    pub positions: Vec<f64>,
    /// Velocities, rad/s (or none).
    pub velocities: Vec<f64>,
    /// Accelerations, rad/s² (or none).
    pub accelerations: Vec<f64>,
    /// Efforts, N·m (or none).
    pub effort: Vec<f64>,
    /// When the point is due, from the trajectory's start.
    pub time_from_start: Duration,
}

/// `trajectory_msgs/msg/JointTrajectory` (its `std_msgs/Header` flattened).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct JointTrajectory {
    /// `header.stamp`: when the trajectory starts (zero: when it is received).
    pub stamp: Time,
    /// `header.frame_id`.
    pub frame_id: String,
    /// The joints, in the order of every point's values.
    pub joint_names: Vec<String>,
    /// The points, at most [`MAX_TRAJECTORY_POINTS`].
    pub points: Vec<JointTrajectoryPoint>,
}

/// `control_msgs/msg/JointTrajectoryControllerState` as `ros2_controllers`'
/// `joint_trajectory_controller` publishes it since `control_msgs` 5 (ROS 2 Jazzy): the
/// header, the joints, then `reference`, `feedback`, `error` and `output` points; its
/// multi-DOF fields are written empty.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct JointTrajectoryControllerState {
    /// `header.stamp`.
    pub stamp: Time,
    /// `header.frame_id`.
    pub frame_id: String,
    /// The joints, in the order of every point's values.
    pub joint_names: Vec<String>,
    /// The trajectory's desired state now.
    pub reference: JointTrajectoryPoint,
    /// What the joints reported.
    pub feedback: JointTrajectoryPoint,
    /// `reference` − `feedback`.
    pub error: JointTrajectoryPoint,
    /// What was sent to the joints (short of `reference` where a joint was held back).
    pub output: JointTrajectoryPoint,
}

/// `sensor_msgs/msg/JointState` (its `std_msgs/Header` flattened).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct JointState {
    /// `header.stamp`.
    pub stamp: Time,
    /// `header.frame_id`.
    pub frame_id: String,
    /// Joint names.
    pub name: Vec<String>,
    /// Positions, rad.
    pub position: Vec<f64>,
    /// Velocities, rad/s.
    pub velocity: Vec<f64>,
    /// Efforts, N·m.
    pub effort: Vec<f64>,
}

/// `std_msgs/msg/MultiArrayDimension`.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct MultiArrayDimension {
    /// The dimension's label.
    pub label: String,
    /// Its size.
    pub size: u32,
    /// Its stride.
    pub stride: u32,
}

/// `std_msgs/msg/Float64MultiArray` (its `MultiArrayLayout` flattened).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Float64MultiArray {
    /// `layout.dim`.
    pub dim: Vec<MultiArrayDimension>,
    /// `layout.data_offset`.
    pub data_offset: u32,
    /// The data.
    pub data: Vec<f64>,
}

/// Why a payload is not a message.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum CdrError {
    /// Shorter than the encapsulation header.
    #[error("a payload of {0} bytes: too short for the 4-byte CDR encapsulation header")]
    NoHeader(usize),
    /// An encapsulation other than plain CDR.
    #[error(
        "encapsulation {0:#06x}: only plain CDR is read (0x0001 little endian, 0x0000 big \
         endian)"
    )]
    Encapsulation(u16),
    /// Larger than [`MAX_PAYLOAD`].
    #[error("a payload of {0} bytes: more than the {MAX_PAYLOAD} read")]
    TooLarge(usize),
    /// The message ends inside a field.
    #[error("{field}: the message ends at byte {len}, inside it")]
    Truncated {
        /// The field.
        field: &'static str,
        /// The payload's length.
        len: usize,
    },
    /// A sequence or string longer than allowed (or than the bytes left).
    #[error("{field}: {count} elements, more than the {max} that fit")]
    TooLong {
        /// The field.
        field: &'static str,
        /// Its count.
        count: usize,
        /// The most allowed here.
        max: usize,
    },
    /// A string that is not NUL-terminated UTF-8.
    #[error("{field}: not a NUL-terminated UTF-8 string")]
    BadString {
        /// The field.
        field: &'static str,
    },
}

/// Writes CDR, little endian, after the encapsulation header.
#[derive(Debug)]
struct Writer {
    buf: Vec<u8>,
}

impl Writer {
    fn new() -> Self {
        Self {
            buf: CDR_LE.to_vec(),
        }
    }

    fn align(&mut self, n: usize) {
        while !(self.buf.len() - CDR_LE.len()).is_multiple_of(n) {
            self.buf.push(0);
        }
    }

    fn u32(&mut self, v: u32) {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    fn count(&mut self, n: usize) {
        // Callers bound their sequences far below u32::MAX.
        self.u32(u32::try_from(n).unwrap_or(u32::MAX));
    }

    fn string(&mut self, s: &str) {
        self.count(s.len() + 1);
        self.buf.extend_from_slice(s.as_bytes());
        self.buf.push(0);
    }

    fn strings(&mut self, v: &[String]) {
        self.count(v.len());
        for s in v {
            self.string(s);
        }
    }

    fn f64s(&mut self, v: &[f64]) {
        self.count(v.len());
        for x in v {
            self.align(8);
            self.buf.extend_from_slice(&x.to_le_bytes());
        }
    }
}

/// Reads CDR after the encapsulation header, ignoring padding contents.
#[derive(Debug)]
struct Reader<'a> {
    buf: &'a [u8],
    pos: usize,
    little: bool,
}

impl<'a> Reader<'a> {
    fn new(payload: &'a [u8]) -> Result<Self, CdrError> {
        if payload.len() > MAX_PAYLOAD {
            return Err(CdrError::TooLarge(payload.len()));
        }
        let Some(header) = payload.get(..4) else {
            return Err(CdrError::NoHeader(payload.len()));
        };
        let little = match u16::from_be_bytes([header[0], header[1]]) {
            0x0001 => true,
            0x0000 => false,
            other => return Err(CdrError::Encapsulation(other)),
        };
        Ok(Self {
            buf: payload,
            pos: 4,
            little,
        })
    }

    fn take(&mut self, n: usize, align: usize, field: &'static str) -> Result<&'a [u8], CdrError> {
        let start = 4 + (self.pos - 4).div_ceil(align) * align;
        let truncated = CdrError::Truncated {
            field,
            len: self.buf.len(),
        };
        let end = start.checked_add(n).ok_or(truncated.clone())?;
        let bytes = self.buf.get(start..end).ok_or(truncated)?;
        self.pos = end;
        Ok(bytes)
    }

    /// `N` bytes aligned to `N`, little endian first (reversed when the payload is big
    /// endian), for `from_le_bytes`.
    fn fixed<const N: usize>(&mut self, field: &'static str) -> Result<[u8; N], CdrError> {
        let len = self.buf.len();
        let mut b: [u8; N] = self
            .take(N, N, field)?
            .try_into()
            .map_err(|_| CdrError::Truncated { field, len })?;
        if !self.little {
            b.reverse();
        }
        Ok(b)
    }

    fn u32(&mut self, field: &'static str) -> Result<u32, CdrError> {
        self.fixed(field).map(u32::from_le_bytes)
    }

    fn i32(&mut self, field: &'static str) -> Result<i32, CdrError> {
        self.fixed(field).map(i32::from_le_bytes)
    }

    fn f64(&mut self, field: &'static str) -> Result<f64, CdrError> {
        self.fixed(field).map(f64::from_le_bytes)
    }

    /// A count of elements of at least `min_bytes` each, checked against `max` and
    /// against the bytes left (so nothing is allocated for a count the payload cannot
    /// hold).
    fn count(
        &mut self,
        field: &'static str,
        max: usize,
        min_bytes: usize,
    ) -> Result<usize, CdrError> {
        let n = usize::try_from(self.u32(field)?).unwrap_or(usize::MAX);
        let left = self.buf.len() - self.pos;
        let fit = max.min(left / min_bytes.max(1));
        if n > fit {
            return Err(CdrError::TooLong {
                field,
                count: n,
                max: fit,
            });
        }
        Ok(n)
    }

    fn string(&mut self, field: &'static str) -> Result<String, CdrError> {
        let n = self.count(field, MAX_STRING + 1, 1)?;
        let bytes = self.take(n, 1, field)?;
        match bytes.split_last() {
            Some((0, text)) => std::str::from_utf8(text)
                .map(str::to_owned)
                .map_err(|_| CdrError::BadString { field }),
            _ => Err(CdrError::BadString { field }),
        }
    }

    fn strings(&mut self, field: &'static str) -> Result<Vec<String>, CdrError> {
        // A string takes at least 5 bytes: its length and its NUL.
        let n = self.count(field, MAX_ELEMENTS, 5)?;
        (0..n).map(|_| self.string(field)).collect()
    }

    fn f64s(&mut self, field: &'static str) -> Result<Vec<f64>, CdrError> {
        let n = self.count(field, MAX_ELEMENTS, 8)?;
        (0..n).map(|_| self.f64(field)).collect()
    }
}

impl JointState {
    /// The payload: header and little-endian CDR.
    pub fn encode(&self) -> Vec<u8> {
        let mut w = Writer::new();
        w.header(self.stamp, &self.frame_id);
        w.strings(&self.name);
        w.f64s(&self.position);
        w.f64s(&self.velocity);
        w.f64s(&self.effort);
        w.buf
    }

    /// Reads a payload (see the [module docs](self) for what is tolerated).
    pub fn decode(payload: &[u8]) -> Result<Self, CdrError> {
        let mut r = Reader::new(payload)?;
        Ok(Self {
            stamp: Time {
                sec: r.i32("header.stamp.sec")?,
                nanosec: r.u32("header.stamp.nanosec")?,
            },
            frame_id: r.string("header.frame_id")?,
            name: r.strings("name")?,
            position: r.f64s("position")?,
            velocity: r.f64s("velocity")?,
            effort: r.f64s("effort")?,
        })
    }
}

impl Float64MultiArray {
    /// A one-dimensional array of `data` (no dimensions described, as the forward
    /// command controllers of `ros2_controllers` take it).
    pub fn of(data: Vec<f64>) -> Self {
        Self {
            dim: Vec::new(),
            data_offset: 0,
            data,
        }
    }

    /// The payload: header and little-endian CDR.
    pub fn encode(&self) -> Vec<u8> {
        let mut w = Writer::new();
        w.count(self.dim.len());
        for d in &self.dim {
            w.string(&d.label);
            w.u32(d.size);
            w.u32(d.stride);
        }
        w.u32(self.data_offset);
        w.f64s(&self.data);
        w.buf
    }

    /// Reads a payload (see the [module docs](self) for what is tolerated).
    pub fn decode(payload: &[u8]) -> Result<Self, CdrError> {
        let mut r = Reader::new(payload)?;
        // A dimension takes at least 13 bytes: a label's length and NUL, size, stride.
        let n = r.count("layout.dim", MAX_ELEMENTS, 13)?;
        let dim = (0..n)
            .map(|_| {
                Ok(MultiArrayDimension {
                    label: r.string("layout.dim.label")?,
                    size: r.u32("layout.dim.size")?,
                    stride: r.u32("layout.dim.stride")?,
                })
            })
            .collect::<Result<_, CdrError>>()?;
        Ok(Self {
            dim,
            data_offset: r.u32("layout.data_offset")?,
            data: r.f64s("data")?,
        })
    }
}

impl Writer {
    fn i32(&mut self, v: i32) {
        self.u32(u32::from_ne_bytes(v.to_ne_bytes()));
    }

    fn header(&mut self, stamp: Time, frame_id: &str) {
        self.i32(stamp.sec);
        self.u32(stamp.nanosec);
        self.string(frame_id);
    }

    fn point(&mut self, p: &JointTrajectoryPoint) {
        self.f64s(&p.positions);
        self.f64s(&p.velocities);
        self.f64s(&p.accelerations);
        self.f64s(&p.effort);
        self.i32(p.time_from_start.sec);
        self.u32(p.time_from_start.nanosec);
    }
}

impl Reader<'_> {
    fn point(&mut self) -> Result<JointTrajectoryPoint, CdrError> {
        Ok(JointTrajectoryPoint {
            positions: self.f64s("points.positions")?,
            velocities: self.f64s("points.velocities")?,
            accelerations: self.f64s("points.accelerations")?,
            effort: self.f64s("points.effort")?,
            time_from_start: Duration {
                sec: self.i32("points.time_from_start.sec")?,
                nanosec: self.u32("points.time_from_start.nanosec")?,
            },
        })
    }
}

impl JointTrajectory {
    /// The payload: header and little-endian CDR.
    pub fn encode(&self) -> Vec<u8> {
        let mut w = Writer::new();
        w.header(self.stamp, &self.frame_id);
        w.strings(&self.joint_names);
        w.count(self.points.len());
        for p in &self.points {
            w.point(p);
        }
        w.buf
    }

    /// Reads a payload (see the [module docs](self) for what is tolerated); at most
    /// [`MAX_TRAJECTORY_POINTS`] points.
    pub fn decode(payload: &[u8]) -> Result<Self, CdrError> {
        let mut r = Reader::new(payload)?;
        let stamp = Time {
            sec: r.i32("header.stamp.sec")?,
            nanosec: r.u32("header.stamp.nanosec")?,
        };
        let frame_id = r.string("header.frame_id")?;
        let joint_names = r.strings("joint_names")?;
        // A point takes at least 24 bytes: four empty sequences and its duration.
        let n = r.count("points", MAX_TRAJECTORY_POINTS, 24)?;
        let points = (0..n).map(|_| r.point()).collect::<Result<_, _>>()?;
        Ok(Self {
            stamp,
            frame_id,
            joint_names,
            points,
        })
    }
}

impl JointTrajectoryControllerState {
    /// The payload: header and little-endian CDR (the multi-DOF fields empty: no names
    /// and four empty `MultiDOFJointTrajectoryPoint`s).
    pub fn encode(&self) -> Vec<u8> {
        let mut w = Writer::new();
        w.header(self.stamp, &self.frame_id);
        w.strings(&self.joint_names);
        for p in [&self.reference, &self.feedback, &self.error, &self.output] {
            w.point(p);
        }
        // multi_dof_joint_names, then four points of transforms, velocities and
        // accelerations (all empty) and a zero duration.
        w.count(0);
        for _ in 0..4 {
            w.count(0);
            w.count(0);
            w.count(0);
            w.i32(0);
            w.u32(0);
        }
        w.buf
    }
}

/// `control_msgs/action/FollowJointTrajectory`'s result codes, which a trajectory's end
/// carries (`error_code`).
pub mod result_code {
    /// Reached.
    pub const SUCCESSFUL: i32 = 0;
    /// Refused: a point, a value or a time does not fit.
    pub const INVALID_GOAL: i32 = -1;
    /// Refused: a joint name the robot does not have (or twice).
    pub const INVALID_JOINTS: i32 = -2;
    /// Refused: its stamp says it ended before it arrived.
    pub const OLD_HEADER_TIMESTAMP: i32 = -3;
    /// Aborted on the way (a joint failed, the host's protection, a stop).
    pub const PATH_TOLERANCE_VIOLATED: i32 = -4;
    /// Played, but a joint ended outside the goal tolerance.
    pub const GOAL_TOLERANCE_VIOLATED: i32 = -5;
}

#[cfg(test)]
mod tests {
    use super::*;

    fn hex(s: &str) -> Vec<u8> {
        let s: String = s.split_whitespace().collect();
        (0..s.len())
            .step_by(2)
            .map(|i| u8::from_str_radix(&s[i..i + 2], 16).unwrap())
            .collect()
    }

    /// stamp 1 s 2 ns, frame `base`, names `j1` `j2`, position [0.5, -1.25], velocity
    /// [0, 0.1], effort []: 96 bytes, the same from rosbags' serializer.
    fn golden_joint_state() -> (JointState, Vec<u8>) {
        (
            JointState {
                stamp: Time { sec: 1, nanosec: 2 },
                frame_id: "base".into(),
                name: vec!["j1".into(), "j2".into()],
                position: vec![0.5, -1.25],
                velocity: vec![0.0, 0.1],
                effort: vec![],
            },
            hex(
                "00010000 01000000 02000000 05000000 62617365 00000000 02000000 03000000 \
                 6a310000 03000000 6a320000 02000000 00000000 000000000000e03f \
                 000000000000f4bf 02000000 00000000 0000000000000000 9a9999999999b93f \
                 00000000",
            ),
        )
    }

    /// stamp 3 s 4 ns, frame `base`, joints `j1` `j2`; point 1: positions [0.5, -0.25],
    /// velocities [0, 0.1], at 1.5 s; point 2: positions [1, 0] at 2 s (no velocities): 152
    /// bytes, written by rosbags 0.11.9's serializer (`crates/bridge/tests/py/
    /// test_trajectory.py` checks it makes them still).
    const GOLDEN_TRAJECTORY: &str = "\
        00010000030000000400000005000000626173650000000002000000030000006a31000003000000\
        6a3200000200000002000000000000000000e03f000000000000d0bf020000000000000000000000\
        000000009a9999999999b93f0000000000000000010000000065cd1d020000000000000000000000\
        0000f03f00000000000000000000000000000000000000000200000000000000";

    fn golden_trajectory() -> JointTrajectory {
        let point =
            |positions: Vec<f64>, velocities: Vec<f64>, sec, nanosec| JointTrajectoryPoint {
                positions,
                velocities,
                accelerations: vec![],
                effort: vec![],
                time_from_start: Duration { sec, nanosec },
            };
        JointTrajectory {
            stamp: Time { sec: 3, nanosec: 4 },
            frame_id: "base".into(),
            joint_names: vec!["j1".into(), "j2".into()],
            points: vec![
                point(vec![0.5, -0.25], vec![0.0, 0.1], 1, 500_000_000),
                point(vec![1.0, 0.0], vec![], 2, 0),
            ],
        }
    }

    #[test]
    #[allow(clippy::float_cmp)] // exact: 1.5 and the stamp are what the bytes hold
    fn joint_trajectory_encodes_to_rosbags_bytes_and_back() {
        let bytes = hex(GOLDEN_TRAJECTORY);
        assert_eq!(bytes.len(), 152);
        let msg = golden_trajectory();
        assert_eq!(msg.encode(), bytes);
        assert_eq!(JointTrajectory::decode(&bytes).unwrap(), msg);
        assert_eq!(msg.points[0].time_from_start.as_secs_f64(), 1.5);
        assert_eq!(msg.stamp.as_unix_s(), Some(3.000_000_004));
        assert_eq!(Time::default().as_unix_s(), None);
    }

    /// joint `j3`, stamp 5 s 6 ns; reference 0.5, feedback 0.25, error 0.25, output 0.5,
    /// each at 0.25 s; the multi-DOF fields empty: 244 bytes, written by rosbags 0.11.9
    /// with `control_msgs` 5's definition registered.
    const GOLDEN_CONTROLLER_STATE: &str = "\
        000100000500000006000000010000000000000001000000030000006a3300000100000000000000\
        0000e03f0000000000000000000000000000000080b2e60e01000000000000000000d03f00000000\
        00000000000000000000000080b2e60e01000000000000000000d03f000000000000000000000000\
        0000000080b2e60e01000000000000000000e03f0000000000000000000000000000000080b2e60e\
        00000000000000000000000000000000000000000000000000000000000000000000000000000000\
        00000000000000000000000000000000000000000000000000000000000000000000000000000000\
        00000000";

    #[test]
    fn controller_state_encodes_to_rosbags_bytes() {
        let at = |p: f64| JointTrajectoryPoint {
            positions: vec![p],
            time_from_start: Duration::from_secs_f64(0.25),
            ..JointTrajectoryPoint::default()
        };
        let msg = JointTrajectoryControllerState {
            stamp: Time { sec: 5, nanosec: 6 },
            frame_id: String::new(),
            joint_names: vec!["j3".into()],
            reference: at(0.5),
            feedback: at(0.25),
            error: at(0.25),
            output: at(0.5),
        };
        let bytes = hex(GOLDEN_CONTROLLER_STATE);
        assert_eq!(bytes.len(), 244);
        assert_eq!(msg.encode(), bytes);
    }

    #[test]
    fn duration_from_seconds() {
        assert_eq!(
            Duration::from_secs_f64(1.5),
            Duration {
                sec: 1,
                nanosec: 500_000_000
            }
        );
        assert_eq!(
            Duration::from_secs_f64(-0.25),
            Duration {
                sec: -1,
                nanosec: 750_000_000
            }
        );
        assert_eq!(Duration::from_secs_f64(f64::NAN), Duration::default());
        assert_eq!(Duration::from_secs_f64(1e12), Duration::default());
    }

    #[test]
    fn every_trajectory_truncation_is_an_error_not_a_panic() {
        let bytes = hex(GOLDEN_TRAJECTORY);
        for n in 0..bytes.len() {
            assert!(JointTrajectory::decode(&bytes[..n]).is_err(), "{n} bytes");
        }
    }

    #[test]
    fn trajectory_points_are_bounded() {
        // A count of MAX_TRAJECTORY_POINTS + 1 points, each the 24 bytes of an empty one.
        let mut b = CDR_LE.to_vec();
        b.extend_from_slice(&[0; 8]); // stamp
        b.extend_from_slice(&1_u32.to_le_bytes());
        b.extend_from_slice(&[0; 4]); // "" and padding
        b.extend_from_slice(&0_u32.to_le_bytes()); // no joint names
        let n = MAX_TRAJECTORY_POINTS + 1;
        b.extend_from_slice(&u32::try_from(n).unwrap().to_le_bytes());
        b.extend(std::iter::repeat_n(0, 24 * n));
        assert_eq!(
            JointTrajectory::decode(&b),
            Err(CdrError::TooLong {
                field: "points",
                count: n,
                max: MAX_TRAJECTORY_POINTS
            })
        );
        // One point fewer decodes: empty points.
        let end = b.len() - 24;
        let count_at = 4 + 8 + 8 + 4;
        b[count_at..count_at + 4].copy_from_slice(&u32::try_from(n - 1).unwrap().to_le_bytes());
        assert_eq!(
            JointTrajectory::decode(&b[..end]).unwrap().points.len(),
            MAX_TRAJECTORY_POINTS
        );
        // A count the bytes left cannot hold.
        let mut short = hex(GOLDEN_TRAJECTORY)[..44].to_vec();
        short.extend_from_slice(&1000_u32.to_le_bytes());
        assert!(matches!(
            JointTrajectory::decode(&short),
            Err(CdrError::TooLong {
                field: "points",
                count: 1000,
                ..
            })
        ));
    }

    #[test]
    fn joint_state_encodes_to_the_golden_bytes_and_back() {
        let (msg, bytes) = golden_joint_state();
        assert_eq!(bytes.len(), 96);
        assert_eq!(msg.encode(), bytes);
        assert_eq!(JointState::decode(&bytes).unwrap(), msg);
    }

    #[test]
    fn padding_contents_and_trailing_bytes_are_ignored() {
        let (msg, mut bytes) = golden_joint_state();
        // The padding of the golden vector: after "base"'s NUL (3 bytes), after each of
        // "j1" / "j2" (1 byte each), before both f64 arrays (4 bytes each).
        for i in [21..24, 35..36, 43..44, 48..52, 72..76] {
            for b in &mut bytes[i] {
                *b = 0xA5;
            }
        }
        bytes.extend_from_slice(&[1, 2, 3, 4]);
        assert_eq!(JointState::decode(&bytes).unwrap(), msg);
    }

    #[test]
    fn big_endian_cdr_is_read() {
        let mut w = vec![0, 0, 0, 0];
        w.extend_from_slice(&7_i32.to_be_bytes());
        w.extend_from_slice(&9_u32.to_be_bytes());
        w.extend_from_slice(&1_u32.to_be_bytes());
        w.extend_from_slice(&[0, 0, 0, 0]); // "" and padding
        w.extend_from_slice(&1_u32.to_be_bytes());
        w.extend_from_slice(&2_u32.to_be_bytes());
        w.extend_from_slice(b"a\0\0\0");
        w.extend_from_slice(&1_u32.to_be_bytes());
        w.extend_from_slice(&2.5_f64.to_be_bytes());
        w.extend_from_slice(&[0; 8]); // two empty sequences
        let m = JointState::decode(&w).unwrap();
        assert_eq!(m.stamp, Time { sec: 7, nanosec: 9 });
        assert_eq!(m.name, ["a"]);
        assert_eq!(m.position, [2.5]);
        assert!(m.velocity.is_empty() && m.effort.is_empty());
    }

    #[test]
    fn float64_multi_array_has_the_forward_controller_layout() {
        let msg = Float64MultiArray::of(vec![1.0, -2.0]);
        let bytes = msg.encode();
        assert_eq!(
            bytes,
            hex("00010000 00000000 00000000 02000000 00000000 000000000000f03f 00000000000000c0")
        );
        assert_eq!(Float64MultiArray::decode(&bytes).unwrap(), msg);
        let with_dim = Float64MultiArray {
            dim: vec![MultiArrayDimension {
                label: "joints".into(),
                size: 2,
                stride: 2,
            }],
            data_offset: 0,
            data: vec![0.25, 0.5],
        };
        assert_eq!(
            Float64MultiArray::decode(&with_dim.encode()).unwrap(),
            with_dim
        );
    }

    #[test]
    fn every_truncation_is_an_error_not_a_panic() {
        let (_, bytes) = golden_joint_state();
        for n in 0..bytes.len() {
            assert!(JointState::decode(&bytes[..n]).is_err(), "{n} bytes");
        }
        let a = Float64MultiArray::of(vec![1.0, 2.0]).encode();
        for n in 0..a.len() {
            assert!(Float64MultiArray::decode(&a[..n]).is_err(), "{n} bytes");
        }
    }

    #[test]
    fn counts_are_bounded_by_the_bytes_left() {
        // A count of 2^32-1 names in a 20-byte payload.
        let mut b = CDR_LE.to_vec();
        b.extend_from_slice(&[0; 8]);
        b.extend_from_slice(&1_u32.to_le_bytes());
        b.extend_from_slice(&[0, 0, 0, 0]);
        b.extend_from_slice(&u32::MAX.to_le_bytes());
        assert!(matches!(
            JointState::decode(&b),
            Err(CdrError::TooLong { field: "name", .. })
        ));
        assert_eq!(
            JointState::decode(&[0x00, 0x07, 0, 0]),
            Err(CdrError::Encapsulation(7))
        );
        assert_eq!(JointState::decode(&[0, 1]), Err(CdrError::NoHeader(2)));
        assert_eq!(
            JointState::decode(&vec![0; MAX_PAYLOAD + 1]),
            Err(CdrError::TooLarge(MAX_PAYLOAD + 1))
        );
    }

    #[test]
    fn a_string_without_its_nul_is_refused() {
        let mut b = CDR_LE.to_vec();
        b.extend_from_slice(&[0; 8]);
        b.extend_from_slice(&2_u32.to_le_bytes());
        b.extend_from_slice(b"ab\0\0");
        assert_eq!(
            JointState::decode(&b),
            Err(CdrError::BadString {
                field: "header.frame_id"
            })
        );
    }

    #[test]
    fn time_from_unix_ms() {
        assert_eq!(
            Time::from_unix_ms(1_500.25),
            Time {
                sec: 1,
                nanosec: 500_250_000
            }
        );
        assert_eq!(Time::from_unix_ms(-1.0), Time::default());
        assert_eq!(Time::from_unix_ms(f64::NAN), Time::default());
    }

    proptest::proptest! {
        #[test]
        fn joint_states_round_trip(
            names in proptest::collection::vec("[a-z_0-9]{0,12}", 0..10),
            pos in proptest::collection::vec(proptest::num::f64::NORMAL, 0..10),
            frame in "[a-z]{0,7}",
            sec in proptest::prelude::any::<i32>(),
        ) {
            let msg = JointState {
                stamp: Time { sec, nanosec: 5 },
                frame_id: frame,
                name: names,
                velocity: pos.iter().map(|p| p / 2.0).collect(),
                position: pos,
                effort: vec![],
            };
            proptest::prop_assert_eq!(JointState::decode(&msg.encode()).unwrap(), msg);
        }

        #[test]
        fn joint_trajectories_round_trip(
            names in proptest::collection::vec("[a-z_0-9]{0,12}", 0..8),
            pos in proptest::collection::vec(proptest::num::f64::ANY, 0..8),
            times in proptest::collection::vec((proptest::prelude::any::<i32>(), 0..1_000_000_000_u32), 0..6),
        ) {
            let msg = JointTrajectory {
                stamp: Time { sec: 1, nanosec: 2 },
                frame_id: "f".into(),
                joint_names: names,
                points: times.iter().map(|&(sec, nanosec)| JointTrajectoryPoint {
                    positions: pos.clone(),
                    velocities: pos.iter().map(|p| p * 2.0).collect(),
                    accelerations: vec![],
                    effort: pos.clone(),
                    time_from_start: Duration { sec, nanosec },
                }).collect(),
            };
            let back = JointTrajectory::decode(&msg.encode()).unwrap();
            // NaN != NaN: compared bit for bit through the encoding.
            proptest::prop_assert_eq!(back.encode(), msg.encode());
        }

        #[test]
        fn arbitrary_bytes_never_panic(bytes in proptest::collection::vec(proptest::prelude::any::<u8>(), 0..200)) {
            let _ = JointState::decode(&bytes);
            let _ = Float64MultiArray::decode(&bytes);
            let _ = JointTrajectory::decode(&bytes);
        }
    }
}
