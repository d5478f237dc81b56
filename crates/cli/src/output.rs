//! What a wCK or WHJ command would send, and how `--dry-run` prints it.
//!
//! Every `robobus wck` / `robobus whj` subcommand first builds a plan (wCK: the library's
//! [`robobus::ops::wck::WckPlan`], [`WhjPlan`]): the validated, typed commands in the order they go on the wire, with the
//! time each is due. `--dry-run` prints the plan; a real run hands it to [`crate::client`].
//!
//! # Text format (stdout)
//!
//! * wCK: one packet per line, hex bytes separated by spaces, as the manual prints them:
//!   `FF 03 7F 7C`.
//! * WHJ: one CAN FD frame per line in `cansend`'s syntax, `ID##FLAGS DATA` without the
//!   space: `001##1020A01` is standard ID 0x001, flags 1 (bit-rate switch on; bit 1 = ESI),
//!   data `02 0A 01`. A line can be passed to `cansend can0` as it is.
//! * Lines starting with `#` are comments: notes on assumptions, the pacing of timed
//!   sequences, and (wCK `scan --all-bauds`) the baud rate the following packets go at.
//!
//! # JSON format (`--json`)
//!
//! One object: `{"dry_run": true, "bus": ..., "notes": [...], "packets": [...]}` for wCK,
//! `"frames"` for WHJ. A packet is `{"t_ms", "baud", "command", "target", "hex", "bytes",
//! "reply_len"}`; a frame is `{"t_ms", "id", "fd", "brs", "esi", "hex", "data", "line",
//! "request"}` (`line` is the text form). `t_ms` is when it is due after the start
//! (`null` = as soon as the previous exchange is done).

use std::fmt::Write as _;
use std::io::Write as _;

use robobus_whj::Request;
use serde_json::{Value, json};

/// One WHJ request to send.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct WhjStep {
    /// When it is due, µs after the start; `None` = right after the previous exchange.
    pub(crate) at_us: Option<u64>,
    /// The request.
    pub(crate) request: Request,
}

/// The frames a `robobus whj` command sends, in order.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub(crate) struct WhjPlan {
    /// Notes printed as comments.
    pub(crate) notes: Vec<String>,
    /// The requests.
    pub(crate) steps: Vec<WhjStep>,
}

pub(crate) use robobus::catalogue::plan::frame_line;

fn spaced_hex(bytes: &[u8]) -> String {
    let mut s = String::with_capacity(3 * bytes.len());
    for (i, b) in bytes.iter().enumerate() {
        if i > 0 {
            s.push(' ');
        }
        let _ = write!(s, "{b:02X}");
    }
    s
}

impl WhjPlan {
    /// The library's plan of an operation ([`robobus::ops::whj::Plan`]): what it assumed
    /// and its notes as comments, its reads, then its timed frames.
    pub(crate) fn of(plan: &robobus::ops::whj::Plan) -> Self {
        let mut p = Self::default();
        p.notes.extend(plan.assumed.iter().cloned());
        p.notes.extend(plan.notes.iter().cloned());
        for r in &plan.reads {
            p.push(*r);
        }
        for f in &plan.frames {
            #[allow(clippy::cast_possible_truncation)] // at most hours, in µs
            p.push_at(f.at.as_micros() as u64, f.request);
        }
        p
    }

    /// Appends a request sent right after the previous exchange.
    pub(crate) fn push(&mut self, request: Request) {
        self.steps.push(WhjStep {
            at_us: None,
            request,
        });
    }

    /// Appends a request due at `at_us` µs after the start.
    pub(crate) fn push_at(&mut self, at_us: u64, request: Request) {
        self.steps.push(WhjStep {
            at_us: Some(at_us),
            request,
        });
    }

    /// The text form (see the module docs).
    pub(crate) fn to_text(&self) -> String {
        let mut s = String::new();
        for n in &self.notes {
            let _ = writeln!(s, "# {n}");
        }
        for st in &self.steps {
            let _ = writeln!(s, "{}", frame_line(&st.request.to_frame()));
        }
        s
    }

    /// The JSON form (see the module docs).
    pub(crate) fn to_json(&self, bus: &str) -> Value {
        let frames: Vec<Value> = self
            .steps
            .iter()
            .map(|st| {
                let f = st.request.to_frame();
                json!({
                    "t_ms": st.at_us.map(|us| us as f64 / 1000.0),
                    "id": f.raw_id(),
                    "fd": f.is_fd(),
                    "brs": f.brs(),
                    "esi": f.esi(),
                    "hex": spaced_hex(f.data()),
                    "data": f.data(),
                    "line": frame_line(&f),
                    "request": format!("{:?}", st.request),
                })
            })
            .collect();
        json!({
            "dry_run": true,
            "bus": {"kind": "whj", "bus": bus},
            "notes": self.notes,
            "frames": frames,
        })
    }
}

/// Writes `text` to stdout (a closed pipe is not an error worth a panic).
pub(crate) fn print(text: &str) -> anyhow::Result<()> {
    let mut out = std::io::stdout().lock();
    match out.write_all(text.as_bytes()).and_then(|()| out.flush()) {
        Err(e) if e.kind() != std::io::ErrorKind::BrokenPipe => Err(e.into()),
        _ => Ok(()),
    }
}

/// Refuses (bad input, before any work) an output file whose folder does not exist or is
/// not a folder, so a long run never ends in "cannot write". `option` names the option.
pub(crate) fn check_output_path(path: &std::path::Path, option: &str) -> anyhow::Result<()> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => std::path::Path::new("."),
    };
    if !dir.is_dir() {
        return Err(crate::exit::usage(format!(
            "{option} {}: the folder {} does not exist (create it first, or give another path)",
            path.display(),
            dir.display()
        )));
    }
    if path.is_dir() {
        return Err(crate::exit::usage(format!(
            "{option} {}: is a folder; give a file name",
            path.display()
        )));
    }
    Ok(())
}

/// Writes a JSON value to stdout, pretty-printed, with a final newline.
pub(crate) fn print_json(value: &Value) -> anyhow::Result<()> {
    let mut text = serde_json::to_string_pretty(value)?;
    text.push('\n');
    print(&text)
}

#[cfg(test)]
mod tests {
    use super::*;
    use robobus_whj::JointId;

    #[test]
    fn frame_lines_use_cansend_syntax() {
        let j1 = JointId::new(1).unwrap();
        let f = Request::enable(j1, true).to_frame();
        assert_eq!(frame_line(&f), "001##1020A01");
        let q = Request::StatusQuery { joint: j1 }.to_frame();
        assert_eq!(frame_line(&q), "601##1");
    }
}
