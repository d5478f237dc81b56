//! The plan of a wCK operation: the packets it sends, in order, with the time each is due.

use std::fmt::Write as _;

use robobus_wck::{BaudRate, Command};
use serde::Serialize;

/// One wCK packet of a plan.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct WckStep {
    /// When it is due, ms after the start; `None` = right after the previous exchange.
    pub at_ms: Option<u64>,
    /// The baud rate it goes at, if the plan switches rates (`scan` over all rates).
    pub baud: Option<BaudRate>,
    /// The command.
    pub command: Command,
}

impl WckStep {
    /// A step sent right after the previous exchange.
    pub const fn now(command: Command) -> Self {
        Self {
            at_ms: None,
            baud: None,
            command,
        }
    }

    /// A step due `at_ms` ms after the start.
    pub const fn at(at_ms: u64, command: Command) -> Self {
        Self {
            at_ms: Some(at_ms),
            baud: None,
            command,
        }
    }

    /// The dry-run form of this step, for a bus at `baud`.
    pub fn packet(&self, baud: BaudRate) -> PlanPacket {
        let p = self.command.encode();
        PlanPacket {
            t_ms: self.at_ms,
            baud: self.baud.unwrap_or(baud).bits_per_second(),
            command: self.command.name(),
            target: self.command.target().to_string(),
            hex: p.to_string(),
            bytes: p.as_bytes().to_vec(),
            reply_len: self.command.reply_len(),
        }
    }
}

/// The packets a wCK operation sends, in order, and the notes that explain them (what a
/// device-dependent step assumed, how timed steps are paced).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct WckPlan {
    /// Notes (assumptions, pacing).
    pub notes: Vec<String>,
    /// The packets.
    pub steps: Vec<WckStep>,
}

/// One packet as a dry-run shows it (`--json`).
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct PlanPacket {
    /// When it is due, ms after the start (`null` = right after the previous exchange).
    pub t_ms: Option<u64>,
    /// The rate it goes at, bit/s.
    pub baud: u32,
    /// The manual's name of the command.
    pub command: &'static str,
    /// The servo, `all` for a broadcast.
    pub target: String,
    /// The bytes in hex, `FF 03 7F 7C`.
    pub hex: String,
    /// The bytes.
    pub bytes: Vec<u8>,
    /// How many reply bytes the command expects.
    pub reply_len: usize,
}

/// Where a dry-run says the packets would go.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct DryRunBus {
    /// Always `wck`.
    pub kind: &'static str,
    /// The port given (`(none)` without one).
    pub port: String,
    /// The rate, bit/s.
    pub baud: u32,
}

/// A dry-run: `{"dry_run": true, "bus", "notes", "packets"}`.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct DryRun {
    /// Always `true`.
    pub dry_run: bool,
    /// The bus.
    pub bus: DryRunBus,
    /// The plan's notes.
    pub notes: Vec<String>,
    /// The packets.
    pub packets: Vec<PlanPacket>,
}

impl WckPlan {
    /// A plan of one command.
    pub fn one(command: Command) -> Self {
        Self {
            notes: Vec::new(),
            steps: vec![WckStep::now(command)],
        }
    }

    /// Appends a command sent right after the previous exchange.
    pub fn push(&mut self, command: Command) {
        self.steps.push(WckStep::now(command));
    }

    /// Whether any step rewrites a servo's EEPROM (callers ask before running it).
    pub fn writes_eeprom(&self) -> bool {
        self.steps.iter().any(|s| s.command.writes_eeprom())
    }

    /// The text form: `# note` lines, then one packet per line in hex (`FF 03 7F 7C`);
    /// where the plan switches rates, a `# 4800 bit/s` line before the packets at it.
    pub fn to_text(&self) -> String {
        let mut s = String::new();
        for n in &self.notes {
            let _ = writeln!(s, "# {n}");
        }
        let mut baud = None;
        for step in &self.steps {
            step_line(&mut s, step, &mut baud);
        }
        s
    }

    /// The JSON form of a dry-run on `port` at `baud`.
    pub fn dry_run(&self, port: &str, baud: BaudRate) -> DryRun {
        DryRun {
            dry_run: true,
            bus: DryRunBus {
                kind: "wck",
                port: port.to_string(),
                baud: baud.bits_per_second(),
            },
            notes: self.notes.clone(),
            packets: self.steps.iter().map(|s| s.packet(baud)).collect(),
        }
    }
}

/// Appends the text line of one step (and a rate line where the rate changes).
pub fn step_line(s: &mut String, step: &WckStep, baud: &mut Option<BaudRate>) {
    if step.baud.is_some() && step.baud != *baud {
        if let Some(b) = step.baud {
            let _ = writeln!(s, "# {b}");
        }
        *baud = step.baud;
    }
    let _ = writeln!(s, "{}", step.command.encode());
}
