//! The 0x7F status query: `whj status --broadcast` (with the end board's state) and
//! `monitor --broadcast`'s sampling, one frame for joints 1..=7.

use core::time::Duration;

use robobus_whj::broadcast::{BroadcastStatus, EndBoardReply};
use robobus_whj::{Address, BroadcastFeedback, JointId, Reply, Request};
use serde::Serialize;

use super::{Slot, collect, reply_mask_with, scale_of, silent};
use crate::ops::whj::{JointSample, StatusReport, check_reading, whj};
use crate::ops::{DeviceResult, Failure, OpError};
use crate::whj::JointBus;

/// One answer to a 0x7F frame.
#[derive(Debug, PartialEq)]
enum Answer {
    Joint(BroadcastFeedback),
    EndBoard(EndBoardReply),
}

/// One 0x7F frame to joints `ids` (and the end board); each joint's 24-byte feedback and
/// the end board's reply, `None` when none came.
#[allow(clippy::type_complexity)] // one result per slot, and the end board's
fn status_query(
    bus: &JointBus,
    ids: &[JointId],
    end_board: bool,
) -> Result<
    (
        Vec<Result<Option<BroadcastFeedback>, Failure>>,
        Result<Option<EndBoardReply>, Failure>,
    ),
    OpError,
> {
    let mask = reply_mask_with(ids, end_board)?;
    let sent = bus
        .send_broadcast(Request::BroadcastStatus(BroadcastStatus::new(mask)))
        .map_err(whj)?;
    let mut slots: Vec<Slot> = ids.iter().map(|&j| Slot::Joint(j)).collect();
    if end_board {
        slots.push(Slot::EndBoard);
    }
    let mut found = collect(bus, sent, &slots, |slot, f| match slot {
        Slot::Joint(id) => match Reply::from_frame(f) {
            Ok(Reply::BroadcastFeedback { joint, feedback }) if joint == id => {
                Some(Answer::Joint(feedback))
            }
            _ => None,
        },
        Slot::EndBoard => (f.standard_raw_id().map(Address::from_raw)
            == Some(Address::EndBoardFeedback))
        .then(|| EndBoardReply::decode(f.data()).map(Answer::EndBoard))
        .flatten(),
    });
    let board = if end_board {
        match found.pop() {
            Some(Ok(Some(Answer::EndBoard(r)))) => Ok(Some(r)),
            Some(Err(f)) => Err(f),
            _ => Ok(None),
        }
    } else {
        Ok(None)
    };
    let joints = found
        .into_iter()
        .map(|a| match a {
            Ok(Some(Answer::Joint(f))) => Ok(Some(f)),
            Err(f) => Err(f),
            _ => Ok(None),
        })
        .collect();
    Ok((joints, board))
}

/// One 0x7F frame; each joint's report made by `report` from its feedback, or a
/// no-device failure.
fn per_joint_status<T>(
    bus: &JointBus,
    ids: &[JointId],
    report: impl Fn(JointId, &BroadcastFeedback) -> T,
) -> Result<Vec<DeviceResult<u8, T>>, OpError> {
    let (found, _) = status_query(bus, ids, false)?;
    Ok(joint_results(bus, ids, found, report))
}

fn joint_results<T>(
    bus: &JointBus,
    ids: &[JointId],
    found: Vec<Result<Option<BroadcastFeedback>, Failure>>,
    report: impl Fn(JointId, &BroadcastFeedback) -> T,
) -> Vec<DeviceResult<u8, T>> {
    ids.iter()
        .zip(found)
        .map(|(&id, fb)| match fb {
            Err(failure) => DeviceResult::failed(id.get(), failure),
            // The joint's limits are read once per bus (a joint the broadcast reached but
            // the bus never spoke to costs one register read here, the first time).
            Ok(Some(f)) => match check_reading(
                &bus.joint_unchecked(id),
                f.position.degrees(),
                Some(f.speed.rpm()),
            ) {
                Ok(()) => DeviceResult::ok(id.get(), report(id, &f)),
                Err(e) => DeviceResult::failed(id.get(), Failure::from(&e)),
            },
            Ok(None) => {
                DeviceResult::failed(id.get(), silent(Slot::Joint(id), "status query", bus))
            }
        })
        .collect()
}

fn status_report(bus: &JointBus, id: JointId, f: &BroadcastFeedback) -> StatusReport {
    StatusReport {
        enabled: f.is_enabled(),
        mode: "-",
        position_deg: f.position.degrees(),
        current_ma: Some(f.current.milliamps(scale_of(bus, id))),
        voltage_v: f64::from(f.voltage.volts()),
        temperature_c: f64::from(f.temperature.celsius()),
        brake: if f.brake_locked() {
            "locked"
        } else {
            "released"
        },
        error: f.error.to_string(),
    }
}

/// Connects joints `ids` before a broadcast (IAP releases pipelined, identities read for
/// their current scales), waiting for them only as long as one point-to-point request
/// waits with its retries (`connect_budget`), not the connect timeout (5 s, for joints
/// that power up late): a joint in its bootloader answers the release at once, and a
/// status query reports what answers now. Absent joints cost that budget once in all,
/// not once each; they are named by the broadcast's own result (as silent). Returns how
/// many connected.
pub fn connect_for_broadcast(bus: &JointBus, ids: &[JointId]) -> usize {
    bus.joints_within(ids, connect_budget(bus))
        .iter()
        .filter(|j| j.is_ok())
        .count()
}

/// How long [`connect_for_broadcast`] waits for joints that do not answer: the reply
/// timeout times the attempts of a point-to-point request (`reply_timeout × (retries +
/// 1)`): the IAP release is sent that many times, each waiting one reply timeout (70 ms
/// by default, with the 5 ms between releases).
fn connect_budget(bus: &JointBus) -> Duration {
    let config = bus.config();
    config
        .reply_timeout
        .saturating_mul(config.retries.saturating_add(1))
}

/// `whj status --broadcast`: one 0x7F frame asks joints `ids` (1..=7) for their status;
/// every joint is reported, one that did not answer within
/// [`broadcast_window`](super::broadcast_window) as a no-device failure. Joints outside `ids`
/// that the mask also selects are not reported.
pub fn broadcast_status(
    bus: &JointBus,
    ids: &[JointId],
) -> Result<Vec<DeviceResult<u8, StatusReport>>, OpError> {
    per_joint_status(bus, ids, |id, f| status_report(bus, id, f))
}

/// The end board's state in its answer to a status query (status0 bits, §8.10).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, schemars::JsonSchema)]
#[allow(clippy::struct_excessive_bools)] // eight independent status bits, as JSON booleans
pub struct EndBoardStatus {
    /// Digital channel 1 is an output.
    pub io1_output: bool,
    /// Digital channel 2 is an output.
    pub io2_output: bool,
    /// Digital channel 1 is high.
    pub io1_high: bool,
    /// Digital channel 2 is high.
    pub io2_high: bool,
    /// The teach button is pressed.
    pub teach_button: bool,
    /// The replay button is pressed.
    pub replay_button: bool,
    /// The gripper reports "in position".
    pub gripper_in_position: bool,
    /// The dexterous hand reports "in position".
    pub hand_in_position: bool,
    /// The board's system error byte, hex.
    pub error: String,
}

impl EndBoardStatus {
    /// The state in a reply's status bytes.
    pub fn of(r: &EndBoardReply) -> Self {
        let bit = |n: u8| r.status0 & (1 << n) != 0;
        Self {
            io1_output: bit(7),
            io2_output: bit(6),
            teach_button: bit(5),
            replay_button: bit(4),
            io1_high: bit(3),
            gripper_in_position: bit(2),
            hand_in_position: bit(1),
            io2_high: bit(0),
            error: format!("0x{:02X}", r.sys_error),
        }
    }
}

/// The joints' and the end board's results of one status query.
pub type StatusWithEndBoard = (
    Vec<DeviceResult<u8, StatusReport>>,
    DeviceResult<Slot, EndBoardStatus>,
);

/// `whj status --broadcast --end-board`: [`broadcast_status`] and, in the same 0x7F frame,
/// the end board's state (or a no-device failure when it did not answer).
pub fn broadcast_status_with_end_board(
    bus: &JointBus,
    ids: &[JointId],
) -> Result<StatusWithEndBoard, OpError> {
    let (found, board) = status_query(bus, ids, true)?;
    let joints = joint_results(bus, ids, found, |id, f| status_report(bus, id, f));
    let board = match board {
        Ok(Some(r)) => DeviceResult::ok(Slot::EndBoard, EndBoardStatus::of(&r)),
        Ok(None) => {
            DeviceResult::failed(Slot::EndBoard, silent(Slot::EndBoard, "status query", bus))
        }
        Err(failure) => DeviceResult::failed(Slot::EndBoard, failure),
    };
    Ok((joints, board))
}

/// `monitor --broadcast`: samples joints `ids` (1..=7) with one 0x7F frame, instead of
/// two point-to-point frames per joint ([`sample`](crate::ops::whj::sample)). A joint that
/// does not answer is a failed result: the caller marks it missing.
pub fn sample_broadcast(
    bus: &JointBus,
    ids: &[JointId],
) -> Result<Vec<DeviceResult<u8, JointSample>>, OpError> {
    per_joint_status(bus, ids, |id, f| JointSample {
        position_deg: f.position.degrees(),
        speed_rpm: Some(f.speed.rpm()),
        current_ma: Some(f.current.milliamps(scale_of(bus, id))),
        enabled: f.is_enabled(),
        error: f.error.to_string(),
    })
}
