//! `whj.status`: each joint's status (0x600+ID), or one broadcast status frame (0x7F) for
//! joints 1..=7 and, with it, the end board.

use robobus_wck::BaudRate;
use robobus_whj::{JointId, Request as Wire};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::{JointRow, R, each, joint_list, plan_of};
use crate::catalogue::args::Ids;
use crate::catalogue::operation::{Confirm, OpDoc, Operation, Report, RunCx};
use crate::catalogue::plan::WhjSteps;
use crate::catalogue::wck::request;
use crate::catalogue::{Effect, Family, Plan};
use crate::ops::whj::{self as ops, EndBoardStatus, Slot, StatusReport};
use crate::ops::{DeviceResult, OpError};

request!(cli
    /// `whj.status` (0x600+ID, or one broadcast 0x7F frame).
    Status {
        /// Joint IDs, e.g. `1-7`.
        #[cfg_attr(feature = "cli", arg(value_parser = crate::catalogue::whj::cli::joints))]
        joints: Ids,
        /// Ask joints 1..=7 with one broadcast status frame (0x7F) instead of one query
        /// each; a joint that does not answer is named.
        #[serde(default)]
        #[cfg_attr(feature = "cli", arg(long))]
        broadcast: bool,
        /// With `broadcast`: the end board answers the same frame (IO modes and levels,
        /// buttons, gripper / hand in position, error byte).
        #[serde(default)]
        #[cfg_attr(feature = "cli", arg(long, requires = "broadcast"))]
        end_board: bool,
    }
);

/// One row of `whj.status`: a joint's status, or (broadcast with `end_board`) the end
/// board's, `id` `"end-board"`.
#[derive(Debug, Clone, PartialEq, Serialize, JsonSchema)]
#[serde(untagged)]
pub enum StatusRow {
    /// A joint's status, or its failure.
    Joint(JointRow<StatusReport>),
    /// The end board's state, or its failure.
    EndBoard(DeviceResult<Slot, EndBoardStatus>),
}

impl Status {
    /// The joints, validated as the run takes them, and the frames it sends.
    fn steps(&self) -> R<(Vec<JointId>, WhjSteps)> {
        if self.end_board && !self.broadcast {
            return Err(OpError::invalid("end_board", true, "needs broadcast"));
        }
        let ids = joint_list(&self.joints)?;
        if !self.broadcast {
            let steps = each(&ids, |joint| Wire::StatusQuery { joint });
            return Ok((ids, steps));
        }
        let mask = ops::reply_mask_with(&ids, self.end_board)?;
        let mut steps = WhjSteps::default();
        steps.push(Wire::BroadcastStatus(
            robobus_whj::broadcast::BroadcastStatus::new(mask),
        ));
        let joints: Vec<String> = mask.joints().map(|j| j.get().to_string()).collect();
        steps.notes.push(format!(
            "one broadcast status query, reply mask {:#X} (joints {}{}); a real run connects \
             each joint first",
            mask.get(),
            joints.join(","),
            if mask.selects_end_board() {
                " and the end board"
            } else {
                ""
            }
        ));
        Ok((ids, steps))
    }
}

impl Operation for Status {
    const OP: &'static str = "whj.status";
    const FAMILY: Family = Family::Whj;
    const DOC: OpDoc = OpDoc {
        args: "`joints`, `broadcast`, `end_board`",
        report: "per joint: `enabled`, `mode`, `position_deg`, `current_ma` (null in the \
                 12-byte layout), `voltage_v`, `temperature_c`, `brake`, `error`; with \
                 `end_board` a row `end-board`: `io1_output`, `io2_output`, `io1_high`, \
                 `io2_high`, `teach_button`, `replay_button`, `gripper_in_position`, \
                 `hand_in_position`, `error`",
        confirm: "-",
    };
    type Row = StatusRow;
    type Summary = ();

    fn bus(&self) -> Option<&str> {
        self.bus.as_deref()
    }

    fn effect(&self) -> Effect {
        Effect::Read
    }

    fn check(&self) -> Result<Confirm, OpError> {
        self.steps().map(|_| Confirm::NONE)
    }

    fn plan(&self, _baud: BaudRate) -> Result<Plan, OpError> {
        let (_, steps) = self.steps()?;
        Ok(plan_of(Self::OP, steps, true, Confirm::NONE))
    }

    fn run(&self, cx: &mut RunCx<'_, '_>) -> Result<Report<StatusRow, ()>, OpError> {
        let (ids, _) = self.steps()?;
        let port = cx.station.whj(self.bus())?;
        let (name, bus) = (port.name(), port.bus());
        if !self.broadcast {
            return Ok(joint_rows(Report::devices(
                Self::OP,
                name,
                ops::status(bus, &ids),
            )));
        }
        // Connect each joint first (IAP release, identity for the current scale), for one
        // request's reply budget; a silent one is named by the broadcast's result.
        ops::connect_for_broadcast(bus, &ids);
        if !self.end_board {
            let joints = ops::broadcast_status(bus, &ids)?;
            return Ok(joint_rows(Report::devices(Self::OP, name, joints)));
        }
        let (joints, board) = ops::broadcast_status_with_end_board(bus, &ids)?;
        let mut out = joint_rows(Report::devices(Self::OP, name, joints));
        let board = Report::devices(Self::OP, name, vec![board]);
        out.results
            .extend(board.results.into_iter().map(StatusRow::EndBoard));
        // The joints' failure first; the end board's only when they all answered.
        if out.failed.is_none() {
            out.failed = board.failed;
            out.error = board.error;
        }
        Ok(out)
    }
}

/// The joints' report as `whj.status` rows.
fn joint_rows(r: Report<JointRow<StatusReport>, ()>) -> Report<StatusRow, ()> {
    Report {
        op: r.op,
        bus: r.bus,
        results: r.results.into_iter().map(StatusRow::Joint).collect(),
        summary: r.summary,
        failed: r.failed,
        error: r.error,
    }
}
