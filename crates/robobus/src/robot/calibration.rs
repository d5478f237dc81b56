//! Calibration of a robot file by hand: the joints are read while the user moves each
//! through its range (wCK servos passive, torque off), the range each went through is
//! recorded, and the pose at the end can become the joints' zero. The result is the
//! file's `offset` and `limits` of each joint, written into the file's text with
//! everything else kept as it was (comments, order, other fields): [`apply_to_toml`].
//!
//! Angles in the file are joint angles: `direction × (device angle − offset)`. The
//! readings are joint angles of the file as it is; a zero at joint angle `q0` makes the
//! new offset `offset + direction × q0`, and each recorded angle `q` becomes `q − q0`.

use serde::{Deserialize, Serialize};
use toml_edit::{DocumentMut, Item, value};

use super::{RobotConfig, RobotError};

/// Largest margin inside the recorded range, degrees.
pub const MAX_MARGIN_DEG: f64 = 30.0;

/// The range one joint went through, as it is being recorded.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Range {
    /// Readings taken.
    pub samples: u64,
    /// Readings that failed.
    pub failed: u64,
    /// Smallest and largest joint angle read, degrees.
    pub min_deg: Option<f64>,
    /// Largest.
    pub max_deg: Option<f64>,
    /// The last angle read (the pose at the end), degrees.
    pub last_deg: Option<f64>,
    /// The last failure, if any.
    pub last_error: Option<String>,
}

impl Range {
    /// Takes one reading (a finite joint angle, degrees).
    pub fn take(&mut self, deg: f64) {
        if !deg.is_finite() {
            self.fail("the joint angle read is not a number".into());
            return;
        }
        self.samples += 1;
        self.min_deg = Some(self.min_deg.map_or(deg, |m| m.min(deg)));
        self.max_deg = Some(self.max_deg.map_or(deg, |m| m.max(deg)));
        self.last_deg = Some(deg);
    }

    /// A reading failed with `error`.
    pub fn fail(&mut self, error: String) {
        self.failed += 1;
        self.last_error = Some(error);
    }
}

/// One joint's calibration: what was recorded and what the file gets.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct JointCalibration {
    /// Readings taken.
    pub samples: u64,
    /// Readings that failed.
    pub failed: u64,
    /// The range recorded, in the file's joint angles before the change, degrees.
    pub min_deg: f64,
    /// Largest.
    pub max_deg: f64,
    /// The joint angle taken as the new zero (0 when the offsets are kept), degrees.
    pub zero_deg: f64,
    /// The file's `offset` before, rad.
    pub offset_before_rad: f64,
    /// The new `offset`, rad.
    pub offset_rad: f64,
    /// The file's `limits` before, rad.
    pub limits_before_rad: [f64; 2],
    /// The new `limits`: the recorded range in the new joint angles, `margin_deg` inside
    /// it at each end, rad.
    pub limits_rad: [f64; 2],
}

/// Turns the ranges recorded for the joints of `config` (by name) into the file's new
/// offsets and limits. With `zero_at_end`, the pose at the end becomes each joint's zero.
/// A joint with no reading, or whose range is not wider than twice the margin, is an
/// error for that joint (its file entry is then left alone).
pub fn finish(
    config: &RobotConfig,
    name: &str,
    range: &Range,
    zero_at_end: bool,
    margin_deg: f64,
) -> Result<JointCalibration, String> {
    let joint = config
        .joints
        .iter()
        .find(|j| j.name == name)
        .ok_or_else(|| format!("joint {name}: not in the robot file"))?;
    let (Some(min), Some(max), Some(last)) = (range.min_deg, range.max_deg, range.last_deg) else {
        return Err(format!(
            "joint {name}: no reading in {} attempt(s){}",
            range.failed,
            range
                .last_error
                .as_deref()
                .map(|e| format!(" (last: {e})"))
                .unwrap_or_default()
        ));
    };
    let zero = if zero_at_end { last } else { 0.0 };
    let lo = min - zero + margin_deg;
    let hi = max - zero - margin_deg;
    if hi <= lo {
        return Err(format!(
            "joint {name}: moved through {:.1}° only ({min:.1}° to {max:.1}°); move it through \
             its whole range, more than twice the {margin_deg}° margin",
            max - min
        ));
    }
    let direction = f64::from(joint.direction);
    Ok(JointCalibration {
        samples: range.samples,
        failed: range.failed,
        min_deg: min,
        max_deg: max,
        zero_deg: zero,
        offset_before_rad: joint.offset,
        offset_rad: round(joint.offset + direction * zero.to_radians()),
        limits_before_rad: joint.limits,
        limits_rad: [round(lo.to_radians()), round(hi.to_radians())],
    })
}

/// Rounded to a microradian (0.00006°), so the file shows short numbers.
fn round(rad: f64) -> f64 {
    (rad * 1e6).round() / 1e6
}

/// The robot file's text with each calibrated joint's `offset` and `limits` replaced
/// (joints matched by `name`); comments, order and every other field are kept. The
/// result is checked as a robot file.
///
/// Errors: the text is not a robot file, or a calibrated joint is not in it, or the
/// result does not check (a limit outside the device's range).
pub fn apply_to_toml(
    text: &str,
    joints: &[(String, JointCalibration)],
) -> Result<String, RobotError> {
    // The text must be a robot file to begin with (and bounded in size).
    RobotConfig::from_toml_str(text)?;
    let mut doc: DocumentMut =
        text.parse()
            .map_err(|e: toml_edit::TomlError| RobotError::Parse {
                line: 0,
                column: 0,
                message: e.to_string(),
            })?;
    let tables = doc
        .get_mut("joints")
        .and_then(Item::as_array_of_tables_mut)
        .ok_or_else(|| RobotError::Invalid {
            item: "robot file".into(),
            field: "joints",
            value: "(missing)".into(),
            expected: "[[joints]] tables".into(),
        })?;
    for (name, cal) in joints {
        let table = tables
            .iter_mut()
            .find(|t| t.get("name").and_then(Item::as_str) == Some(name.as_str()))
            .ok_or_else(|| RobotError::Invalid {
                item: format!("joint {name}"),
                field: "name",
                value: name.clone(),
                expected: "a joint of the robot file".into(),
            })?;
        set_keeping_decor(table, "offset", value(cal.offset_rad));
        let mut limits = toml_edit::Array::new();
        limits.push(cal.limits_rad[0]);
        limits.push(cal.limits_rad[1]);
        set_keeping_decor(table, "limits", value(limits));
    }
    let out = doc.to_string();
    RobotConfig::from_toml_str(&out)?;
    Ok(out)
}

/// Sets `key` to `new`, keeping the comment after the old value (`offset = 0.05  # ...`).
fn set_keeping_decor(table: &mut toml_edit::Table, key: &str, mut new: Item) {
    if let (Some(Item::Value(old)), Item::Value(v)) = (table.get(key), &mut new) {
        let decor = old.decor().clone();
        *v.decor_mut() = decor;
    } else if let Item::Value(v) = &mut new {
        v.decor_mut().set_prefix(" ");
    }
    table.insert(key, new);
}

#[cfg(test)]
mod tests {
    // Exact: the file must carry these very numbers.
    #![allow(clippy::float_cmp)]

    use super::*;

    const FILE: &str = "# my robot\n\
        watchdog_timeout = 0.1\n\
        \n\
        [buses.legs]\n\
        kind = \"wck\"\n\
        port = \"/dev/ttyUSB0\"\n\
        \n\
        [[joints]]\n\
        name = \"hip\"   # the left hip\n\
        bus = \"legs\"\n\
        id = 0\n\
        limits = [-0.8, 0.8]  # keep inside the frame\n\
        max_velocity = 3.0\n\
        max_acceleration = 30.0\n\
        \n\
        [[joints]]\n\
        name = \"knee\"\n\
        bus = \"legs\"\n\
        id = 1\n\
        direction = -1\n\
        offset = 0.05              # servo angle at joint zero\n\
        limits = [-0.2, 1.2]\n\
        max_velocity = 3.0\n\
        max_acceleration = 30.0\n";

    fn range(values: &[f64]) -> Range {
        let mut r = Range::default();
        for v in values {
            r.take(*v);
        }
        r
    }

    #[test]
    fn the_zero_at_the_end_moves_the_offset_and_the_limits_with_it() {
        let config = RobotConfig::from_toml_str(FILE).unwrap();
        // The knee (direction -1) went from -10° to 60° and ended at 20°.
        let knee = finish(
            &config,
            "knee",
            &range(&[5.0, -10.0, 60.0, 20.0]),
            true,
            2.0,
        )
        .unwrap();
        assert_eq!(
            (knee.min_deg, knee.max_deg, knee.zero_deg),
            (-10.0, 60.0, 20.0)
        );
        assert_eq!(knee.offset_rad, round(0.05 - 20f64.to_radians()));
        assert_eq!(
            knee.limits_rad,
            [round((-28f64).to_radians()), round(38f64.to_radians())]
        );
        // Keeping the offsets: the limits are the recorded range, the margin inside.
        let hip = finish(&config, "hip", &range(&[-30.0, 30.0]), false, 5.0).unwrap();
        assert_eq!(hip.offset_rad, 0.0);
        assert_eq!(
            hip.limits_rad,
            [round((-25f64).to_radians()), round(25f64.to_radians())]
        );
        // Too small a range, no reading, an unknown joint: errors naming the joint.
        let e = finish(&config, "hip", &range(&[1.0, 3.0]), false, 2.0).unwrap_err();
        assert!(e.contains("hip") && e.contains("2.0°"), "{e}");
        let mut silent = Range::default();
        silent.fail("servo 0 did not answer".into());
        let e = finish(&config, "hip", &silent, true, 2.0).unwrap_err();
        assert!(
            e.contains("no reading in 1 attempt") && e.contains("did not answer"),
            "{e}"
        );
        assert!(finish(&config, "elbow", &range(&[0.0]), true, 2.0).is_err());
    }

    #[test]
    fn the_file_keeps_its_comments_and_order_and_reads_back_as_calibrated() {
        let config = RobotConfig::from_toml_str(FILE).unwrap();
        let knee = finish(&config, "knee", &range(&[-10.0, 60.0, 20.0]), true, 2.0).unwrap();
        let hip = finish(&config, "hip", &range(&[-30.0, 30.0, 0.0]), true, 5.0).unwrap();
        let out = apply_to_toml(
            FILE,
            &[("knee".into(), knee.clone()), ("hip".into(), hip.clone())],
        )
        .unwrap();
        for kept in [
            "# my robot",
            "name = \"hip\"   # the left hip",
            "# keep inside the frame",
            "# servo angle at joint zero",
            "direction = -1",
        ] {
            assert!(out.contains(kept), "{kept:?} lost in:\n{out}");
        }
        assert!(
            out.find("name = \"hip\"") < out.find("name = \"knee\""),
            "{out}"
        );
        let back = RobotConfig::from_toml_str(&out).unwrap();
        let j = |n: &str| back.joints.iter().find(|j| j.name == n).unwrap().clone();
        assert_eq!(
            (j("knee").offset, j("knee").limits),
            (knee.offset_rad, knee.limits_rad)
        );
        assert_eq!(
            (j("hip").offset, j("hip").limits),
            (hip.offset_rad, hip.limits_rad)
        );
        assert_eq!(j("knee").direction, -1);
        // A joint the file does not have: an error naming it, nothing written.
        let e = apply_to_toml(FILE, &[("elbow".into(), hip)]).unwrap_err();
        assert!(e.to_string().contains("elbow"), "{e}");
        // Not a robot file: the parser's error.
        assert!(apply_to_toml("joints = 3", &[]).is_err());
    }
}
