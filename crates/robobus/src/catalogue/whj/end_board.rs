//! `whj.end-board`: the end-effector board's typed operations and their plans;
//! [`ops::broadcast::end_board`] runs them.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::{Job, Prepared, R, prepared};
use crate::catalogue::bounds::ConfirmClass;
use crate::catalogue::plan::WhjSteps;
use crate::catalogue::wck::request;
use crate::ops::OpError;
use crate::ops::whj::broadcast::end_board as ops;

/// What `whj.end-board` does.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
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
#[serde(rename_all = "lowercase")]
pub enum IoMode {
    /// Input.
    Input,
    /// Output.
    Output,
}

request!(
    /// `whj.end-board`: the end-effector board's typed operations (its state, tool power,
    /// a digital channel's direction, its force sensor). Switching the tool power on or a
    /// channel's direction needs `confirm`: it switches what is attached to the tool.
    EndBoard {
        /// `status`, `power`, `io` or `force`.
        action: EndBoardAction,
        /// `power`: the tool power, volts (0, 12 or 24).
        #[serde(default)]
        volts: Option<u8>,
        /// `io`: the digital channel, 1 or 2.
        #[serde(default)]
        channel: Option<u8>,
        /// `io`: `input` or `output`.
        #[serde(default)]
        mode: Option<IoMode>,
        /// Confirms switching the tool power on or a channel's direction.
        #[serde(default)]
        confirm: bool,
    }
);

/// What a run does.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum EndBoardJob {
    Status,
    Power(ops::ToolPower),
    Io(u8, bool),
    Force,
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

/// `whj.end-board`: its frames (a write's read-back included) and the confirmation.
pub(super) fn end_board(r: &EndBoard) -> R<Prepared> {
    let mut p = WhjSteps::default();
    let (job, confirm) = match r.action {
        EndBoardAction::Status => {
            p.push(ops::frame(ops::read_op(0x02, 6)?)?);
            (EndBoardJob::Status, false)
        }
        EndBoardAction::Force => {
            p.push(ops::frame(ops::read_op(ops::FORCE, 12)?)?);
            (EndBoardJob::Force, false)
        }
        EndBoardAction::Power => {
            let power = ops::ToolPower::of_volts(
                r.volts
                    .ok_or_else(|| needs("--volts", "power", "0, 12 or 24"))?,
            )?;
            p.push(ops::frame(ops::write_op(ops::TOOL_POWER, power.code())?)?);
            p.push(ops::frame(ops::read_op(ops::TOOL_POWER, 1)?)?);
            (EndBoardJob::Power(power), power != ops::ToolPower::Off)
        }
        EndBoardAction::Io => {
            let channel = r
                .channel
                .ok_or_else(|| needs("--channel", "io", "1 or 2"))?;
            let output = r
                .mode
                .ok_or_else(|| needs("--mode", "io", "input or output"))?
                == IoMode::Output;
            let index = ops::io_register(channel)?;
            p.push(ops::frame(ops::write_op(index, u16::from(output))?)?);
            p.push(ops::frame(ops::read_op(index, 1)?)?);
            (EndBoardJob::Io(channel, output), true)
        }
    };
    p.notes.push(
        "the end board's field of the 0x0F broadcast register frame (no joint's slot is \
         used); it answers on 0xF7"
            .into(),
    );
    let mut pr = prepared(p, Job::EndBoard(job));
    if confirm {
        pr.confirm = ConfirmClass::Register;
        pr.confirm_text = END_BOARD_CONFIRM.into();
        pr.confirmed = r.confirm;
    }
    Ok(pr)
}
