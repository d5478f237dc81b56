//! `NS/diagnostics`: `diagnostic_msgs/msg/DiagnosticArray` in CDR about once a second, one
//! status per joint and per bus of the station's robot file, from the library's
//! diagnostics ([`robobus::station::diagnostics`]) of the joint state thread's own samples:
//! no frame of its own.
//!
//! The CDR is written here with [`robobus::cdr`]'s conventions (little endian after the
//! 4-byte encapsulation header, each primitive aligned to its size from the header's end, a
//! string a `u32` length that counts its NUL, a sequence a `u32` count); golden vectors
//! written by rosbags check it (`tests/vectors/diagnostic_array.hex`, made by
//! `tests/py/diagnostics_vectors.py`). The decoder, for tests and peers written in Rust,
//! reads what DDS writers send as [`robobus::cdr`] does: bounded, padding contents and
//! trailing bytes ignored.

use std::sync::PoisonError;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use robobus::cdr::{CDR_LE, CdrError, MAX_ELEMENTS, MAX_PAYLOAD, MAX_STRING, Time};
use robobus::station::diagnostics::{Diagnosis, STALE_AFTER, Stops};
use zenoh::Wait as _;

use crate::Shared;

/// How often the diagnostics are published.
pub const DIAGNOSTICS_PERIOD: Duration = Duration::from_secs(1);

/// `diagnostic_msgs/msg/KeyValue`.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct KeyValue {
    /// The key (`temperature_c`).
    pub key: String,
    /// The value, as text.
    pub value: String,
}

/// `diagnostic_msgs/msg/DiagnosticStatus`.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct DiagnosticStatus {
    /// `OK` 0, `WARN` 1, `ERROR` 2, `STALE` 3.
    pub level: u8,
    /// `robobus: ROBOT joint NAME`, `robobus: ROBOT bus NAME`.
    pub name: String,
    /// Why it is at its level.
    pub message: String,
    /// The device.
    pub hardware_id: String,
    /// What was read.
    pub values: Vec<KeyValue>,
}

/// `diagnostic_msgs/msg/DiagnosticArray` (its `std_msgs/Header` flattened).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct DiagnosticArray {
    /// `header.stamp`.
    pub stamp: Time,
    /// `header.frame_id`.
    pub frame_id: String,
    /// One status per joint and per bus.
    pub status: Vec<DiagnosticStatus>,
}

/// Writes CDR, little endian, after the encapsulation header.
struct Writer(Vec<u8>);

impl Writer {
    fn align(&mut self, n: usize) {
        while !(self.0.len() - CDR_LE.len()).is_multiple_of(n) {
            self.0.push(0);
        }
    }

    fn u32(&mut self, v: u32) {
        self.align(4);
        self.0.extend_from_slice(&v.to_le_bytes());
    }

    fn count(&mut self, n: usize) {
        // Bounded by the callers (at most MAX_ELEMENTS, MAX_STRING + 1).
        self.u32(u32::try_from(n).unwrap_or(u32::MAX));
    }

    /// A string, cut to [`MAX_STRING`] bytes at a character boundary (a reader bounds its
    /// strings too).
    fn string(&mut self, s: &str) {
        let mut end = s.len().min(MAX_STRING);
        while !s.is_char_boundary(end) {
            end -= 1;
        }
        self.count(end + 1);
        self.0.extend_from_slice(&s.as_bytes()[..end]);
        self.0.push(0);
    }
}

/// Reads CDR after the encapsulation header, ignoring padding contents.
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
        let start = 4 + (self.pos - 4).next_multiple_of(align);
        let end = start.checked_add(n).filter(|&e| e <= self.buf.len());
        let Some(end) = end else {
            return Err(CdrError::Truncated {
                field,
                len: self.buf.len(),
            });
        };
        self.pos = end;
        Ok(&self.buf[start..end])
    }

    fn fixed4(&mut self, field: &'static str) -> Result<[u8; 4], CdrError> {
        let mut b = [0u8; 4];
        b.copy_from_slice(self.take(4, 4, field)?);
        if !self.little {
            b.reverse();
        }
        Ok(b)
    }

    fn u8(&mut self, field: &'static str) -> Result<u8, CdrError> {
        Ok(self.take(1, 1, field)?[0])
    }

    /// A count of elements of at least `min_bytes` each, checked against `max` and the
    /// bytes left before anything is allocated.
    fn count(
        &mut self,
        field: &'static str,
        max: usize,
        min_bytes: usize,
    ) -> Result<usize, CdrError> {
        let n = usize::try_from(u32::from_le_bytes(self.fixed4(field)?)).unwrap_or(usize::MAX);
        let fit = max.min((self.buf.len() - self.pos) / min_bytes.max(1));
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
        match self.take(n, 1, field)?.split_last() {
            Some((0, text)) => std::str::from_utf8(text)
                .map(str::to_owned)
                .map_err(|_| CdrError::BadString { field }),
            _ => Err(CdrError::BadString { field }),
        }
    }
}

impl DiagnosticArray {
    /// The payload: header and little-endian CDR. At most [`MAX_ELEMENTS`] statuses and
    /// values per status are written, each string at most [`MAX_STRING`] bytes.
    pub fn encode(&self) -> Vec<u8> {
        let mut w = Writer(CDR_LE.to_vec());
        w.u32(self.stamp.sec.cast_unsigned());
        w.u32(self.stamp.nanosec);
        w.string(&self.frame_id);
        let status = &self.status[..self.status.len().min(MAX_ELEMENTS)];
        w.count(status.len());
        for s in status {
            w.0.push(s.level);
            w.string(&s.name);
            w.string(&s.message);
            w.string(&s.hardware_id);
            let values = &s.values[..s.values.len().min(MAX_ELEMENTS)];
            w.count(values.len());
            for kv in values {
                w.string(&kv.key);
                w.string(&kv.value);
            }
        }
        w.0
    }

    /// Reads a payload (either byte order).
    ///
    /// # Errors
    ///
    /// [`CdrError`] naming the field that does not fit.
    pub fn decode(payload: &[u8]) -> Result<Self, CdrError> {
        let mut r = Reader::new(payload)?;
        let sec = u32::from_le_bytes(r.fixed4("header.stamp.sec")?).cast_signed();
        let nanosec = u32::from_le_bytes(r.fixed4("header.stamp.nanosec")?);
        let frame_id = r.string("header.frame_id")?;
        // A status takes at least 20 bytes: its level, three empty strings, no values.
        let n = r.count("status", MAX_ELEMENTS, 20)?;
        let mut status = Vec::with_capacity(n);
        for _ in 0..n {
            let level = r.u8("status.level")?;
            let name = r.string("status.name")?;
            let message = r.string("status.message")?;
            let hardware_id = r.string("status.hardware_id")?;
            // A key value takes at least 10 bytes: two empty strings.
            let m = r.count("status.values", MAX_ELEMENTS, 10)?;
            let mut values = Vec::with_capacity(m);
            for _ in 0..m {
                values.push(KeyValue {
                    key: r.string("status.values.key")?,
                    value: r.string("status.values.value")?,
                });
            }
            status.push(DiagnosticStatus {
                level,
                name,
                message,
                hardware_id,
                values,
            });
        }
        Ok(Self {
            stamp: Time { sec, nanosec },
            frame_id,
            status,
        })
    }
}

impl DiagnosticStatus {
    /// A library diagnosis, named `robobus: ROBOT NAME`.
    pub fn of(robot: &str, d: Diagnosis) -> Self {
        Self {
            level: d.level.byte(),
            name: format!("robobus: {robot} {}", d.name),
            message: d.message,
            hardware_id: d.hardware_id,
            values: d
                .values
                .into_iter()
                .map(|(key, value)| KeyValue { key, value })
                .collect(),
        }
    }
}

/// The robot's name in the statuses: the bridge's namespace, or `robot` on the root one.
pub(crate) fn robot_name(s: &Shared) -> &str {
    s.config.namespace.as_deref().unwrap_or("robot")
}

/// How old a reading may be before its joint is stale: [`STALE_AFTER`], or three periods
/// of a slower joint state rate.
pub(crate) fn stale_after(rate_hz: f64) -> Duration {
    STALE_AFTER.max(Duration::from_secs_f64(3.0 / rate_hz))
}

/// The diagnostics now (`unix_ms` the stamp): each joint's and bus's, from the joint state
/// thread's last readings, the host's protection stop and the safe stop that holds the
/// moved joints (until a command moves them again).
pub(crate) fn message(s: &Shared, now: Instant, unix_ms: f64) -> DiagnosticArray {
    let held = (!s.status.streaming.load(Ordering::SeqCst))
        .then(|| {
            s.status
                .last_safe
                .lock()
                .unwrap_or_else(PoisonError::into_inner)
                .as_ref()
                .map(|e| {
                    (
                        e.reason.clone(),
                        e.devices.iter().map(|d| (d.bus.clone(), d.id)).collect(),
                    )
                })
        })
        .flatten();
    let stops = Stops {
        protection: s
            .follower
            .as_ref()
            .and_then(robobus::station::follow::Follower::protection_stop),
        held,
    };
    let robot = robot_name(s);
    let status = s
        .states
        .diagnose(&s.station, now, stale_after(s.config.rate_hz), &stops)
        .into_iter()
        .map(|d| DiagnosticStatus::of(robot, d))
        .collect();
    DiagnosticArray {
        stamp: Time::from_unix_ms(unix_ms),
        frame_id: String::new(),
        status,
    }
}

/// Publishes the diagnostics every [`DIAGNOSTICS_PERIOD`] until the bridge stops.
pub(crate) fn publish(s: &Shared, publisher: &zenoh::pubsub::Publisher<'static>) {
    let mut next = Instant::now();
    while !s.stop.is_stopped() {
        let now = Instant::now();
        if now >= next {
            let unix_ms = std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(0.0, |d| d.as_secs_f64() * 1e3);
            if let Err(e) = publisher.put(message(s, now, unix_ms).encode()).wait() {
                tracing::warn!("diagnostics: {e}");
            }
            next += DIAGNOSTICS_PERIOD;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn hex(s: &str) -> Vec<u8> {
        (0..s.len())
            .step_by(2)
            .map(|i| u8::from_str_radix(&s[i..i + 2], 16).unwrap())
            .collect()
    }

    /// The golden vectors rosbags wrote (`tests/py/diagnostics_vectors.py`), by name.
    fn golden(name: &str) -> Vec<u8> {
        let file = include_str!("../tests/vectors/diagnostic_array.hex");
        let line = file
            .lines()
            .find_map(|l| l.strip_prefix(name)?.strip_prefix(' '))
            .unwrap();
        hex(line.trim())
    }

    fn kv(key: &str, value: &str) -> KeyValue {
        KeyValue {
            key: key.into(),
            value: value.into(),
        }
    }

    /// The messages of `diagnostics_vectors.py`.
    fn two() -> DiagnosticArray {
        DiagnosticArray {
            stamp: Time { sec: 1, nanosec: 2 },
            frame_id: String::new(),
            status: vec![
                DiagnosticStatus {
                    level: 0,
                    name: "robobus: bot1 joint j1".into(),
                    message: "OK".into(),
                    hardware_id: "whj arm 1".into(),
                    values: vec![kv("position_deg", "12.500"), kv("temperature_c", "35.0")],
                },
                DiagnosticStatus {
                    level: 2,
                    name: "robobus: bot1 bus arm".into(),
                    message: "1 of 3 joints in error: j3".into(),
                    hardware_id: "whj arm".into(),
                    values: vec![],
                },
            ],
        }
    }

    fn empty() -> DiagnosticArray {
        DiagnosticArray {
            stamp: Time {
                sec: 1_700_000_000,
                nanosec: 999_999_999,
            },
            frame_id: "base".into(),
            status: vec![],
        }
    }

    #[test]
    fn diagnostic_arrays_encode_to_the_bytes_rosbags_writes_and_back() {
        for (name, msg) in [("two", two()), ("empty", empty())] {
            let bytes = golden(name);
            assert_eq!(msg.encode(), bytes, "{name}");
            assert_eq!(DiagnosticArray::decode(&bytes).unwrap(), msg, "{name}");
        }
    }

    #[test]
    fn padding_contents_and_trailing_bytes_are_ignored_and_big_endian_is_read() {
        let mut bytes = golden("two");
        // The padding (body offsets): after frame_id's NUL, after the first level, after
        // "robobus: bot1 joint j1"'s NUL.
        for i in [13, 14, 15, 21, 22, 23, 51] {
            assert_eq!(bytes[4 + i], 0, "{i}");
            bytes[4 + i] = 0xA5;
        }
        bytes.extend_from_slice(&[1, 2, 3]);
        assert_eq!(DiagnosticArray::decode(&bytes).unwrap(), two());
        let mut be = vec![0, 0, 0, 0];
        be.extend_from_slice(&0x6553_f100_u32.to_be_bytes());
        be.extend_from_slice(&999_999_999_u32.to_be_bytes());
        be.extend_from_slice(&5u32.to_be_bytes());
        be.extend_from_slice(b"base\0\0\0\0");
        be.extend_from_slice(&0u32.to_be_bytes());
        assert_eq!(DiagnosticArray::decode(&be).unwrap(), empty());
    }

    #[test]
    fn a_truncated_or_oversized_payload_is_an_error_naming_its_field_never_a_panic() {
        let bytes = golden("two");
        for n in 0..bytes.len() {
            assert!(DiagnosticArray::decode(&bytes[..n]).is_err(), "{n} bytes");
        }
        // A status count no payload of this size can hold: refused before allocating.
        let mut huge = golden("empty");
        let at = huge.len() - 4;
        huge[at..].copy_from_slice(&u32::MAX.to_le_bytes());
        assert_eq!(
            DiagnosticArray::decode(&huge).unwrap_err(),
            CdrError::TooLong {
                field: "status",
                count: u32::MAX as usize,
                max: 0
            }
        );
        assert_eq!(
            DiagnosticArray::decode(&[0, 1]).unwrap_err(),
            CdrError::NoHeader(2)
        );
    }

    fn shared() -> std::sync::Arc<Shared> {
        let config = crate::BridgeConfig {
            namespace: Some("bot1".into()),
            ..crate::BridgeConfig::default()
        };
        let keys = crate::Keys::new(Some("bot1")).unwrap();
        Shared::new(
            robobus::station::Station::simulated().unwrap(),
            None,
            config,
            keys,
        )
        .unwrap()
    }

    fn status<'a>(msg: &'a DiagnosticArray, name: &str) -> &'a DiagnosticStatus {
        msg.status
            .iter()
            .find(|s| s.name == format!("robobus: bot1 {name}"))
            .unwrap_or_else(|| panic!("{name} in {msg:?}"))
    }

    fn value<'a>(s: &'a DiagnosticStatus, key: &str) -> Option<&'a str> {
        s.values
            .iter()
            .find(|kv| kv.key == key)
            .map(|kv| kv.value.as_str())
    }

    #[test]
    fn the_samples_of_the_joint_states_are_diagnosed_silent_joints_error_and_old_ones_stale() {
        let s = shared();
        let t0 = Instant::now();
        // Before any sample: nothing is known.
        let msg = message(&s, t0, 0.0);
        let joints = s.follower.as_ref().unwrap().joints().len();
        assert_eq!(msg.status.len(), joints + 2);
        assert!(msg.status.iter().all(|st| st.level == 3), "{msg:?}");
        // One real sample of the simulated robot: every joint and bus OK, in CDR too.
        let request =
            robobus::catalogue::Request::RobotSample(robobus::catalogue::robot::Sample {});
        let stop = robobus::ops::StopToken::new();
        let report =
            robobus::catalogue::run(&s.station, &request, &mut robobus::ops::Control::new(&stop))
                .unwrap();
        s.states.record(&s.station, Some(&report), t0);
        let msg = DiagnosticArray::decode(&message(&s, t0, 1500.0).encode()).unwrap();
        assert_eq!(
            msg.stamp,
            Time {
                sec: 1,
                nanosec: 500_000_000
            }
        );
        for st in &msg.status {
            assert_eq!(st.level, 0, "{st:?}");
        }
        let j3 = status(&msg, "joint j3");
        assert_eq!(j3.hardware_id, "whj sim-whj 3");
        assert_eq!(j3.message, "OK");
        assert!(value(j3, "temperature_c").is_some(), "{j3:?}");
        assert!(value(j3, "voltage_v").is_some(), "{j3:?}");
        assert_eq!(value(j3, "error_bits"), Some("no error"));
        let bus = status(&msg, "bus sim-whj");
        assert_eq!(bus.message, "OK, 7 of 7 joints answering");
        // j3 falls silent: an error naming why, and its bus warns.
        let mut rows = report.clone();
        for row in &mut rows.results {
            if row["id"] == "j3" {
                *row = serde_json::json!({
                    "id": "j3", "kind": "no-device",
                    "error": "joint 3: no reply within 2.0 ms"
                });
            }
        }
        let t1 = t0 + Duration::from_millis(20);
        s.states.record(&s.station, Some(&rows), t1);
        let msg = message(&s, t1, 0.0);
        let j3 = status(&msg, "joint j3");
        assert_eq!(
            (j3.level, j3.message.as_str()),
            (2, "silent: joint 3: no reply within 2.0 ms")
        );
        assert_eq!(value(j3, "temperature_c"), None);
        let bus = status(&msg, "bus sim-whj");
        assert_eq!(
            (bus.level, bus.message.as_str()),
            (1, "1 of 7 joints in error: j3")
        );
        assert_eq!(status(&msg, "joint j4").level, 0);
        // Not read since: stale, the joints and their buses.
        let late = t1 + stale_after(s.config.rate_hz) + Duration::from_millis(1);
        let msg = message(&s, late, 0.0);
        assert!(msg.status.iter().all(|st| st.level == 3), "{msg:?}");
    }

    #[test]
    fn a_slow_joint_state_rate_keeps_its_joints_news_for_three_periods() {
        assert_eq!(stale_after(50.0), STALE_AFTER);
        assert_eq!(stale_after(0.5), Duration::from_secs(6));
    }

    #[test]
    fn a_string_longer_than_a_reader_takes_is_cut_at_a_character_boundary() {
        let mut msg = empty();
        msg.status.push(DiagnosticStatus {
            message: "é".repeat(MAX_STRING),
            ..DiagnosticStatus::default()
        });
        let back = DiagnosticArray::decode(&msg.encode()).unwrap();
        assert_eq!(back.status[0].message, "é".repeat(MAX_STRING / 2));
    }
}
