//! The frames of a velocity or effort command: a wCK wheel command is sent at once; a WHJ
//! speed or current servo frame is made first, then sent with the other joints' frames
//! of its bus in one batch (`JointBus::servo_many`), so that each reply's duplicate check
//! overlaps the other joints' frames.

use std::f64::consts::TAU;

use robobus_whj::units::{Current, TargetSpeed};
use robobus_whj::{Request, ServoFeedback};

use super::{Joint, Slot, Units, joint_id, refused, servo_id};
use crate::actuator::rpm_to_rad_s;
use crate::ops::{Failure, OpError};
use crate::robot::Interface;
use crate::station::Station;

/// A joint's frame for one command.
pub(super) enum Frame {
    /// A wCK wheel command, sent: the speed it carries (rad/s).
    Sent(f64),
    /// A WHJ servo frame to send, and what it carries (rad/s or N·m).
    Whj { frame: Request, carried: f64 },
}

fn sign(reversed: bool) -> f64 {
    if reversed { -1.0 } else { 1.0 }
}

/// The frame that carries `value` (rad/s or N·m) to a joint on `interface`: a wCK wheel
/// command is sent now (and where the servo reported itself recorded), a WHJ frame made.
pub(super) fn frame(
    station: &Station,
    j: &Joint,
    s: &mut Slot,
    interface: Interface,
    value: f64,
) -> Result<Frame, OpError> {
    match (&j.units, interface) {
        (Units::Wck(scale, Some(wheel)), Interface::Velocity) => {
            let (rotation, level, speed) = wheel.command(value, scale.map.reversed);
            let port = station.wck(Some(&j.bus))?;
            let st = port.lock().servo(servo_id(j)?).wheel(rotation, level)?;
            s.at = Some(scale.to_rad(st.position));
            Ok(Frame::Sent(speed))
        }
        (Units::Whj(map), Interface::Velocity) => {
            let rpm = value * sign(map.reversed) * 60.0 / TAU;
            let target =
                TargetSpeed::from_rpm(rpm).map_err(|e| refused(&j.name, value, e.to_string()))?;
            Ok(Frame::Whj {
                frame: Request::SpeedServo {
                    joint: joint_id(j)?,
                    target,
                },
                carried: rpm_to_rad_s(target.rpm()) * sign(map.reversed),
            })
        }
        (Units::Whj(map), Interface::Effort) => {
            let Some((current, Some(k))) = s.whj else {
                return Err(OpError::Refused(format!(
                    "{}: no torque constant known for its model",
                    j.name
                )));
            };
            let ma = value / k.nm_per_a * 1e3 * sign(map.reversed);
            let target = Current::from_milliamps(ma, current)
                .map_err(|e| refused(&j.name, value, e.to_string()))?;
            #[allow(clippy::cast_precision_loss)] // mA of a joint
            let sent_ma = target.milliamps(current) as f64;
            Ok(Frame::Whj {
                frame: Request::CurrentServo {
                    joint: joint_id(j)?,
                    target,
                },
                carried: sent_ma / 1e3 * k.nm_per_a * sign(map.reversed),
            })
        }
        _ => Err(OpError::Refused(format!(
            "{}: has no {interface} interface",
            j.name
        ))),
    }
}

/// Records where a WHJ joint reported itself in its servo frame's feedback.
pub(super) fn record(j: &Joint, s: &mut Slot, fb: &ServoFeedback) {
    let Units::Whj(map) = &j.units else {
        return;
    };
    s.at = Some(map.to_joint(fb.position.degrees().to_radians()));
    s.speed_deg_s = Some(fb.speed.rpm() * 6.0 * sign(map.reversed));
    s.current_a = s.whj.map(|(scale, _)| {
        #[allow(clippy::cast_precision_loss)] // mA of a joint
        let ma = fb.current.milliamps(scale) as f64;
        ma / 1e3
    });
}

/// Sends `frames` on WHJ bus `bus` in one batch: each one's feedback, or its failure (a
/// failure of the whole batch is each frame's).
pub(super) fn send_whj(
    station: &Station,
    bus: &str,
    frames: &[Request],
) -> Vec<Result<ServoFeedback, Failure>> {
    let all = |e: OpError| {
        let f = Failure::from(&e);
        frames.iter().map(|_| Err(f.clone())).collect()
    };
    let port = match station.whj(Some(bus)) {
        Ok(p) => p,
        Err(e) => return all(e),
    };
    match port.bus().servo_many(frames) {
        Ok(answers) => answers
            .into_iter()
            .map(|a| a.map_err(|e| Failure::from(&OpError::from(e))))
            .collect(),
        Err(e) => all(OpError::from(e)),
    }
}

/// Sends `value` (rad/s or N·m) to one joint on `interface`: what it carries at the
/// device's resolution; records where the joint reported itself.
pub(super) fn send(
    station: &Station,
    j: &Joint,
    s: &mut Slot,
    interface: Interface,
    value: f64,
) -> Result<f64, OpError> {
    match frame(station, j, s, interface, value)? {
        Frame::Sent(carried) => Ok(carried),
        Frame::Whj { frame, carried } => {
            let port = station.whj(Some(&j.bus))?;
            let fb = port
                .bus()
                .joint_unchecked(joint_id(j)?)
                .servo_request(frame)?;
            record(j, s, &fb);
            Ok(carried)
        }
    }
}
