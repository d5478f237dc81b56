//! Helpers shared by the CLI tests: run the built `robobus` binary.

#![allow(dead_code)] // each test file uses a different subset

use std::process::{Command, Output, Stdio};

/// The result of one run.
#[derive(Debug)]
pub(crate) struct Run {
    /// Exit code (`None` if killed by a signal).
    pub(crate) code: Option<i32>,
    /// Standard output.
    pub(crate) stdout: String,
    /// Standard error.
    pub(crate) stderr: String,
}

impl From<Output> for Run {
    fn from(o: Output) -> Self {
        Self {
            code: o.status.code(),
            stdout: String::from_utf8_lossy(&o.stdout).into_owned(),
            stderr: String::from_utf8_lossy(&o.stderr).into_owned(),
        }
    }
}

/// Runs `robobus ARGS` with a clean logging environment.
pub(crate) fn robobus(args: &[&str]) -> Run {
    Command::new(env!("CARGO_BIN_EXE_robobus"))
        .args(args)
        .env_remove("RUST_LOG")
        .env("COLUMNS", "100")
        .stdin(Stdio::null())
        .output()
        .expect("robobus runs")
        .into()
}

/// Runs `robobus ARGS` and requires exit code 0; returns stdout.
#[track_caller]
pub(crate) fn ok(args: &[&str]) -> String {
    let r = robobus(args);
    assert_eq!(r.code, Some(0), "robobus {args:?} failed: {r:#?}");
    r.stdout
}

/// The non-comment lines of a dry-run's text output.
pub(crate) fn lines(stdout: &str) -> Vec<&str> {
    stdout
        .lines()
        .filter(|l| !l.starts_with('#') && !l.is_empty())
        .collect()
}
