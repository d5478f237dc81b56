//! The parsers of files and user input: capture lines and whole captures, the robot TOML,
//! keyframe motions, motion programs, ID lists and register names.

use std::io::Cursor;

use robobus::ops::IdList;
use robobus::ops::replay::{Replay, ReplayOptions};
use robobus::ops::wck::Motion;
use robobus_link::capture::{
    format_candump_line, format_hex_line, parse_candump_line, parse_hex_line,
};
use robobus_wck::{Program, ServoId};
use robobus_whj::JointId;

use crate::{Checked, ensure};

/// The longest input a text check reads (the parsers' own file limits are larger; this
/// keeps each fuzz run short).
const MAX_TEXT: usize = 64 * 1024;

fn text_of(data: &[u8]) -> Option<&str> {
    std::str::from_utf8(data.get(..data.len().min(MAX_TEXT))?).ok()
}

/// Whether (`line`, `column`), both from 1 with the column in characters, lies inside
/// `text`: on one of its lines (split at `\n`; an empty text has one line), at most one
/// past that line's last character (a `\r` is a character: an error at the end of a
/// `\r\n` line may point at either).
pub fn position_inside(text: &str, line: usize, column: usize) -> bool {
    line >= 1
        && column >= 1
        && text
            .split('\n')
            .nth(line - 1)
            .is_some_and(|l| column <= l.chars().count() + 1)
}

/// `t` to the microsecond, the resolution capture lines are written with.
fn to_micros(t: std::time::Duration) -> std::time::Duration {
    std::time::Duration::new(t.as_secs(), t.subsec_micros() * 1000)
}

/// One candump line: what parses formats back to a line that parses to the same record
/// (times to the microsecond).
pub fn candump_line(data: &[u8]) -> Checked {
    let Some(text) = text_of(data) else {
        return Ok(());
    };
    let Some(line) = text.lines().next() else {
        return Ok(());
    };
    if let Ok(mut record) = parse_candump_line(line) {
        // candump writes microseconds (canplayer requires six decimals): a time read with
        // nanoseconds comes back to the microsecond.
        record.timestamp = to_micros(record.timestamp);
        let again = format_candump_line(&record);
        let back = parse_candump_line(&again);
        ensure!(
            back.as_ref() == Ok(&record),
            "`{line}` parsed to {record:?}, formatted as `{again}`, which parses to {back:?}"
        );
    }
    Ok(())
}

/// One hex log line: what parses formats back to a line that parses to the same record.
pub fn hex_line(data: &[u8]) -> Checked {
    let Some(text) = text_of(data) else {
        return Ok(());
    };
    let Some(line) = text.lines().next() else {
        return Ok(());
    };
    if let Ok(Some(mut record)) = parse_hex_line(line) {
        record.at = to_micros(record.at);
        let again = format_hex_line(&record);
        let back = parse_hex_line(&again);
        ensure!(
            matches!(&back, Ok(Some(r)) if *r == record),
            "`{line}` parsed to {record:?}, formatted as `{again}`, which parses to {back:?}"
        );
    }
    Ok(())
}

/// A whole capture (candump or hex log, any bytes): it replays to at most a few entries
/// per line (every malformed line, stray byte or missing reply is an entry of its own,
/// never a crash), and the replay ends.
pub fn replay(data: &[u8]) -> Checked {
    let data = data.get(..data.len().min(MAX_TEXT)).unwrap_or_default();
    let Ok(r) = Replay::from_reader(Cursor::new(data), "fuzz.log", &ReplayOptions::default())
    else {
        return Ok(());
    };
    // A line yields its entry and at most a few the pairing adds (missing replies), a hex
    // line one per byte at most.
    let bound = 4 * (data.len() + 2);
    let mut n = 0usize;
    for entry in r {
        let _ = entry;
        n += 1;
        ensure!(
            n <= bound,
            "{} bytes replayed to more than {bound} entries",
            data.len()
        );
    }
    Ok(())
}

/// The robot TOML: accepted, or refused at a position inside the text (line and column
/// 0 name the file as a whole, for a value that is wrong wherever it stands).
pub fn robot_toml(data: &[u8]) -> Checked {
    let Some(text) = text_of(data) else {
        return Ok(());
    };
    if let Err(robobus::RobotError::Parse { line, column, .. }) =
        robobus::RobotConfig::from_toml_str(text)
    {
        ensure!(
            (line, column) == (0, 0) || position_inside(text, line, column),
            "robot file refused at line {line}, column {column}, outside its text"
        );
    }
    Ok(())
}

/// A keyframe motion: accepted (and then its text form parses back equal), or refused at
/// a position inside the text.
pub fn motion_text(data: &[u8]) -> Checked {
    let Some(text) = text_of(data) else {
        return Ok(());
    };
    match Motion::parse(text) {
        Ok(m) => {
            let ids: Vec<ServoId> = (0..m.servos())
                .filter_map(|i| u8::try_from(i).ok().and_then(|i| ServoId::new(i).ok()))
                .collect();
            let again = m.to_text(&ids);
            let back = Motion::parse(&again);
            ensure!(
                back.as_ref().ok() == Some(&m),
                "a motion printed as `{again}` parses to {back:?}"
            );
        }
        Err(e) => ensure!(
            position_inside(text, e.line, e.column),
            "motion refused at line {}, column {}, outside its text: {e}",
            e.line,
            e.column
        ),
    }
    Ok(())
}

/// A motion program's text form: accepted (its printed form parses back equal), or
/// refused at a position inside the text.
pub fn program_text(data: &[u8]) -> Checked {
    let Some(text) = text_of(data) else {
        return Ok(());
    };
    match Program::parse(text) {
        Ok(p) => {
            let again = p.to_string();
            let back = Program::parse(&again);
            ensure!(
                back.as_ref().ok() == Some(&p),
                "a program printed as `{again}` parses to {back:?}"
            );
        }
        Err(e) => ensure!(
            position_inside(text, e.line, e.column),
            "program refused at line {}, column {}, outside its text: {e:?}",
            e.line,
            e.column
        ),
    }
    Ok(())
}

/// ID lists (`0-5,7`) of servos and joints: what parses lists IDs that parse back to the
/// same list when written one by one.
pub fn id_list(data: &[u8]) -> Checked {
    let Some(text) = text_of(data) else {
        return Ok(());
    };
    if let Ok(list) = text.parse::<IdList<ServoId>>() {
        let again: Vec<String> = list
            .as_slice()
            .iter()
            .map(|i| i.get().to_string())
            .collect();
        let back = again.join(",").parse::<IdList<ServoId>>();
        ensure!(
            back.as_ref().map(IdList::as_slice) == Ok(list.as_slice()),
            "`{text}` listed as `{}` parses to {back:?}",
            again.join(",")
        );
    }
    if let Ok(list) = text.parse::<IdList<JointId>>() {
        let again: Vec<String> = list
            .as_slice()
            .iter()
            .map(|i| i.get().to_string())
            .collect();
        let back = again.join(",").parse::<IdList<JointId>>();
        ensure!(
            back.as_ref().map(IdList::as_slice) == Ok(list.as_slice()),
            "`{text}` listed as `{}` parses to {back:?}",
            again.join(",")
        );
    }
    Ok(())
}

/// Register names and addresses (`SYS_ID`, `0x0A`): a register found by either is found
/// again by its name and by its address.
pub fn register_name(data: &[u8]) -> Checked {
    let Some(text) = text_of(data) else {
        return Ok(());
    };
    let text = text.get(..text.len().min(256)).unwrap_or(text);
    if let Ok((addr, Some(info))) = robobus::catalogue::whj::parse_register(text) {
        ensure!(
            info.addr == addr,
            "`{text}`: {} is not at {addr:?}",
            info.name
        );
        let by_name = robobus::catalogue::whj::parse_register(info.name);
        ensure!(
            matches!(by_name, Ok((a, _)) if a == addr),
            "`{text}` is {}, whose name finds {by_name:?}",
            info.name
        );
        let hex = format!("0x{:02X}", addr.get());
        let by_addr = robobus::catalogue::whj::parse_register(&hex);
        ensure!(
            matches!(by_addr, Ok((a, _)) if a == addr),
            "`{text}` is at {hex}, which finds {by_addr:?}"
        );
    }
    Ok(())
}
