//! Snapshot tests: `--help` of the top level and of every subcommand group, and the table /
//! JSON output of a few commands, against golden files in `tests/snapshots/`.
//!
//! Regenerate after an intended change with
//! `UPDATE_SNAPSHOTS=1 cargo test -p robobus-cli --test integration snapshots::`, then review the diff.

#![allow(clippy::unwrap_used, clippy::panic)] // test helpers: a failed unwrap is a failed test

use crate::common;

use std::path::PathBuf;

use common::ok;

fn snapshot_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/snapshots")
}

/// Compares `actual` with the golden file `name`, or writes it under `UPDATE_SNAPSHOTS=1`.
#[track_caller]
fn check(name: &str, actual: &str) {
    let path = snapshot_dir().join(name);
    if std::env::var_os("UPDATE_SNAPSHOTS").is_some_and(|v| v == "1") {
        std::fs::create_dir_all(snapshot_dir()).unwrap();
        std::fs::write(&path, actual).unwrap();
        return;
    }
    let expected = std::fs::read_to_string(&path).unwrap_or_else(|e| {
        panic!(
            "{}: {e}; create it with UPDATE_SNAPSHOTS=1 cargo test -p robobus-cli --test integration snapshots::",
            path.display()
        )
    });
    if expected != actual {
        let diff: Vec<String> = expected
            .lines()
            .zip(actual.lines())
            .enumerate()
            .filter(|(_, (e, a))| e != a)
            .take(5)
            .map(|(i, (e, a))| format!("line {}:\n  expected: {e}\n  actual:   {a}", i + 1))
            .collect();
        panic!(
            "{} differs ({} vs {} lines); first differences:\n{}\nIf intended: \
             UPDATE_SNAPSHOTS=1 cargo test -p robobus-cli --test integration snapshots::",
            path.display(),
            expected.lines().count(),
            actual.lines().count(),
            diff.join("\n")
        );
    }
}

#[test]
fn help_texts_match_their_snapshots() {
    let groups: &[&[&str]] = &[
        &[],
        &["wck"],
        &["wck", "get"],
        &["wck", "set"],
        &["wck", "program"],
        &["wck", "program", "check"],
        &["wck", "play"],
        &["wck", "move"],
        &["whj"],
        &["whj", "move"],
        &["whj", "write"],
        &["whj", "wave"],
        &["demo"],
        &["monitor"],
        &["plot"],
        &["doctor"],
        &["completions"],
        &["man"],
        &["sim"],
        &["bridge"],
    ];
    for group in groups {
        let mut args = group.to_vec();
        args.push("--help");
        let name = if group.is_empty() {
            "help.txt".to_owned()
        } else {
            format!("help-{}.txt", group.join("-"))
        };
        check(&name, &ok(&args));
    }
}

#[test]
fn dry_run_outputs_match_their_snapshots() {
    check(
        "dry-run-wck-move.json",
        &ok(&[
            "wck",
            "--port",
            "/dev/ttyUSB0",
            "--dry-run",
            "--json",
            "move",
            "3",
            "127",
        ]),
    );
    check(
        "dry-run-whj-enable.json",
        &ok(&["whj", "--bus", "can0", "--dry-run", "--json", "enable", "1"]),
    );
    check(
        "dry-run-whj-set-id.txt",
        &ok(&["whj", "--dry-run", "set-id", "1", "2"]),
    );
    check("whj-registers.txt", &ok(&["whj", "registers"]));
}
