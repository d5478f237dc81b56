//! Keyframe motion files for `robobus wck play` (and what `robobus wck teach` writes).
//!
//! The format is [`FORMAT_HELP`]: one directive per line, `#` comments.
//!
//! ```text
//! # wave the arm: servos 0, 1, 2
//! torque 0
//! pose 1000 127 127 127     # reach this pose (allow 1 s)
//! pose 500  100 150 127     # then move to this one in 500 ms
//! hold 200                  # keep it for 200 ms
//! pose 500  127 127 127
//! ```
//!
//! Playing interpolates linearly between consecutive poses and sends one synchronized
//! move (A-1 (2)) per period of `--rate-hz`; the last move of a transition is the pose
//! itself, exactly.

use std::fmt;
use std::fmt::Write as _;

use robobus_wck::{Command, Position, ServoId, SyncMove, TorqueLevel};

use crate::output::{WckPlan, WckStep};

/// `--help` text describing the file format.
pub(crate) const FORMAT_HELP: &str = "\
Keyframe motion file (text, one directive per line, `#` starts a comment):
  torque <0..=4>            torque level of every move (optional, before the first pose;
                            default 0 = maximum)
  pose <ms> <p0> <p1> ...   positions (0..=254) of servos 0, 1, 2, ...; every pose lists
                            the same number of servos (1..=31). <ms> (0..=600000) is the
                            transition time from the previous pose; the first pose is sent
                            at once and <ms> is the time allowed to reach it
  hold <ms>                 keep the current pose for <ms> (0..=600000)
Between poses the positions are interpolated linearly and sent as synchronized moves,
--rate-hz per second; the last move of each transition is the pose itself.

Example:
  torque 0
  pose 1000 127 127 127
  pose 500  100 150 127
  hold 200
  pose 500  127 127 127";

/// Longest transition or hold, ms (10 minutes).
const MAX_MS: u32 = 600_000;

/// One keyframe: positions of servos `0..n` and the time to get there.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct Pose {
    /// Transition time from the previous pose, ms.
    pub(crate) ms: u32,
    /// Positions of servos 0, 1, ...
    pub(crate) positions: Vec<Position>,
}

/// An entry of a motion.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) enum Frame {
    /// Move to a pose.
    Pose(Pose),
    /// Keep the current pose.
    Hold(u32),
}

/// A parsed keyframe motion file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct Motion {
    /// Torque level of every move.
    pub(crate) torque: TorqueLevel,
    /// The entries in order; the first is a pose.
    pub(crate) frames: Vec<Frame>,
}

/// A parse error with its position (line and column from 1).
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct ParseError {
    /// Line, from 1.
    pub(crate) line: usize,
    /// Column, from 1, in characters.
    pub(crate) column: usize,
    /// What is wrong.
    pub(crate) message: String,
}

impl fmt::Display for ParseError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}:{}: {}", self.line, self.column, self.message)
    }
}

/// Tokens of a line with their 1-based character columns.
fn tokens(line: &str) -> Vec<(usize, &str)> {
    let code = line.split('#').next().unwrap_or("");
    let mut out = Vec::new();
    let mut start = None;
    for (col, (i, c)) in code.char_indices().enumerate() {
        match (c.is_whitespace(), start) {
            (false, None) => start = Some((col + 1, i)),
            (true, Some((scol, si))) => {
                out.push((scol, code.get(si..i).unwrap_or("")));
                start = None;
            }
            _ => {}
        }
    }
    if let Some((scol, si)) = start {
        out.push((scol, code.get(si..).unwrap_or("")));
    }
    out
}

impl Motion {
    /// Parses the text form.
    #[allow(clippy::too_many_lines)] // one arm per directive, each with its errors
    pub(crate) fn parse(text: &str) -> Result<Self, ParseError> {
        let mut torque = TorqueLevel::MIN;
        let mut frames = Vec::new();
        let mut servos: Option<usize> = None;
        for (n, line) in text.lines().enumerate() {
            let line_no = n + 1;
            let err = |column: usize, message: String| ParseError {
                line: line_no,
                column,
                message,
            };
            let toks = tokens(line);
            let Some(&(col, word)) = toks.first() else {
                continue;
            };
            let arg = |i: usize| -> Result<(usize, &str), ParseError> {
                toks.get(i).copied().ok_or_else(|| {
                    err(
                        line.chars().count() + 1,
                        format!("`{word}` needs more values"),
                    )
                })
            };
            let ms = |(c, t): (usize, &str)| -> Result<u32, ParseError> {
                let v: u32 = t
                    .parse()
                    .map_err(|_| err(c, format!("`{t}` is not a time in ms (0..={MAX_MS})")))?;
                if v > MAX_MS {
                    return Err(err(c, format!("time {v} ms is out of range 0..={MAX_MS}")));
                }
                Ok(v)
            };
            match word {
                "torque" => {
                    if !frames.is_empty() {
                        return Err(err(col, "`torque` must come before the first pose".into()));
                    }
                    let (c, t) = arg(1)?;
                    let v: u8 = t
                        .parse()
                        .map_err(|_| err(c, format!("`{t}` is not a torque level (0..=4)")))?;
                    torque = TorqueLevel::new(v).map_err(|e| err(c, e.to_string()))?;
                    if let Some(&(c, t)) = toks.get(2) {
                        return Err(err(c, format!("unexpected `{t}` after the torque level")));
                    }
                }
                "hold" => {
                    if frames.is_empty() {
                        return Err(err(col, "`hold` needs a pose before it".into()));
                    }
                    let v = ms(arg(1)?)?;
                    if let Some(&(c, t)) = toks.get(2) {
                        return Err(err(c, format!("unexpected `{t}` after the hold time")));
                    }
                    frames.push(Frame::Hold(v));
                }
                "pose" => {
                    let t = ms(arg(1)?)?;
                    arg(2)?;
                    let mut positions = Vec::new();
                    for &(c, p) in toks.iter().skip(2) {
                        let v: u32 = p
                            .parse()
                            .map_err(|_| err(c, format!("`{p}` is not a position (0..=254)")))?;
                        let pos = u8::try_from(v)
                            .map_err(|_| "")
                            .and_then(|b| Position::new(b).map_err(|_| ""))
                            .map_err(|_| err(c, format!("position {v} is out of range 0..=254")))?;
                        positions.push(pos);
                    }
                    if positions.len() > SyncMove::MAX_SERVOS {
                        return Err(err(
                            col,
                            format!(
                                "{} positions; a synchronized move drives at most 31 servos (0..=30)",
                                positions.len()
                            ),
                        ));
                    }
                    match servos {
                        None => servos = Some(positions.len()),
                        Some(k) if k != positions.len() => {
                            return Err(err(
                                col,
                                format!(
                                    "this pose lists {} servos, the first pose {k}; every pose must list the same servos",
                                    positions.len()
                                ),
                            ));
                        }
                        Some(_) => {}
                    }
                    frames.push(Frame::Pose(Pose { ms: t, positions }));
                }
                other => {
                    return Err(err(
                        col,
                        format!("unknown directive `{other}` (expected torque, pose or hold)"),
                    ));
                }
            }
        }
        if frames.is_empty() {
            return Err(ParseError {
                line: text.lines().count().max(1),
                column: 1,
                message: "the file has no pose".into(),
            });
        }
        Ok(Self { torque, frames })
    }

    /// The interpolated synchronized moves, one every `1000 / rate_hz` ms.
    pub(crate) fn plan(&self, rate_hz: f64) -> WckPlan {
        let period_ms = 1000.0 / rate_hz;
        let mut plan = WckPlan::default();
        plan.notes.push(format!(
            "synchronized moves at {rate_hz} Hz (one every {period_ms:.1} ms); t_ms in --json"
        ));
        let mut t0: u64 = 0;
        let mut prev: Option<&[Position]> = None;
        for frame in &self.frames {
            match frame {
                Frame::Hold(ms) => t0 += u64::from(*ms),
                Frame::Pose(pose) => {
                    match prev {
                        None => self.push(&mut plan, t0, &pose.positions),
                        Some(from) => {
                            #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
                            let steps = (f64::from(pose.ms) / period_ms).ceil().max(1.0) as u64;
                            for k in 1..=steps {
                                let at = t0 + u64::from(pose.ms) * k / steps;
                                let frac = k as f64 / steps as f64;
                                let pos: Vec<Position> = from
                                    .iter()
                                    .zip(&pose.positions)
                                    .map(|(a, b)| lerp(*a, *b, frac))
                                    .collect();
                                self.push(&mut plan, at, &pos);
                            }
                        }
                    }
                    t0 += u64::from(pose.ms);
                    prev = Some(&pose.positions);
                }
            }
        }
        plan
    }

    fn push(&self, plan: &mut WckPlan, at_ms: u64, positions: &[Position]) {
        // The parser guarantees 1..=31 positions.
        if let Ok(sync) = SyncMove::new(self.torque, positions) {
            plan.steps.push(WckStep {
                at_ms: Some(at_ms),
                baud: None,
                command: Command::SyncMove(sync),
            });
        }
    }

    /// The text form of a list of poses (what `teach` writes).
    pub(crate) fn to_text(&self, ids: &[ServoId]) -> String {
        let mut s = String::from("# robobus keyframe motion\n");
        let names: Vec<String> = ids.iter().map(ToString::to_string).collect();
        let _ = writeln!(s, "# servos {}", names.join(" "));
        let _ = writeln!(s, "torque {}", self.torque);
        for f in &self.frames {
            match f {
                Frame::Hold(ms) => {
                    let _ = writeln!(s, "hold {ms}");
                }
                Frame::Pose(p) => {
                    let ps: Vec<String> = p.positions.iter().map(ToString::to_string).collect();
                    let _ = writeln!(s, "pose {} {}", p.ms, ps.join(" "));
                }
            }
        }
        s
    }
}

/// Linear interpolation between two positions, rounded to the nearest step.
fn lerp(a: Position, b: Position, frac: f64) -> Position {
    let v = f64::from(a.get()) + (f64::from(b.get()) - f64::from(a.get())) * frac;
    #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)] // between a and b
    let raw = v.round().clamp(0.0, 254.0) as u8;
    Position::new(raw).unwrap_or(b)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p(raw: u8) -> Position {
        Position::new(raw).unwrap()
    }

    #[test]
    fn parses_poses_holds_and_torque() {
        let m =
            Motion::parse("# c\ntorque 2\npose 0 10 20\n\nhold 5 # x\npose 100 30 40\n").unwrap();
        assert_eq!(m.torque.get(), 2);
        assert_eq!(
            m.frames,
            vec![
                Frame::Pose(Pose {
                    ms: 0,
                    positions: vec![p(10), p(20)]
                }),
                Frame::Hold(5),
                Frame::Pose(Pose {
                    ms: 100,
                    positions: vec![p(30), p(40)]
                }),
            ]
        );
    }

    #[test]
    fn errors_point_at_line_and_column() {
        let e = Motion::parse("pose 0 1 2\npose 10 1 255\n").unwrap_err();
        assert_eq!((e.line, e.column), (2, 11));
        assert!(e.message.contains("255"), "{e}");
        let e = Motion::parse("pose 0 1 2\npose 10 1\n").unwrap_err();
        assert_eq!((e.line, e.column), (2, 1));
        let e = Motion::parse("  jump 3\n").unwrap_err();
        assert_eq!((e.line, e.column), (1, 3));
        assert!(Motion::parse("# nothing\n").is_err());
        assert!(Motion::parse("hold 3\n").is_err());
        assert!(Motion::parse("pose 0 1\ntorque 5\n").is_err());
        assert!(Motion::parse("torque 5\npose 0 1\n").is_err());
        assert!(Motion::parse("pose 600001 1\n").is_err());
    }

    #[test]
    fn interpolation_ends_exactly_on_each_pose() {
        let m = Motion::parse("pose 0 0 254\npose 100 100 154\nhold 50\npose 0 5 5\n").unwrap();
        let plan = m.plan(50.0); // 20 ms period: 5 steps of 20 ms
        let times: Vec<_> = plan.steps.iter().map(|s| s.at_ms.unwrap()).collect();
        assert_eq!(times, [0, 20, 40, 60, 80, 100, 150]);
        let Command::SyncMove(s) = plan.steps[1].command else {
            panic!()
        };
        assert_eq!(s.positions(), [p(20), p(234)]);
        let Command::SyncMove(s) = plan.steps[5].command else {
            panic!()
        };
        assert_eq!(s.positions(), [p(100), p(154)]);
        let Command::SyncMove(s) = plan.steps[6].command else {
            panic!()
        };
        assert_eq!(s.positions(), [p(5), p(5)]);
    }

    #[test]
    fn text_form_round_trips() {
        let m = Motion::parse("torque 1\npose 0 10 20\nhold 5\npose 100 30 40\n").unwrap();
        let ids = [ServoId::new(0).unwrap(), ServoId::new(1).unwrap()];
        assert_eq!(Motion::parse(&m.to_text(&ids)).unwrap(), m);
    }
}
