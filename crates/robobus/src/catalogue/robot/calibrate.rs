//! `robot.calibrate`: calibration by hand, the range each joint of the station's robot
//! file is moved through read into its new `offset` and `limits`.

use std::time::{Duration, Instant};

use robobus_wck::BaudRate;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::{END_NOTE, ROBOT, make_passive, no_robot, settle, within};
use crate::catalogue::effect::{Effect, Moved};
use crate::catalogue::operation::{Confirm, OpDoc, Operation, Report, RunCx};
use crate::catalogue::plan::{Family, Plan};
use crate::ops::{Control, DeviceResult, ErrorKind, Failure, OpError, Outcome, Progress};
use crate::robot::calibration::{self, JointCalibration, MAX_MARGIN_DEG, Range};
use crate::station::Station;

/// Which pose becomes the joints' zero in a calibration.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum ZeroPose {
    /// The pose the joints are in when the reading ends.
    #[default]
    End,
    /// The file's offsets stay; only the limits change.
    Keep,
}

/// `robot.calibrate`: calibration by hand. The station's robot file's wCK servos are made
/// passive (torque off; `passive: false` leaves them as they are) and every joint is read
/// `seconds × rate_hz` times while the user moves each through its whole range; WHJ
/// joints are read as they are (a disabled WHJ joint holds its brake: move it in a mode
/// that lets it turn). Each joint's row has the range it went through and the file's new
/// `offset` (with `zero: "end"`, the pose at the end becomes the zero) and `limits` (the
/// recorded range, `margin_deg` inside at each end), in the same joint frame; the file is
/// not written (`robobus robot calibrate --write` writes it, keeping its comments). A
/// joint that never answered, or moved through less than twice the margin, is a failed
/// row. Stops early at the stop token, with what was read so far. Every bus of the file
/// is then left in its `safe_state` (`settle`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Calibrate {
    /// How long the joints are read, seconds (0.1..=600).
    pub seconds: f64,
    /// Readings a second (1..=100; default 20).
    #[serde(default = "default_rate")]
    pub rate_hz: f64,
    /// `end` (default): the pose at the end becomes each joint's zero; `keep`: the file's
    /// offsets stay.
    #[serde(default)]
    pub zero: ZeroPose,
    /// How far inside the recorded range the soft limits stay, degrees (0..=30; default 2).
    #[serde(default = "default_margin")]
    pub margin_deg: f64,
    /// Make the wCK servos passive first (default true).
    #[serde(default = "super::yes")]
    pub passive: bool,
}

const fn default_rate() -> f64 {
    20.0
}

const fn default_margin() -> f64 {
    2.0
}

/// Range of `seconds`.
pub const CALIBRATE_SECONDS: std::ops::RangeInclusive<f64> = 0.1..=600.0;
/// Range of `rate_hz`.
pub const CALIBRATE_RATE_HZ: std::ops::RangeInclusive<f64> = 1.0..=100.0;

impl Calibrate {
    /// Checks the ranges; returns the number of readings.
    pub fn readings(&self) -> Result<u64, OpError> {
        // Named as the command line's options (the request's fields are the same words).
        within("--seconds", self.seconds, &CALIBRATE_SECONDS)?;
        within("--rate-hz", self.rate_hz, &CALIBRATE_RATE_HZ)?;
        within("--margin-deg", self.margin_deg, &(0.0..=MAX_MARGIN_DEG))?;
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)] // 1..=60000
        Ok(((self.seconds * self.rate_hz).round() as u64).max(1))
    }

    /// What a run sends, for the plan.
    pub fn note(&self) -> Result<String, OpError> {
        let n = self.readings()?;
        Ok(format!(
            "{}reads every joint of the station's robot file {n} times at {} Hz while you move \
             each through its range by hand (a status read per wCK servo, a status query and a \
             speed read per WHJ joint); {}; the file is not written",
            if self.passive {
                "makes every wCK servo of the robot file passive (FF <0xC0|ID> 00 <checksum>, \
                 torque off), then "
            } else {
                ""
            },
            self.rate_hz,
            match self.zero {
                ZeroPose::End => "the pose at the end becomes each joint's zero",
                ZeroPose::Keep => "the offsets stay",
            },
        ) + END_NOTE)
    }
}

/// What a `robot.calibrate` run did.
struct Calibrated {
    /// Each joint's result, by name.
    joints: Vec<DeviceResult<String, JointCalibration>>,
    /// Readings taken.
    taken: u64,
    /// Readings asked for (fewer taken: the stop token ended the reading).
    asked: u64,
}

/// `robot.calibrate` on the station's robot file.
fn run_calibrate(
    station: &Station,
    r: &Calibrate,
    control: &mut Control<'_>,
) -> Result<Calibrated, OpError> {
    let readings = r.readings()?;
    let config = station.robot().cloned().ok_or_else(no_robot)?;
    if r.passive {
        make_passive(station, &config)?;
    }
    let mut ranges: Vec<(String, Range)> = config
        .joints
        .iter()
        .map(|j| (j.name.clone(), Range::default()))
        .collect();
    let read = read_ranges(station, &mut ranges, readings, r.rate_hz, control);
    // Finished, stopped or failed: each bus as the robot file says.
    let names: Vec<String> = config.joints.iter().map(|j| j.name.clone()).collect();
    let settled = settle(station, &config, &names);
    let taken = read.inspect_err(|_| settled.log())?;
    let results = ranges
        .iter()
        .map(|(name, range)| {
            match calibration::finish(&config, name, range, r.zero == ZeroPose::End, r.margin_deg) {
                Ok(c) => DeviceResult::ok(name.clone(), c),
                Err(e) => {
                    let kind = if range.samples == 0 {
                        ErrorKind::NoDevice
                    } else {
                        ErrorKind::Device
                    };
                    DeviceResult::failed(name.clone(), Failure::of(kind, &e))
                }
            }
        })
        .collect();
    Ok(Calibrated {
        joints: settled.fail_rows(results),
        taken,
        asked: readings,
    })
}

/// Reads every joint `readings` times at `rate_hz` into its range; the readings taken
/// (fewer: the stop token ended the reading).
fn read_ranges(
    station: &Station,
    ranges: &mut [(String, Range)],
    readings: u64,
    rate_hz: f64,
    control: &mut Control<'_>,
) -> Result<u64, OpError> {
    let period = Duration::from_secs_f64(1.0 / rate_hz);
    let start = Instant::now();
    let mut taken = 0;
    for k in 0..readings {
        if k > 0 && !control.sleep_until(start + period * u32::try_from(k).unwrap_or(u32::MAX)) {
            break;
        }
        let rows = station.sample_robot().ok_or_else(no_robot)??;
        for row in rows {
            if let Some((_, range)) = ranges.iter_mut().find(|(n, _)| *n == row.id) {
                match row.outcome {
                    Outcome::Ok(s) => range.take(s.position_deg),
                    Outcome::Failed(f) => range.fail(f.error),
                }
            }
        }
        taken += 1;
        control.report(&Progress::new("calibrate", taken, Some(readings)));
    }
    Ok(taken)
}

/// The summary of `robot.calibrate`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, JsonSchema)]
pub struct CalibrateSummary {
    /// Readings taken.
    pub readings: u64,
    /// The stop token ended the reading early (the rows hold what was read).
    pub interrupted: bool,
}

impl Operation for Calibrate {
    const OP: &'static str = "robot.calibrate";
    const FAMILY: Family = Family::Robot;
    const DOC: OpDoc = OpDoc {
        args: "`seconds` (0.1..=600), `rate_hz`=20 (1..=100), `zero` (`end`: the pose at the \
               end becomes the zero; `keep`), `margin_deg`=2 (0..=30), `passive`=true (wCK \
               servos torque off first)",
        report: "one row per joint by name: `samples`, `failed`, `min_deg` / `max_deg` (the \
                 range it was moved through), `zero_deg`, `offset_rad` and `limits_rad` for the \
                 robot file (and `offset_before_rad`, `limits_before_rad`); `summary`: \
                 `readings`, `interrupted` (stopped early, with what was read). The file is not \
                 written: `robobus robot calibrate --write` writes it, keeping its comments",
        confirm: "-",
    };
    type Row = DeviceResult<String, JointCalibration>;
    type Summary = CalibrateSummary;

    /// wCK servos made passive while the joints are moved by hand.
    fn effect(&self) -> Effect {
        Effect::Configure
    }

    fn moved(&self) -> Result<Option<Moved>, OpError> {
        self.readings().map(|_| None)
    }

    fn check(&self) -> Result<Confirm, OpError> {
        self.readings().map(|_| Confirm::NONE)
    }

    fn plan(&self, _baud: BaudRate) -> Result<Plan, OpError> {
        Ok(Plan::notes_only(
            Self::OP,
            Family::Robot,
            vec![self.note()?],
        ))
    }

    fn run(&self, cx: &mut RunCx<'_, '_>) -> Result<Report<Self::Row, CalibrateSummary>, OpError> {
        let c = run_calibrate(cx.station, self, cx.control)?;
        let summary = CalibrateSummary {
            readings: c.taken,
            interrupted: c.taken < c.asked,
        };
        Ok(Report::devices_with(Self::OP, ROBOT, c.joints).summary(summary))
    }
}

#[cfg(all(test, feature = "sim"))]
mod tests {
    // Exact comparisons: the file must carry these very numbers.
    #![allow(clippy::unwrap_used, clippy::float_cmp)]

    use std::time::Duration;

    use serde_json::{Value, json};

    use crate::catalogue::robot::row;
    use crate::catalogue::{Request, run, validate};
    use crate::ops::Control;
    use crate::robot::calibration::apply_to_toml;
    use crate::station::Station;

    /// Servo `id`'s shaft turned by hand to `deg` joint degrees (from step 127) at
    /// simulated time `after` from now.
    fn turn(sim: &robobus_sim::wck::SimHandle, after: Duration, id: usize, deg: f64) {
        let at = sim.now() + after;
        sim.at(at, move |bus| {
            let centre = 127.0 * robobus_sim::wck::mechanics::DEG_PER_STEP8;
            bus.servo_mut(id).unwrap().set_angle(centre + deg);
        });
    }

    #[test]
    fn the_range_moved_through_by_hand_becomes_the_files_limits_and_the_end_its_zero() {
        let (station, wck, _) = Station::simulated_with_handles().unwrap();
        // Servo 0 is turned to -40°, then +50°, and left at +10°; servo 1 to -20°, +30°,
        // then back to 0, half-way between readings 2 and 3, 5 and 6, 8 and 9. The others
        // stay where they are. The simulated clock moves only while the bus waits: one
        // reading is a status read of each servo, each transaction followed by the quiet
        // time after its reply.
        let baud = robobus_wck::BaudRate::B115200;
        let status = robobus_wck::Command::StatusRead {
            id: robobus_wck::ServoId::new(0).unwrap(),
        };
        let reading = (robobus_wck::timing::transaction_time(&status, baud)
            + crate::wck::reply_guard(baud))
            * u32::from(crate::robot::simulated::SERVOS);
        for (k, d0, d1) in [(2.5, -40.0, -20.0), (5.5, 50.0, 30.0), (8.5, 10.0, 0.0)] {
            turn(&wck, reading.mul_f64(k), 0, d0);
            turn(&wck, reading.mul_f64(k), 1, d1);
        }
        let request: Request =
            serde_json::from_value(json!({"op": "robot.calibrate", "seconds": 0.5})).unwrap();
        let report = run(&station, &request, &mut Control::none()).unwrap();
        let v = serde_json::to_value(&report).unwrap();
        assert_eq!(v["summary"]["readings"], 10, "{v:#}");
        assert_eq!(v["summary"]["interrupted"], false, "{v:#}");
        // Within a step (1.05°) of what the shafts were turned to.
        let near = |x: &Value, want: f64| (x.as_f64().unwrap() - want).abs() <= 1.06;
        let s0 = row(&v, "s0");
        assert!(
            near(&s0["min_deg"], -40.0) && near(&s0["max_deg"], 50.0),
            "{s0}"
        );
        assert!(near(&s0["zero_deg"], 10.0), "{s0}");
        // The new zero is the end pose; the limits are the range from it, 2° inside.
        let zero = s0["zero_deg"].as_f64().unwrap();
        let lim = |i: usize| s0["limits_rad"][i].as_f64().unwrap().to_degrees();
        assert!(
            (lim(0) - (s0["min_deg"].as_f64().unwrap() - zero + 2.0)).abs() < 1e-3,
            "{s0}"
        );
        assert!(
            (lim(1) - (s0["max_deg"].as_f64().unwrap() - zero - 2.0)).abs() < 1e-3,
            "{s0}"
        );
        assert!((s0["offset_rad"].as_f64().unwrap() - zero.to_radians()).abs() < 1e-6);
        let s1 = row(&v, "s1");
        assert!(
            near(&s1["min_deg"], -20.0) && near(&s1["max_deg"], 30.0),
            "{s1}"
        );
        // A joint left alone cannot be calibrated: its row says so, the report fails.
        let s5 = row(&v, "s5");
        assert_eq!(s5["kind"], "device", "{s5}");
        assert!(
            s5["error"]
                .as_str()
                .unwrap()
                .contains("s5: moved through 0.0°"),
            "{s5}"
        );
        assert_eq!(v["failed"], "device");
        // What was calibrated goes into the file, which then reads back.
        let done: Vec<(String, crate::robot::calibration::JointCalibration)> = ["s0", "s1"]
            .iter()
            .map(|n| {
                let r = row(&v, n);
                let c = crate::robot::calibration::JointCalibration {
                    samples: r["samples"].as_u64().unwrap(),
                    failed: r["failed"].as_u64().unwrap(),
                    min_deg: r["min_deg"].as_f64().unwrap(),
                    max_deg: r["max_deg"].as_f64().unwrap(),
                    zero_deg: r["zero_deg"].as_f64().unwrap(),
                    offset_before_rad: 0.0,
                    offset_rad: r["offset_rad"].as_f64().unwrap(),
                    limits_before_rad: [-2.0, 2.0],
                    limits_rad: [
                        r["limits_rad"][0].as_f64().unwrap(),
                        r["limits_rad"][1].as_f64().unwrap(),
                    ],
                };
                ((*n).to_owned(), c)
            })
            .collect();
        let text = apply_to_toml(&crate::robot::simulated::simulated_robot(), &done).unwrap();
        let back = crate::robot::RobotConfig::from_toml_str(&text).unwrap();
        assert_eq!(back.joints[0].limits, done[0].1.limits_rad);
        assert_eq!(back.joints[1].offset, done[1].1.offset_rad);
    }

    #[test]
    fn keeping_the_offsets_and_bad_values() {
        let (station, wck, _) = Station::simulated_with_handles().unwrap();
        turn(&wck, Duration::from_millis(50), 3, -30.0);
        turn(&wck, Duration::from_millis(200), 3, 30.0);
        let request: Request = serde_json::from_value(
            json!({"op": "robot.calibrate", "seconds": 0.3, "zero": "keep", "margin_deg": 5}),
        )
        .unwrap();
        let v =
            serde_json::to_value(run(&station, &request, &mut Control::none()).unwrap()).unwrap();
        let s3 = row(&v, "s3");
        assert_eq!(s3["zero_deg"], 0.0, "{s3}");
        assert_eq!(s3["offset_rad"], 0.0, "{s3}");
        // Bad values are refused before anything is sent, naming the field and range.
        for (field, option, value, range) in [
            ("seconds", "--seconds", 0.0, "0.1..=600"),
            ("rate_hz", "--rate-hz", 500.0, "1..=100"),
            ("margin_deg", "--margin-deg", -1.0, "0..=30"),
        ] {
            let mut req = json!({"op": "robot.calibrate", "seconds": 1.0});
            req[field] = json!(value);
            let request: Request = serde_json::from_value(req).unwrap();
            let e = validate(&request).unwrap_err().to_string();
            assert!(e.contains(option) && e.contains(range), "{e}");
        }
    }
}
