//! WHJ operations: what `robobus whj` does, as library calls any front end can make.
//!
//! Each operation takes typed, validated arguments and a connected [`JointBus`], and returns
//! a typed report. Operations on many joints return one [`DeviceResult`] per joint and carry
//! on past a silent one; the caller picks the exit code (the CLI: 3 when any was silent).
//! Long operations ([`run_move`], [`run_wave`]) take a [`Control`]; on stop they apply the
//! caller's [`SafeState`](super::SafeState) through
//! [`SafeState::apply`](super::SafeState::apply) (the same function the robot watchdog
//! uses) and return [`OpError::Interrupted`].
//!
//! One file per job: `joints.rs` (status, enable, clear, set-id, scan, info, modes, zero,
//! save, release-IAP, monitor samples), `checks.rs` (the safe state of an interrupted run,
//! the checks before any motion), `motion.rs` (moves and waves), `registers.rs` (register
//! reads and writes, speed and current targets), `broadcast.rs` (the broadcast protocol),
//! `stream.rs` (sending a plan's frames on time).
//!
//! # One plan
//!
//! [`plan_move`] and [`plan_wave`] compute every frame and its time once ([`Plan`]). A
//! dry-run shows the plan; the real run ([`run_move`], [`run_wave`]) sends the plan's servo
//! frames at the plan's times. A move depends on where the joint is: the dry run names the
//! start angle it assumed ([`Plan::assumed`]), the real run plans from the measured one
//! (after checking that it is plausible and within the joint's limits). While it runs, a
//! position set-point is held back when the joint lags further behind the plan than the
//! step limit allows (never a target beyond the joint's step protection from where it was
//! measured; counted as `held_back`); on a joint that follows, the frames are the plan's.
//! A run looks at its stop token while it plans (a slow move has up to
//! [`MAX_MOVE_FRAMES`]): a stop ends it there, the joint brought to its safe state before
//! any frame of the plan was sent ([`prepare_move_stoppable`], [`prepare_wave_stoppable`]).
//!
//! # Report schema (`--json`)
//!
//! Every report serializes to flat JSON objects whose field names carry their units
//! (`position_deg`, `speed_rpm`, `current_ma`, `voltage_v`, `temperature_c`); error bits are
//! text (`"no error"`, or the bit names joined by `, `). Per-joint results are
//! `{"id": N, ...fields}` for a joint that answered and `{"id": N, "kind", "error"}` for one
//! that did not ([`DeviceResult`]). The reports:
//!
//! - [`StatusReport`]: `enabled`, `mode`, `position_deg`, `current_ma` (null in the 12-byte
//!   layout), `voltage_v`, `temperature_c`, `brake` (`locked` / `released`), `error`;
//! - [`EnableReport`]: `enabled`, `error`; [`ClearReport`]: `error_before`, `error_after`;
//! - [`MoveReport`]: `from_deg`, `target_deg`, `position_deg` (a fresh reading after the
//!   move settled), `frames`, `seconds`, `step_limited` (the plan ran slower than asked so
//!   that no frame exceeds the step limit), `held_back` (frames held back to the step
//!   limit from the joint's measured position: it lagged; a move whose last set-point was
//!   held back sends the target again until it goes out unchanged), `error`;
//! - [`WaveReport`]: `cycles`, `complete`, `missing_replies`, `deadline_misses`, `overruns`, `clamped`
//!   (set-points the plan's step limiter changed because the wave asked for more speed or
//!   acceleration than allowed, or started away from the joint: none for a wave within the
//!   limits), `held_back` (set-points held back to the step limit from the joint's measured
//!   position because it lagged), `tracking_rms`, `tracking_max` (against the
//!   *requested* target, in the loop's unit), `last` (the last feedback, or null when none
//!   came), `stale` (true when the last cycle had no reply), `missing_at_end`,
//!   `round_trip_p50_us`, `round_trip_p99_us`, `round_trip_max_us` (send to feedback of the
//!   answered frames, credited at the end of the bus's collision window; null without
//!   replies);
//! - [`SetIdReport`]: `new_id`, `saved`, `note`.
//! - broadcast register reads and writes ([`broadcast_read`], [`broadcast_write`]): one
//!   [`RegisterReport`] per register and [`Slot`], whose `id` is the joint's number or
//!   `"end-board"` (the end board's registers by their names in its own map, raw values);
//!   a slot without a credited reply is `{"id", "kind": "no-device", "error"}`.

// OpError carries the client errors by value, as they do (see `ops::read_bounded`).
#![allow(clippy::result_large_err)]

use std::time::{Duration, Instant};

use robobus_whj::{JointId, Request, WorkMode};
use serde::Serialize;

use super::{Control, DeviceResult, Failure, OpError};
use crate::whj::{JointBus, WhjError};

/// A frame of a plan and when it goes out, from the start of the plan.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlannedFrame {
    /// Time from the first frame.
    pub at: Duration,
    /// The request.
    pub request: Request,
}

/// The frames an operation sends, with their times, and what it assumed.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Plan {
    /// Requests sent before the timed frames (reads the real run makes to plan).
    pub reads: Vec<Request>,
    /// The timed frames.
    pub frames: Vec<PlannedFrame>,
    /// The start angle the plan begins from (moves, position waves), degrees.
    pub start_deg: Option<f64>,
    /// What the plan assumed about the device (`start angle 0 deg`), if anything.
    pub assumed: Option<String>,
    /// Notes for a human (what the frames do, what the joint must be in).
    pub notes: Vec<String>,
}

/// The work mode that a servo loop needs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum ServoLoop {
    /// Position targets, degrees.
    Position,
    /// Speed targets, RPM.
    Speed,
    /// Current targets, mA.
    Current,
}

impl ServoLoop {
    /// The work mode this loop needs.
    pub const fn mode(self) -> WorkMode {
        match self {
            Self::Position => WorkMode::Position,
            Self::Speed => WorkMode::Speed,
            Self::Current => WorkMode::Current,
        }
    }

    /// The unit of its values.
    pub const fn unit(self) -> &'static str {
        match self {
            Self::Position => "deg",
            Self::Speed => "RPM",
            Self::Current => "mA",
        }
    }
}

/// A work mode as the CLI and the reports name it.
pub const fn mode_name(m: WorkMode) -> &'static str {
    match m {
        WorkMode::OpenLoop => "open-loop",
        WorkMode::Current => "current",
        WorkMode::Speed => "speed",
        WorkMode::Position => "position",
        WorkMode::Unknown(_) => "unknown",
    }
}

fn whj(e: WhjError) -> OpError {
    OpError::Whj(e)
}

/// Waits on the bus's clock until `deadline` unless stopped first; `false` when stopped.
fn pause_until(bus: &JointBus, control: &Control<'_>, deadline: Instant) -> bool {
    control.sleep_with(deadline, |until| {
        if let Some(t) = until {
            bus.sleep_until(t);
        }
        bus.now()
    })
}

fn per_joint<T>(
    ids: &[JointId],
    mut f: impl FnMut(JointId) -> Result<T, OpError>,
) -> Vec<DeviceResult<u8, T>> {
    ids.iter()
        .map(|&id| match f(id) {
            Ok(v) => DeviceResult::ok(id.get(), v),
            Err(e) => DeviceResult::failed(id.get(), Failure::from(&e)),
        })
        .collect()
}

// ---------------------------------------------------------------------------------------
// Broadcast frames (0x7F status, 0x0F registers, sampling)
// ---------------------------------------------------------------------------------------

pub mod broadcast;
mod checks;
mod joints;
mod motion;
pub mod rates;
mod registers;
pub mod settings;
mod stream;

pub use checks::*;
pub use joints::*;
pub use motion::*;
pub use registers::*;

#[cfg(feature = "sim")]
pub(crate) use stream::FrameTimes;
pub use stream::{SILENT_AFTER, SILENT_FRAMES, STALL_AFTER, TEMPERATURE_EVERY, check_plan_steps};

pub use broadcast::{
    BROADCAST_WAVE_MIN_HZ, BroadcastPlan, EndBoardArg, EndBoardStatus, SECOND_ANSWER_GUARD, Slot,
    StatusWithEndBoard, broadcast_read, broadcast_status, broadcast_status_with_end_board,
    broadcast_window, broadcast_write, connect_for_broadcast, plan_broadcast_read,
    plan_broadcast_wave, plan_broadcast_write, prepare_broadcast_wave, reply_mask, reply_mask_with,
    run_broadcast_plan, sample_broadcast,
};
