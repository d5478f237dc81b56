//! `whj.end-board`: the end-effector board's typed operations and their plans;
//! [`ops`] runs them.

use robobus_wck::BaudRate;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::{R, plan_of};
use crate::catalogue::bounds::ConfirmClass;
use crate::catalogue::operation::{Confirm, OpDoc, Operation, Report, RunCx};
use crate::catalogue::plan::WhjSteps;
use crate::catalogue::wck::request;
use crate::catalogue::{Effect, Family, Moved, Plan};
use crate::ops::whj::broadcast::end_board::{self as ops, EndBoardSet, EndBoardState, Force};
use crate::ops::{DeviceResult, Failure, OpError};

/// What `whj.end-board` does.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
#[serde(rename_all = "lowercase")]
pub enum EndBoardAction {
    /// Read its state: model, version, tool power, the digital channels' direction and
    /// level, the buttons, the gripper's and the hand's "in position".
    Status,
    /// Switch the tool power (`volts`: 0, 12 or 24), verified.
    Power,
    /// Set a digital channel's direction (`channel` 1 or 2, `mode`), verified.
    Io,
    /// Read the force sensor's six raw values.
    Force,
}

/// A digital channel's direction.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
#[serde(rename_all = "lowercase")]
pub enum IoMode {
    /// Input.
    Input,
    /// Output.
    Output,
}

request!(cli
    /// `whj.end-board`: the end-effector board's typed operations (its state, tool power,
    /// a digital channel's direction, its force sensor). Switching the tool power on or a
    /// channel's direction needs `confirm`: it switches what is attached to the tool.
    EndBoard {
        /// `status`, `power` (with `volts`), `io` (with `channel` and `mode`) or `force`.
        action: EndBoardAction,
        /// `power`: the tool power, volts (0, 12 or 24).
        #[serde(default)]
        #[cfg_attr(feature = "cli", arg(long))]
        volts: Option<u8>,
        /// `io`: the digital channel, 1 or 2.
        #[serde(default)]
        #[cfg_attr(feature = "cli", arg(long))]
        channel: Option<u8>,
        /// `io`: the channel's direction, `input` or `output`.
        #[serde(default)]
        #[cfg_attr(feature = "cli", arg(long))]
        mode: Option<IoMode>,
        /// Confirms switching the tool power on or a channel's direction.
        #[serde(default)]
        #[cfg_attr(feature = "cli", arg(skip))]
        confirm: bool,
    }
);

/// What a run does.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Job {
    Status,
    Power(ops::ToolPower),
    Io(u8, bool),
    Force,
}

/// What the board answered: its state, a write's read-back, or its force sensor.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, JsonSchema)]
#[serde(untagged)]
pub enum EndBoardRow {
    /// `status`: its state.
    State(EndBoardState),
    /// `power`, `io`: the register written and what it reads back.
    Set(EndBoardSet),
    /// `force`: the force sensor's six raw values.
    Force(Force),
}

/// What switching something on the tool needs confirmed.
pub(crate) const END_BOARD_CONFIRM: &str = "This switches what is attached to the tool through the \
     end board (its power or a digital channel's direction).";

fn needs(option: &str, what: &str, allowed: &str) -> OpError {
    OpError::invalid(
        option,
        "(none)",
        format!("{what} needs {option}: {allowed}"),
    )
}

impl EndBoard {
    /// Its frames (a write's read-back included), what a run does, and the
    /// confirmation.
    fn prepare(&self) -> R<(WhjSteps, Job, Confirm)> {
        let mut p = WhjSteps::default();
        let (job, confirm) = match self.action {
            EndBoardAction::Status => {
                p.push(ops::frame(ops::read_op(0x02, 6)?)?);
                (Job::Status, false)
            }
            EndBoardAction::Force => {
                p.push(ops::frame(ops::read_op(ops::FORCE, 12)?)?);
                (Job::Force, false)
            }
            EndBoardAction::Power => {
                let power = ops::ToolPower::of_volts(
                    self.volts
                        .ok_or_else(|| needs("--volts", "power", "0, 12 or 24"))?,
                )?;
                p.push(ops::frame(ops::write_op(ops::TOOL_POWER, power.code())?)?);
                p.push(ops::frame(ops::read_op(ops::TOOL_POWER, 1)?)?);
                (Job::Power(power), power != ops::ToolPower::Off)
            }
            EndBoardAction::Io => {
                let channel = self
                    .channel
                    .ok_or_else(|| needs("--channel", "io", "1 or 2"))?;
                let output = self
                    .mode
                    .ok_or_else(|| needs("--mode", "io", "input or output"))?
                    == IoMode::Output;
                let index = ops::io_register(channel)?;
                p.push(ops::frame(ops::write_op(index, u16::from(output))?)?);
                p.push(ops::frame(ops::read_op(index, 1)?)?);
                (Job::Io(channel, output), true)
            }
        };
        p.notes.push(
            "the end board's field of the 0x0F broadcast register frame (no joint's slot is \
             used); it answers on 0xF7"
                .into(),
        );
        let confirm = if confirm {
            Confirm::of(ConfirmClass::Register, END_BOARD_CONFIRM)
        } else {
            Confirm::NONE
        };
        Ok((p, job, confirm))
    }
}

impl Operation for EndBoard {
    const OP: &'static str = "whj.end-board";
    const FAMILY: Family = Family::Whj;
    const DOC: OpDoc = OpDoc {
        args: "`action`: `status`, `power` (`volts`: 0, 12 or 24), `io` (`channel` 1 or 2, \
               `mode` `input` / `output`) or `force`",
        report: "one row `end-board`: its state (`model`, `version`, `tool_volts`, \
                 `io1_output`, `io2_output`, `io1_high`, `io2_high`, `teach_button`, \
                 `replay_button`, `gripper_in_position`, `hand_in_position`, `error`); a \
                 write's `register`, `read_back` and `meaning` (written, then read back); or \
                 the force sensor's `fx`, `fy`, `fz`, `mx`, `my`, `mz` (raw: the vendor does \
                 not document their unit). A board that does not answer is `no-device`",
        confirm: "register: tool power on, a channel's direction (power off needs none)",
    };
    type Row = DeviceResult<&'static str, EndBoardRow>;
    type Summary = ();

    fn bus(&self) -> Option<&str> {
        self.bus.as_deref()
    }

    fn effect(&self) -> Effect {
        match (self.action, self.volts) {
            (EndBoardAction::Status | EndBoardAction::Force, _) => Effect::Read,
            // Power on for a tool can make it move (a gripper).
            (EndBoardAction::Power, Some(v)) if v > 0 => Effect::Motion,
            _ => Effect::Configure,
        }
    }

    fn moved(&self) -> R<Option<Moved>> {
        // What the tool does is not a joint's motion: no device of the bus moves.
        self.prepare().map(|_| None)
    }

    fn confirmed(&self) -> bool {
        self.confirm
    }

    fn confirm(&mut self) {
        self.confirm = true;
    }

    fn check(&self) -> R<Confirm> {
        self.prepare().map(|(_, _, confirm)| confirm)
    }

    fn plan(&self, _baud: BaudRate) -> R<Plan> {
        let (p, _, confirm) = self.prepare()?;
        // Broadcast frames name no joint: no connect note comes of them.
        Ok(plan_of(Self::OP, p, true, confirm))
    }

    fn run(&self, cx: &mut RunCx<'_, '_>) -> Result<Report<Self::Row, ()>, OpError> {
        let (_, job, _) = self.prepare()?;
        let port = cx.station.whj(self.bus())?;
        let bus = port.bus();
        let value = match job {
            Job::Status => ops::state(bus).map(EndBoardRow::State),
            Job::Power(p) => ops::set_power(bus, p).map(EndBoardRow::Set),
            Job::Io(c, out) => ops::set_io(bus, c, out).map(EndBoardRow::Set),
            Job::Force => ops::force(bus).map(EndBoardRow::Force),
        };
        let row = match value {
            Ok(v) => DeviceResult::ok("end-board", v),
            Err(e) => DeviceResult::failed("end-board", Failure::from(&e)),
        };
        Ok(Report::devices(Self::OP, port.name(), vec![row]))
    }
}
