//! The one place where a planned command meets a device.
//!
//! Every `robobus wck` / `robobus whj` subcommand validates its arguments and builds a plan
//! ([`robobus::ops::wck::WckPlan`] / [`crate::output::WhjPlan`]) before anything is opened.
//! `--dry-run` prints the plan; otherwise the plan comes here, to [`execute`].
//!
//! - wCK plans run through the library's operations ([`robobus::ops::wck`]): see [`wck`]
//!   for how each report is rendered.
//! - WHJ plans run through [`robobus::whj::JointBus`]: see [`whj`] (the plan is what
//!   `--dry-run` prints; the run is the typed [`whj::WhjRun`]).

use std::io::{BufRead as _, IsTerminal as _, Write as _};

use crate::exit::usage;
use robobus::ops::wck::WckPlan;

pub(crate) mod wck;

/// A validated plan and the bus it is for.
#[derive(Debug)]
pub(crate) enum Job<'a> {
    /// wCK servos on a serial port.
    Wck {
        /// The subcommand (for messages), e.g. `"move"`.
        action: &'static str,
        /// Serial port path.
        port: &'a str,
        /// Baud rate.
        baud: robobus_wck::BaudRate,
        /// `--reply-margin`, if given.
        margin: Option<core::time::Duration>,
        /// Equal replies a read needs (`--verify-reads`).
        confirm_reads: u8,
        /// `--capture FILE`: log every byte written and read.
        capture: Option<&'a std::path::Path>,
        /// What to send.
        plan: &'a WckPlan,
        /// How to run the plan (one exchange per step, or a scan / teach / play loop).
        run: wck::WckRun,
        /// `--json`: one JSON document on stdout instead of a table.
        json: bool,
    },
}

impl Job<'_> {
    /// Whether the plan rewrites a device's non-volatile memory (wCK EEPROM, WHJ flash).
    pub(crate) fn rewrites_memory(&self) -> bool {
        match self {
            Job::Wck { plan, .. } => plan.writes_eeprom(),
        }
    }

    /// What the plan does that needs a confirmation (non-volatile memory, or a WHJ register
    /// of the `confirm` safety class: bit rates, IAP, brake, calibration, ...), if anything.
    pub(crate) fn needs_confirmation(&self) -> Option<String> {
        self.rewrites_memory()
            .then(|| "This rewrites the device's non-volatile memory (EEPROM / flash).".to_owned())
    }
}

/// Asks before a plan that rewrites non-volatile memory: `--yes` skips the question; on a
/// terminal the user answers y/N; without a terminal the command is refused (exit 2).
pub(crate) fn confirm(job: &Job<'_>, yes: bool) -> anyhow::Result<()> {
    let Some(what) = job.needs_confirmation() else {
        return Ok(());
    };
    if yes {
        return Ok(());
    }
    let stdin = std::io::stdin();
    if !stdin.is_terminal() {
        return Err(usage(format!(
            "{what} Confirm with --yes; nothing was sent"
        )));
    }
    let mut err = std::io::stderr().lock();
    let _ = write!(err, "{what} Continue? [y/N] ");
    let _ = err.flush();
    let mut answer = String::new();
    stdin.lock().read_line(&mut answer)?;
    if matches!(answer.trim(), "y" | "Y" | "yes" | "YES") {
        Ok(())
    } else {
        Err(usage("not confirmed; nothing was sent"))
    }
}

/// Runs a plan on a real (or simulated) device, after [`confirm`] where the plan
/// rewrites non-volatile memory.
pub(crate) fn execute(job: &Job<'_>, yes: bool) -> anyhow::Result<()> {
    confirm(job, yes)?;
    match job {
        Job::Wck {
            action,
            port,
            baud,
            margin,
            confirm_reads,
            capture,
            plan,
            run,
            json,
        } => wck::execute(&wck::WckJob {
            action,
            port,
            baud: *baud,
            margin: *margin,
            confirm_reads: *confirm_reads,
            capture: *capture,
            plan,
            run,
            json: *json,
        }),
    }
}
