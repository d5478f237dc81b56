//! `NS/diagnostics`: `diagnostic_msgs/msg/DiagnosticArray` in CDR about once a second, one
//! status per joint and per bus of the station's robot file, from the library's
//! diagnostics ([`robobus::station::diagnostics`]) of the joint state thread's own samples:
//! no frame of its own.
//!
//! The message and its CDR are [`robobus::cdr`]'s ([`DiagnosticArray`]); golden vectors
//! written by rosbags check it (`tests/vectors/diagnostic_array.hex`, made by
//! `tests/py/diagnostics_vectors.py`).

use std::sync::PoisonError;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use robobus::cdr::Time;
pub use robobus::cdr::{DiagnosticArray, DiagnosticStatus, KeyValue};
use robobus::station::diagnostics::{Diagnosis, STALE_AFTER, Stops};
use zenoh::Wait as _;

use crate::Shared;

/// How often the diagnostics are published.
pub const DIAGNOSTICS_PERIOD: Duration = Duration::from_secs(1);

/// A library diagnosis as a status, named `robobus: ROBOT NAME`.
pub fn status_of(robot: &str, d: Diagnosis) -> DiagnosticStatus {
    DiagnosticStatus {
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
        .map(|d| status_of(robot, d))
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
    use robobus::cdr::{CdrError, MAX_STRING};

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
