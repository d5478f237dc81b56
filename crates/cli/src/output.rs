//! How the CLI writes to stdout, and what `--dry-run` prints.
//!
//! Every `robobus wck` / `robobus whj` subcommand first builds its plan (the library's:
//! the validated, typed commands in the order they go on the wire, with the time each is
//! due). `--dry-run` prints the plan and opens nothing.
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
//! wCK: one object `{"dry_run": true, "bus": ..., "notes": [...], "packets": [...]}`, a
//! packet `{"t_ms", "baud", "command", "target", "hex", "bytes", "reply_len"}`. WHJ: the
//! library's plan ([`robobus::catalogue::Plan`]): `{"op", "family", "notes", "steps",
//! "confirm", "truncated"}`, a step `{"t_ms", "can_id", "what", "bytes", "line"}` (`line`
//! is the text form). `t_ms` is when it is due after the start (`null` = as soon as the
//! previous exchange is done).

use std::io::Write as _;

use serde_json::Value;

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
