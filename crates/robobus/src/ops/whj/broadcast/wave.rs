//! Broadcast waves: a wave's servo frames sent as 0x2F position or 0x4F current frames.

use robobus_whj::Request;
use robobus_whj::broadcast::{BroadcastCurrent, BroadcastPosition, ReplyMask};
use robobus_whj::units::CurrentScale;

use crate::ops::OpError;
use crate::ops::whj::{Plan, ServoLoop, WaveArgs, plan_wave, prepare_wave};
use crate::whj::Joint;

/// The lowest frame rate of a broadcast wave: a joint that gets no 0x2F frame for 20 ms
/// stops by itself (the communication watchdog of broadcast position servo), so frames
/// must never be more than 10 ms apart.
pub const BROADCAST_WAVE_MIN_HZ: f64 = 100.0;

/// The point-to-point servo frames of a wave plan as broadcast frames: position targets in
/// 0x2F, currents in 0x4F, the joint's slot only, reply mask "this joint". Speed waves
/// have no broadcast frame.
fn as_broadcast(mut plan: Plan, args: &WaveArgs) -> Result<Plan, OpError> {
    let joint = args.joint;
    let mask = ReplyMask::only(joint).ok_or_else(|| {
        OpError::invalid(
            "wave <JOINT> --broadcast",
            joint.get(),
            "broadcast frames address joints 1..=7 only",
        )
    })?;
    match args.servo {
        ServoLoop::Speed => {
            return Err(OpError::invalid(
                "wave --mode --broadcast",
                "speed",
                "the broadcast protocol has position (0x2F) and current (0x4F) frames only",
            ));
        }
        ServoLoop::Position if args.rate_hz < BROADCAST_WAVE_MIN_HZ => {
            return Err(OpError::invalid(
                "--rate-hz",
                args.rate_hz,
                format!(
                    "{BROADCAST_WAVE_MIN_HZ}..=1000 with --broadcast: a joint stops a \
                     broadcast position stream after 20 ms without a frame"
                ),
            ));
        }
        _ => {}
    }
    let no_data = || OpError::invalid("wave", "value", "a target that reads as \"no data\"");
    for f in &mut plan.frames {
        f.request = match f.request {
            Request::PositionServo { target, .. } => Request::BroadcastPosition(
                BroadcastPosition::new(mask)
                    .with_target(joint, target)
                    .ok_or_else(no_data)?,
            ),
            Request::CurrentServo { target, .. } => Request::BroadcastCurrent(
                BroadcastCurrent::new(mask)
                    .with_target(joint, target)
                    .ok_or_else(no_data)?,
            ),
            other => other,
        };
    }
    plan.notes.push(format!(
        "sent as broadcast {} frames (reply mask {:#X}: joint {} answers); the joint stops by \
         itself 20 ms after the last position frame, holding where it is",
        if args.servo == ServoLoop::Position {
            "position (0x2F)"
        } else {
            "current (0x4F)"
        },
        mask.get(),
        joint.get()
    ));
    Ok(plan)
}

/// `whj wave --broadcast` dry run: [`plan_wave`] as broadcast frames.
pub fn plan_broadcast_wave(
    args: &WaveArgs,
    from_deg: f64,
    scale: CurrentScale,
    assumed: bool,
) -> Result<Plan, OpError> {
    as_broadcast(plan_wave(args, from_deg, scale, assumed)?, args)
}

/// `whj wave --broadcast`: [`prepare_wave`] (the same checks and start position) as
/// broadcast frames; run it with [`execute_wave`](crate::ops::whj::execute_wave).
pub fn prepare_broadcast_wave(j: &Joint<'_>, args: &WaveArgs) -> Result<Plan, OpError> {
    as_broadcast(prepare_wave(j, args)?, args)
}
