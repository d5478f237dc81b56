//! The one place where a planned command meets a device.
//!
//! Every `robobus wck` / `robobus whj` subcommand validates its arguments and builds a plan
//! ([`crate::output::WckPlan`] / [`crate::output::WhjPlan`]) before anything is opened.
//! `--dry-run` prints the plan; otherwise the plan comes here, to [`execute`].
//!
//! The client library (`robobus`: `WckBus` / `Servo`, `JointBus` / `Joint`) is not part
//! of this build yet, so [`execute`] refuses with [`NotAvailable`] (exit code 4) instead of
//! pretending. Wiring the client in replaces the body of [`execute`]: open the bus named
//! in [`Job`], run the plan's commands through the client, print the replies.

use std::io::{BufRead as _, IsTerminal as _, Write as _};

use robobus_whj::{Request, registers};

use crate::exit::{NotAvailable, usage};
use crate::output::{WckPlan, WhjPlan};

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
        /// What to send.
        plan: &'a WckPlan,
    },
    /// WHJ joints on a CAN FD bus.
    Whj {
        /// The subcommand, e.g. `"enable"`.
        action: &'static str,
        /// The bus as given (`udp`, `udp:GROUP:PORT`, `can0`).
        bus: &'a str,
        /// What to send.
        plan: &'a WhjPlan,
    },
}

impl Job<'_> {
    /// Whether the plan rewrites a device's non-volatile memory (wCK EEPROM, WHJ flash).
    pub(crate) fn rewrites_memory(&self) -> bool {
        match self {
            Job::Wck { plan, .. } => plan.steps.iter().any(|s| s.command.writes_eeprom()),
            Job::Whj { plan, .. } => plan.steps.iter().any(|s| {
                matches!(s.request, Request::Write { addr, .. }
                    if addr == registers::addr::SYS_SAVE_TO_FLASH || addr == registers::addr::SYS_ID)
            }),
        }
    }
}

/// Asks before a plan that rewrites non-volatile memory: `--yes` skips the question; on a
/// terminal the user answers y/N; without a terminal the command is refused (exit 2).
pub(crate) fn confirm(job: &Job<'_>, yes: bool) -> anyhow::Result<()> {
    if yes || !job.rewrites_memory() {
        return Ok(());
    }
    let stdin = std::io::stdin();
    if !stdin.is_terminal() {
        return Err(usage(
            "this command rewrites the device's non-volatile memory (EEPROM / flash); \
             confirm with --yes",
        ));
    }
    let mut err = std::io::stderr().lock();
    let _ = write!(
        err,
        "This rewrites the device's non-volatile memory (EEPROM / flash). Continue? [y/N] "
    );
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
    let (what, action) = match job {
        Job::Wck {
            action,
            port,
            baud,
            plan,
        } => {
            tracing::debug!(%port, %baud, packets = plan.steps.len(), "wck plan");
            (format!("robobus wck --port {port}"), *action)
        }
        Job::Whj { action, bus, plan } => {
            tracing::debug!(%bus, frames = plan.steps.len(), "whj plan");
            (format!("robobus whj --bus {bus}"), *action)
        }
    };
    Err(anyhow::Error::new(NotAvailable(format!(
        "`{what} {action}` is not yet available: it needs the robobus client library, which \
         this build does not include yet. Nothing was opened or sent. Use --dry-run to see \
         the exact bytes / frames it would send."
    ))))
}
