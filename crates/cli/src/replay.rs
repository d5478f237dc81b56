//! `robobus replay FILE`: print what every frame or packet of a capture file means.
//!
//! The decoding is [`robobus::ops::replay`]'s; this module parses the options and renders
//! the entries: one line per frame, packet or reply (time, direction, CAN ID, bytes,
//! meaning), or with `--json` one JSON document (`file`, `format`, `entries`, `side`,
//! `summary`), written entry by entry so a capture of any size prints in bounded memory.

use std::fmt::Write as _;
use std::io::{BufWriter, Write};
use std::path::PathBuf;

use anyhow::Context as _;
use robobus::ops::replay::{self, Entry, EntryKind, Format, ReplayOptions, Side};
use robobus::ops::{ErrorKind, OpError};
use robobus_whj::units::CurrentScale;

use crate::Global;

/// `--help` text describing the formats.
const FORMATS_HELP: &str = "\
Capture formats (detected from the first line unless --format is given):
  candump  WHJ CAN FD frames as `candump -L` writes them:
             (1795360410.847412) can0 001##5020A01
  hex      wCK bytes, one line per read or write: seconds, > or <, hex bytes:
             0.000100 > FF 03 7F 7C
             0.000900 < 12 7F
           `>` is what the side that wrote the log sent. A host's log (`>` commands) and a
           simulator's log (`>` replies) are both read: --side, or detected.

Output: one line per frame, packet or reply: time, direction (> to the devices, < from
them), CAN ID (WHJ), the bytes, and their meaning. Malformed lines, frames and packets
(bad checksum, unknown command, truncated) are marked MALFORMED with the reason, reply
bytes no command asked for UNEXPECTED, and a command whose reply never came NO REPLY.
Exit code 2 when the file cannot be read (it names the file and line), and with --strict
at the first malformed entry.";

/// Options of `robobus replay`.
#[derive(Debug, clap::Args)]
#[command(after_help = FORMATS_HELP)]
pub(crate) struct Args {
    /// The capture file (candump log or hex log).
    file: PathBuf,
    /// The capture format (default: detected from the first line).
    #[arg(long, value_enum)]
    format: Option<FormatArg>,
    /// Which side wrote a hex log (default: detected).
    #[arg(long, value_enum, default_value = "auto")]
    side: SideArg,
    /// mA per current count of the WHJ joints: 1, or 2 for Joint 60 / 120.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u8).range(1..=2), value_name = "MA")]
    current_scale: u8,
    /// Stop with exit code 2 at the first malformed entry.
    #[arg(long)]
    strict: bool,
}

#[derive(Debug, Clone, Copy, clap::ValueEnum)]
enum FormatArg {
    /// candump log (WHJ CAN FD frames).
    Candump,
    /// Hex log (wCK bytes).
    Hex,
}

#[derive(Debug, Clone, Copy, clap::ValueEnum)]
enum SideArg {
    /// Detect it.
    Auto,
    /// The host wrote the log: `>` are commands.
    Host,
    /// A simulator (the devices) wrote the log: `<` are commands.
    Device,
}

/// Runs `robobus replay`.
pub(crate) fn run(g: Global, args: &Args) -> anyhow::Result<()> {
    let options = ReplayOptions {
        format: args.format.map(|f| match f {
            FormatArg::Candump => Format::Candump,
            FormatArg::Hex => Format::Hex,
        }),
        side: match args.side {
            SideArg::Auto => Side::Auto,
            SideArg::Host => Side::Host,
            SideArg::Device => Side::Device,
        },
        current_scale: if args.current_scale == 2 {
            CurrentScale::TwoMilliamps
        } else {
            CurrentScale::OneMilliamp
        },
    };
    let mut replay = replay::open(&args.file, &options)?;
    let stdout = std::io::stdout();
    let mut out = BufWriter::new(stdout.lock());
    let format = replay.format();
    if g.json {
        write!(
            out,
            "{{\"file\":{},\"format\":{},\"entries\":[",
            serde_json::to_string(&args.file.display().to_string())?,
            serde_json::to_string(&format)?
        )?;
    }
    let mut first = true;
    let mut failure = None;
    for entry in replay.by_ref() {
        let entry = entry?;
        if g.json {
            if !first {
                out.write_all(b",")?;
            }
            serde_json::to_writer(&mut out, &entry)?;
        } else {
            writeln!(out, "{}", render(&entry))?;
        }
        first = false;
        if args.strict && entry.kind == EntryKind::Malformed {
            failure = Some(OpError::File {
                path: args.file.clone(),
                reason: format!(
                    "line {}: malformed: {}",
                    entry.line,
                    entry.malformed.as_deref().unwrap_or_default()
                ),
                kind: ErrorKind::BadInput,
            });
            break;
        }
    }
    let summary = replay.summary();
    if g.json {
        writeln!(
            out,
            "],\"side\":{},\"summary\":{}}}",
            serde_json::to_string(&(format == Format::Hex).then_some(replay.side()))?,
            serde_json::to_string(&summary)?
        )?;
    } else {
        writeln!(
            out,
            "# {} entries: {} requests, {} replies, {} missing replies, {} unexpected, {} malformed",
            summary.entries,
            summary.requests,
            summary.replies,
            summary.missing,
            summary.unexpected,
            summary.malformed
        )?;
    }
    out.flush().context("writing the replay")?;
    failure.map_or(Ok(()), |e| Err(e.into()))
}

/// One entry as a text line: `time dir [CAN ID] bytes  meaning`.
fn render(e: &Entry) -> String {
    let mut s = e.time.clone().unwrap_or_else(|| "-".into());
    s.push(' ');
    s.push_str(e.direction.arrow());
    if let Some(id) = e.can_id {
        if id > 0x7FF {
            let _ = write!(s, " {id:08X}");
        } else {
            let _ = write!(s, " {id:03X}");
        }
    }
    if !e.bytes.is_empty() {
        s.push(' ');
        s.push_str(&e.bytes);
    }
    s.push_str("  ");
    s.push_str(&e.text);
    if matches!(e.kind, EntryKind::Malformed | EntryKind::Unexpected) {
        let _ = write!(s, " (line {})", e.line);
    }
    s
}
