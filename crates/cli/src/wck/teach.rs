//! `robobus wck teach` at the terminal: the key presses that record poses, and where the
//! poses go as they are recorded (a file, or stdout as text). The recording itself is the
//! library's (`wck.teach`); this is its [`Interaction`].

use std::io::{BufRead as _, IsTerminal as _, Read as _};
use std::path::{Path, PathBuf};
use std::sync::mpsc;
use std::time::Duration;

use robobus::ErrorKind;
use robobus::catalogue::{Interaction, Report, Request};
use robobus::ops::OpError;
use robobus::ops::ids_text;
use robobus::ops::wck::{MotionWriter, Pose, TeachEvent};
use robobus_wck::{ServoId, TorqueLevel};

use crate::exit::usage;
use crate::output;

/// Longest line `teach` reads as a key press.
const MAX_KEY_LINE: usize = 1024;

/// The terminal side of a recording.
pub(super) struct Teacher {
    /// Lines typed on stdin; `None` for a timed recording, which does not read stdin.
    keys: Option<mpsc::Receiver<Option<String>>>,
    /// Poses by key press (a line records, `q` or the end of input finishes); otherwise a
    /// line finishes a recording at a rate.
    by_key: bool,
    /// Whether stdin is a terminal (the poses are echoed to stderr as they come).
    interactive: bool,
    /// Where poses are written as they are recorded; `None`: kept in the report (`--json`
    /// without `--output`).
    writer: Option<MotionWriter>,
    /// The file, for messages.
    path: Option<PathBuf>,
    /// The servos, for messages.
    ids: Vec<ServoId>,
    /// Poses recorded so far.
    count: usize,
}

impl Teacher {
    /// The terminal side of `request` (a `wck.teach`): creates `output` at once (an
    /// unwritable path fails before anything is opened) and tells the user what to do.
    pub(super) fn new(
        request: &Request,
        output: Option<&Path>,
        json: bool,
    ) -> anyhow::Result<Self> {
        let Request::WckTeach(t) = request else {
            return Err(usage("not a teach request"));
        };
        let ids: Vec<ServoId> = t.ids.parse("<IDS>")?;
        let torque = TorqueLevel::new(u8::try_from(t.torque).unwrap_or(u8::MAX))
            .map_err(|e| usage(format!("--torque: {e}")))?;
        let by_key = t.rate_hz.is_none() && t.duration.is_none();
        let timed = t.duration.is_some();
        let interactive = std::io::stdin().is_terminal();
        let writer = match (output, json) {
            (Some(path), _) => Some(MotionWriter::create(path, &ids, torque)?),
            (None, false) => Some(MotionWriter::new(
                Box::new(std::io::stdout()),
                &ids,
                torque,
            )?),
            (None, true) => None,
        };
        if by_key && interactive {
            eprintln!(
                "robobus: servo(s) {} are passive: move them by hand. Enter records a pose, \
                 q + Enter (or Ctrl-D) finishes, Ctrl-C aborts.",
                ids_text(&ids)
            );
        } else if !by_key && !timed {
            eprintln!(
                "robobus: recording at {} Hz; press Enter (or Ctrl-C) to stop",
                t.rate_hz.unwrap_or(10.0)
            );
        }
        Ok(Self {
            keys: (!timed).then(stdin_lines),
            by_key,
            interactive,
            writer,
            path: output.map(Path::to_path_buf),
            ids,
            count: 0,
        })
    }

    /// After the run: the text summary of a recording into a file (poses printed to stdout
    /// need none).
    pub(super) fn finish(self, report: &Report, output: Option<&Path>) -> anyhow::Result<()> {
        match output {
            Some(path) if report.failed.is_none() => output::print(&format!(
                "recorded {} pose(s) of servo(s) {} to {}\n",
                self.count,
                ids_text(&self.ids),
                path.display()
            )),
            _ => Ok(()),
        }
    }
}

impl Interaction for Teacher {
    fn teach_event(&mut self, wait: Duration) -> TeachEvent {
        let Some(keys) = &self.keys else {
            std::thread::sleep(wait);
            return TeachEvent::Nothing;
        };
        match keys.recv_timeout(wait) {
            Ok(Some(line)) if self.by_key && line.trim() != "q" => TeachEvent::Record,
            Ok(_) | Err(mpsc::RecvTimeoutError::Disconnected) => TeachEvent::Finish,
            Err(mpsc::RecvTimeoutError::Timeout) => TeachEvent::Nothing,
        }
    }

    fn pose(&mut self, pose: &Pose) -> Result<(), OpError> {
        self.count += 1;
        if self.by_key && self.interactive {
            let ps: Vec<String> = pose.positions.iter().map(ToString::to_string).collect();
            eprintln!("pose {}: {}", self.count, ps.join(" "));
        }
        let Some(w) = self.writer.as_mut() else {
            return Ok(());
        };
        w.pose(pose).map_err(|e| OpError::File {
            path: self
                .path
                .clone()
                .unwrap_or_else(|| "(standard output)".into()),
            reason: format!("cannot write: {e}"),
            kind: ErrorKind::Link,
        })
    }

    fn keep_poses(&self) -> bool {
        self.writer.is_none()
    }
}

/// Lines typed on stdin (Enter = a line, EOF ends), read in a thread so Ctrl-C is seen
/// while waiting. Lines are bounded ([`MAX_KEY_LINE`]) and so is the queue (a few lines),
/// so an endless input (`< /dev/zero`, `yes |`) costs no memory: an overlong line ends
/// the input.
fn stdin_lines() -> mpsc::Receiver<Option<String>> {
    let (tx, rx) = mpsc::sync_channel(4);
    std::thread::spawn(move || {
        let stdin = std::io::stdin();
        let mut lock = stdin.lock();
        loop {
            let mut line = String::new();
            let limit = MAX_KEY_LINE as u64 + 1;
            match (&mut lock).take(limit).read_line(&mut line) {
                Ok(0) | Err(_) => {
                    let _ = tx.send(None);
                    return;
                }
                Ok(n) if n > MAX_KEY_LINE && !line.ends_with('\n') => {
                    eprintln!(
                        "robobus: a line of more than {MAX_KEY_LINE} bytes on stdin: that is \
                         not a key press; input ends here"
                    );
                    let _ = tx.send(None);
                    return;
                }
                Ok(_) => {
                    if tx.send(Some(line)).is_err() {
                        return;
                    }
                }
            }
        }
    });
    rx
}
