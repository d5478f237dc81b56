//! Keyframe motion files: what `teach` records and `play` plays.
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
//! move (A-1 (2)) per period of the rate; the last move of a transition is the pose
//! itself, exactly. The moves are computed one at a time ([`Motion::moves`]), so a long
//! motion is streamed, never expanded whole; files are read with a size limit
//! ([`MOTION_FILE_LIMIT`]).

use std::fmt;
use std::fmt::Write as _;
use std::io::Write as _;
use std::path::Path;

use robobus_wck::{Command, Position, ServoId, SyncMove, TorqueLevel};

use super::plan::{WckPlan, WckStep};
use crate::ops::{OpError, read_bounded};

/// The largest keyframe motion file read: 4 MiB (about 200 000 poses of 4 servos).
pub const MOTION_FILE_LIMIT: u64 = 4 << 20;

/// `--help` text describing the file format.
pub const FORMAT_HELP: &str = "\
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

/// One keyframe: positions of servos `0..n` and the time to get there; serialized as
/// `{"ms", "positions": [0..=254, ...]}`.
#[derive(Debug, Clone, PartialEq, Eq, schemars::JsonSchema)]
pub struct Pose {
    /// Transition time from the previous pose, ms.
    pub ms: u32,
    /// Positions of servos 0, 1, ...
    #[schemars(with = "Vec<u8>")]
    pub positions: Vec<Position>,
}

impl serde::Serialize for Pose {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeStruct as _;
        let mut st = s.serialize_struct("Pose", 2)?;
        st.serialize_field("ms", &self.ms)?;
        let ps: Vec<u8> = self.positions.iter().map(|p| p.get()).collect();
        st.serialize_field("positions", &ps)?;
        st.end()
    }
}

/// An entry of a motion.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Frame {
    /// Move to a pose.
    Pose(Pose),
    /// Keep the current pose.
    Hold(u32),
}

/// A parsed keyframe motion file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Motion {
    /// Torque level of every move.
    pub torque: TorqueLevel,
    /// The entries in order; the first is a pose.
    pub frames: Vec<Frame>,
}

/// A parse error with its position (line and column from 1).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ParseError {
    /// Line, from 1.
    pub line: usize,
    /// Column, from 1, in characters.
    pub column: usize,
    /// What is wrong.
    pub message: String,
}

impl std::error::Error for ParseError {}

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
    pub fn parse(text: &str) -> Result<Self, ParseError> {
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

    /// Reads and parses a keyframe file of at most [`MOTION_FILE_LIMIT`] bytes; a syntax
    /// error is [`OpError::Invalid`] naming `FILE:line:column`.
    #[allow(clippy::result_large_err)] // OpError carries the client errors by value
    pub fn load(path: &Path) -> Result<Self, OpError> {
        let text = read_bounded(path, MOTION_FILE_LIMIT)?;
        Self::parse(&text).map_err(|e| OpError::Invalid {
            option: "FILE".into(),
            value: format!("{}:{e}", path.display()),
            reason: "not a keyframe motion file (see `robobus wck play --help`)".into(),
        })
    }

    /// When the last pose is reached, ms after the start (the motion's length, without a
    /// trailing hold).
    pub fn end_ms(&self) -> u64 {
        let (mut t, mut end, mut first) = (0u64, 0u64, true);
        for f in &self.frames {
            match f {
                Frame::Hold(ms) => t += u64::from(*ms),
                Frame::Pose(p) => {
                    if !first {
                        end = t + u64::from(p.ms);
                    }
                    first = false;
                    t += u64::from(p.ms);
                }
            }
        }
        end
    }

    /// The servos a pose lists (0..n).
    pub fn servos(&self) -> usize {
        self.frames
            .iter()
            .find_map(|f| match f {
                Frame::Pose(p) => Some(p.positions.len()),
                Frame::Hold(_) => None,
            })
            .unwrap_or(0)
    }

    /// The interpolated synchronized moves, one every `1000 / rate_hz` ms, computed one
    /// at a time (a long motion is never expanded whole).
    pub fn moves(&self, rate_hz: f64) -> Moves<'_> {
        Moves {
            motion: self,
            period_ms: 1000.0 / rate_hz,
            frame: 0,
            t0: 0,
            prev: None,
            step: 0,
            steps: 0,
            watch_at: PLAY_WATCH_MS,
            watched: 0,
            pending: None,
        }
    }

    /// The note a plan of this motion carries.
    pub fn plan_note(rate_hz: f64) -> String {
        format!(
            "synchronized moves at {rate_hz} Hz (one every {:.1} ms); t_ms in --json",
            1000.0 / rate_hz
        )
    }

    /// The whole plan (for a dry-run in JSON: it holds every move; the text dry-run and
    /// the real run stream [`moves`](Self::moves) instead).
    pub fn plan(&self, rate_hz: f64) -> WckPlan {
        WckPlan {
            notes: vec![Self::plan_note(rate_hz)],
            steps: self.moves(rate_hz).collect(),
        }
    }

    /// The text form of a list of poses (what `teach` writes).
    pub fn to_text(&self, ids: &[ServoId]) -> String {
        let mut s = header(ids, self.torque);
        for f in &self.frames {
            match f {
                Frame::Hold(ms) => {
                    let _ = writeln!(s, "hold {ms}");
                }
                Frame::Pose(p) => s.push_str(&pose_line(p)),
            }
        }
        s
    }
}

fn header(ids: &[ServoId], torque: TorqueLevel) -> String {
    let mut s = String::from("# robobus keyframe motion\n");
    let names: Vec<String> = ids.iter().map(ToString::to_string).collect();
    let _ = writeln!(s, "# servos {}", names.join(" "));
    let _ = writeln!(s, "torque {torque}");
    s
}

fn pose_line(p: &Pose) -> String {
    let ps: Vec<String> = p.positions.iter().map(ToString::to_string).collect();
    format!("pose {} {}\n", p.ms, ps.join(" "))
}

/// Writes a keyframe file pose by pose, flushing each (what `teach` records is kept
/// even when the recording is cut off).
pub struct MotionWriter {
    out: Box<dyn std::io::Write + Send>,
}

impl fmt::Debug for MotionWriter {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("MotionWriter").finish_non_exhaustive()
    }
}

impl MotionWriter {
    /// Creates (or truncates) `path` and writes the header: done before any device is
    /// touched, so an unwritable path fails first.
    #[allow(clippy::result_large_err)] // OpError carries the client errors by value
    pub fn create(path: &Path, ids: &[ServoId], torque: TorqueLevel) -> Result<Self, OpError> {
        let file = std::fs::File::create(path).map_err(|e| OpError::File {
            path: path.to_path_buf(),
            reason: format!("cannot write: {e}"),
            kind: crate::ErrorKind::BadInput,
        })?;
        Self::new(Box::new(file), ids, torque).map_err(|e| OpError::File {
            path: path.to_path_buf(),
            reason: format!("cannot write: {e}"),
            kind: crate::ErrorKind::Link,
        })
    }

    /// A writer on any output (standard output, a buffer), header written.
    pub fn new(
        mut out: Box<dyn std::io::Write + Send>,
        ids: &[ServoId],
        torque: TorqueLevel,
    ) -> std::io::Result<Self> {
        out.write_all(header(ids, torque).as_bytes())?;
        out.flush()?;
        Ok(Self { out })
    }

    /// Appends one pose and flushes.
    pub fn pose(&mut self, pose: &Pose) -> std::io::Result<()> {
        self.out.write_all(pose_line(pose).as_bytes())?;
        self.out.flush()
    }
}

/// The synchronized moves of a [`Motion`], one at a time (see [`Motion::moves`]).
#[derive(Debug, Clone)]
pub struct Moves<'a> {
    motion: &'a Motion,
    period_ms: f64,
    frame: usize,
    t0: u64,
    prev: Option<&'a [Position]>,
    /// The move within the current transition (1..=steps), 0 = not started.
    step: u64,
    steps: u64,
    /// When the next watch read is due, ms.
    watch_at: u64,
    /// Watch reads so far (the next one asks servo `watched % servos`).
    watched: usize,
    /// The watch read that goes right after the move just returned.
    pending: Option<WckStep>,
}

/// How often a played motion reads one servo's status (round robin over its servos, right
/// after the first move due at or after each multiple of this), ms:
/// synchronized moves have no reply, so without it a servo (or a whole bus) that stops
/// answering would go unnoticed. A read that gets no answer ends the run in the safe state.
pub const PLAY_WATCH_MS: u64 = 200;

impl Iterator for Moves<'_> {
    type Item = WckStep;

    fn next(&mut self) -> Option<WckStep> {
        if let Some(read) = self.pending.take() {
            return Some(read);
        }
        let step = self.next_move()?;
        let at = step.at_ms.unwrap_or(0);
        let servos = self.motion.servos();
        if at >= self.watch_at && servos > 0 {
            // Right after the move (which keeps its time), never before it.
            while self.watch_at <= at {
                self.watch_at += PLAY_WATCH_MS;
            }
            let id = u8::try_from(self.watched % servos)
                .ok()
                .and_then(|i| ServoId::new(i).ok());
            self.watched += 1;
            self.pending = id.map(|id| WckStep::now(Command::StatusRead { id }));
        }
        Some(step)
    }
}

impl Moves<'_> {
    fn next_move(&mut self) -> Option<WckStep> {
        loop {
            let frame = self.motion.frames.get(self.frame)?;
            match frame {
                Frame::Hold(ms) => {
                    self.t0 += u64::from(*ms);
                    self.frame += 1;
                }
                Frame::Pose(pose) => {
                    let Some(from) = self.prev else {
                        // The first pose goes at once.
                        self.prev = Some(&pose.positions);
                        let at = self.t0;
                        self.t0 += u64::from(pose.ms);
                        self.frame += 1;
                        return self.motion.step(at, &pose.positions);
                    };
                    if self.step == 0 {
                        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
                        let steps = (f64::from(pose.ms) / self.period_ms).ceil().max(1.0) as u64;
                        self.steps = steps;
                    }
                    self.step += 1;
                    let k = self.step;
                    let at = self.t0 + u64::from(pose.ms) * k / self.steps;
                    #[allow(clippy::cast_precision_loss)] // steps < 2^53
                    let frac = k as f64 / self.steps as f64;
                    let pos: Vec<Position> = from
                        .iter()
                        .zip(&pose.positions)
                        .map(|(a, b)| lerp(*a, *b, frac))
                        .collect();
                    if k >= self.steps {
                        self.t0 += u64::from(pose.ms);
                        self.prev = Some(&pose.positions);
                        self.frame += 1;
                        self.step = 0;
                    }
                    return self.motion.step(at, &pos);
                }
            }
        }
    }
}

impl Motion {
    fn step(&self, at_ms: u64, positions: &[Position]) -> Option<WckStep> {
        // The parser guarantees 1..=31 positions.
        SyncMove::new(self.torque, positions)
            .ok()
            .map(|sync| WckStep::at(at_ms, Command::SyncMove(sync)))
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

#[cfg(test)]
mod limits {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        /// Any text parses or fails with a position inside it; never panics.
        #[test]
        fn any_text_parses_or_points_into_itself(text in "(?s).{0,400}") {
            match Motion::parse(&text) {
                Ok(m) => prop_assert!(m.servos() >= 1 && m.servos() <= 31),
                Err(e) => {
                    prop_assert!(e.line >= 1 && e.line <= text.lines().count().max(1));
                    prop_assert!(e.column >= 1);
                }
            }
        }

        /// Valid motions round-trip through their text form, and their streamed moves end
        /// on the last pose.
        #[test]
        fn motions_round_trip_and_end_on_the_last_pose(
            poses in proptest::collection::vec((0u32..2000, proptest::collection::vec(0u8..=254, 3)), 1..8),
            rate in 1.0f64..200.0,
        ) {
            let mut text = String::from("torque 2\n");
            for (ms, ps) in &poses {
                let ps: Vec<String> = ps.iter().map(ToString::to_string).collect();
                let _ = writeln!(text, "pose {ms} {}", ps.join(" "));
            }
            let m = Motion::parse(&text).unwrap();
            let ids: Vec<ServoId> = (0..3).map(|i| ServoId::new(i).unwrap()).collect();
            prop_assert_eq!(&Motion::parse(&m.to_text(&ids)).unwrap(), &m);
            // The last move (a watch read may follow it).
            let last = m
                .moves(rate)
                .filter(|s| matches!(s.command, Command::SyncMove(_)))
                .last()
                .unwrap();
            let Command::SyncMove(s) = last.command else { unreachable!() };
            let want: Vec<u8> = poses.last().unwrap().1.clone();
            prop_assert_eq!(s.positions().iter().map(|p| p.get()).collect::<Vec<_>>(), want);
            prop_assert_eq!(m.plan(rate).steps.len(), m.moves(rate).count());
        }
    }

    #[test]
    fn files_are_read_with_a_limit() {
        let e = Motion::load(Path::new("/dev/zero")).unwrap_err();
        assert_eq!(e.kind(), crate::ErrorKind::BadInput);
        assert!(e.to_string().contains("limit of 4 MiB"), "{e}");
    }

    #[test]
    fn long_motions_are_streamed_not_expanded() {
        // 1000 transitions of 10 minutes at 200 Hz: 120 million moves if expanded whole.
        let mut text = String::from("pose 0 0\n");
        for i in 0..1000 {
            let _ = writeln!(text, "pose 600000 {}", (i % 2) * 254);
        }
        let m = Motion::parse(&text).unwrap();
        let start = std::time::Instant::now();
        let first: Vec<WckStep> = m.moves(200.0).take(3).collect();
        assert_eq!(first.len(), 3);
        assert_eq!(first[2].at_ms, Some(10));
        assert!(start.elapsed() < std::time::Duration::from_secs(1));
        assert_eq!(m.end_ms(), 600_000_000);
    }
}
