//! Following a robot's joint targets: what a position command stream sends again and
//! again (a ROS 2 forward position controller through the Zenoh bridge, a teleoperation
//! master).
//!
//! A command is one target per joint of the station's robot file, in the file's order, in
//! joint radians. [`Follower::plan`] checks the whole command before anything is sent:
//! the count, that every target is a finite number, that it lies within the joint's soft
//! limits (the file's `limits`) and, for a wCK joint, within the servo's 0..=254 steps. A
//! command that fails any check is refused whole: never half applied. [`Follower::apply`]
//! then steps every joint toward its target with the [`Jogger`]: at most one jog step
//! from where the device is now ([`WHJ_JOG_STEP_DEG`](super::jog::WHJ_JOG_STEP_DEG),
//! [`WCK_JOG_STEP`](super::jog::WCK_JOG_STEP)), within the device's own limits, through
//! the handles' step-limit and readiness checks. Each joint has its own result: a silent
//! device is its failure and the others still move.
//!
//! Admission (who may move, armed or not) is the caller's: a remote front end asks its
//! guard (`frontend::guard::Guard`) first (`admit_jog` for each of [`Follower::joints`]).
//!
//! A follower of the whole file ([`Follower::new`]) is watched by the host's protection
//! ([`crate::ops::protect`]; `guard.rs`): a stall, a collision or heat stops the joint
//! that tripped (disabled where its brake holds it, else held) and refuses every later
//! command, nothing sent, until [`Follower::resume`]; its events are
//! [`Follower::protection`]. A follower of some joints ([`Follower::of_joints`],
//! `robot.teleop`'s) is watched by its operation.

use serde::Serialize;

use super::jog::{JogRequest, Jogged, Jogger};
use crate::actuator::{JointMap, WckScale};
use crate::ops::Family;
use crate::ops::{DeviceResult, Failure, OpError};
use crate::station::Station;

pub mod drive;
mod guard;
#[cfg(all(test, feature = "sim"))]
mod testing;

/// A joint of the robot file as the follower commands it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FollowedJoint {
    /// Its name in the file.
    pub name: String,
    /// `wck` or `whj`.
    pub family: Family,
    /// The station's bus (the file's bus name).
    pub bus: String,
    /// Servo or joint ID.
    pub id: u8,
    /// Soft limits `[min, max]`, rad.
    pub limits_rad: [f64; 2],
    #[serde(skip)]
    units: Units,
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Units {
    Whj(JointMap),
    Wck(WckScale),
}

/// Follows joint targets on a station with a robot file (see the [module docs](self)).
#[derive(Debug)]
pub struct Follower {
    joints: Vec<FollowedJoint>,
    jogger: Jogger,
    /// The host's protection (a follower of the whole file).
    guard: Option<guard::Guard>,
}

impl Follower {
    /// A follower of the station's robot file.
    ///
    /// Errors: an [`OpError`] of kind [`ErrorKind::BadInput`](crate::ErrorKind::BadInput) when the station has no robot file.
    pub fn new(station: &Station) -> Result<Self, OpError> {
        Self::of(station, None)
    }

    /// A follower of some joints of the station's robot file, by name, in the order of
    /// `names` (a teleoperation's followers).
    ///
    /// Errors: an [`OpError`] of kind [`ErrorKind::BadInput`](crate::ErrorKind::BadInput)
    /// when the station has no robot file or it has no joint of one of the names.
    pub fn of_joints(station: &Station, names: &[String]) -> Result<Self, OpError> {
        Self::of(station, Some(names))
    }

    fn of(station: &Station, names: Option<&[String]>) -> Result<Self, OpError> {
        let robot = station.robot().ok_or_else(|| {
            OpError::invalid(
                "robot",
                "none",
                "following joint targets needs a robot file (--robot FILE) that names the joints",
            )
        })?;
        let chosen: Vec<&crate::robot::JointConfig> = match names {
            None => robot.joints.iter().collect(),
            Some(names) => names
                .iter()
                .map(|n| {
                    robot.joints.iter().find(|j| j.name == *n).ok_or_else(|| {
                        OpError::invalid(
                            "joint",
                            n,
                            format!("a joint of the robot file: {}", robot.joint_names()),
                        )
                    })
                })
                .collect::<Result<_, _>>()?,
        };
        let index: Vec<usize> = chosen
            .iter()
            .filter_map(|c| robot.joints.iter().position(|j| std::ptr::eq(j, *c)))
            .collect();
        let joints = chosen
            .into_iter()
            .map(|j| {
                let wck = robot.is_wck(j);
                FollowedJoint {
                    name: j.name.clone(),
                    family: if wck { Family::Wck } else { Family::Whj },
                    bus: j.bus.clone(),
                    id: j.id,
                    limits_rad: [j.limits[0].min(j.limits[1]), j.limits[0].max(j.limits[1])],
                    units: if wck {
                        Units::Wck(j.wck_scale())
                    } else {
                        Units::Whj(j.map())
                    },
                }
            })
            .collect();
        let guard = match names {
            None => Some(guard::Guard::new(station, index)?),
            Some(_) => None,
        };
        Ok(Self {
            joints,
            jogger: Jogger::unwatched(),
            guard,
        })
    }

    /// The joint angle (rad) of joint `index` at a device position as a jog reports it
    /// ([`Jogged::from`], [`Jogged::sent`]: WHJ degrees, wCK steps); `None` for an index
    /// past the joints or a wCK value outside 0..=254.
    pub fn joint_rad(&self, index: usize, device: f64) -> Option<f64> {
        match self.joints.get(index)?.units {
            Units::Whj(map) => Some(map.to_joint(device.to_radians())),
            Units::Wck(scale) => {
                if !(0.0..=254.0).contains(&device) {
                    return None;
                }
                #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)] // 0..=254
                let p = robobus_wck::Position::new(device.round() as u8).ok()?;
                Some(scale.to_rad(p))
            }
        }
    }

    /// The joints, in the order of a command.
    pub fn joints(&self) -> &[FollowedJoint] {
        &self.joints
    }

    /// Checks a whole command (joint radians, in the file's order) and turns it into one
    /// jog per joint in device units (WHJ degrees, wCK steps). Refused whole, nothing
    /// sent: a count other than the joints', a target that is not finite or lies outside
    /// the joint's soft limits or the servo's range.
    pub fn plan(&self, targets_rad: &[f64]) -> Result<Vec<JogRequest>, OpError> {
        if targets_rad.len() != self.joints.len() {
            return Err(OpError::invalid(
                "targets",
                format!("{} values", targets_rad.len()),
                format!(
                    "one target per joint of the robot file: {} values, in the order {}",
                    self.joints.len(),
                    self.joints
                        .iter()
                        .map(|j| j.name.as_str())
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
            ));
        }
        self.joints
            .iter()
            .zip(targets_rad)
            .map(|(j, &rad)| {
                let [lo, hi] = j.limits_rad;
                if !(rad.is_finite() && (lo..=hi).contains(&rad)) {
                    return Err(OpError::invalid(
                        &j.name,
                        format!("{rad} rad"),
                        format!("a number within the joint's soft limits {lo}..={hi} rad"),
                    ));
                }
                let target = match j.units {
                    Units::Whj(map) => map.to_device(rad).to_degrees(),
                    Units::Wck(scale) => f64::from(
                        scale
                            .to_position(rad)
                            .ok_or_else(|| {
                                OpError::invalid(
                                    &j.name,
                                    format!("{rad} rad"),
                                    "an angle the servo reaches (position steps 0..=254)",
                                )
                            })?
                            .get(),
                    ),
                };
                Ok(JogRequest {
                    family: j.family,
                    bus: Some(j.bus.clone()),
                    device: j.id,
                    target,
                })
            })
            .collect()
    }

    /// Makes every joint's handle now, as the first command would (reads only: a WHJ
    /// joint's identity and limits, a wCK servo's boundaries), so that the first command
    /// costs no more than the next. Nothing moves; a joint that does not answer is its
    /// error here (named), and is tried again by the first command.
    pub fn prepare(&self, station: &Station) -> Vec<DeviceResult<String, ()>> {
        self.joints
            .iter()
            .map(|j| {
                let req = JogRequest {
                    family: j.family,
                    bus: Some(j.bus.clone()),
                    device: j.id,
                    target: 0.0,
                };
                match self.jogger.prepare(station, &req) {
                    Ok(()) => DeviceResult::ok(j.name.clone(), ()),
                    Err(e) => DeviceResult::failed(j.name.clone(), Failure::from(&e)),
                }
            })
            .collect()
    }

    /// Steps every joint of a planned command toward its target, one result per joint
    /// (named as in the file), in the file's order.
    pub fn apply(
        &self,
        station: &Station,
        plan: &[JogRequest],
    ) -> Vec<DeviceResult<String, Jogged>> {
        // After a protection stop nothing is sent until resumed; a derated joint is
        // stepped at its share of its max_velocity.
        let mut plan = plan.to_vec();
        if let Some(g) = &self.guard {
            if let Some(refused) = g.refusal(&self.joints) {
                return refused;
            }
            g.derate(station, &mut plan);
        }
        // Each WHJ bus's joints step in one batch.
        let done = self
            .joints
            .iter()
            .zip(self.jogger.jog_many(station, &plan))
            .map(|(j, r)| match r {
                Ok(done) => DeviceResult::ok(j.name.clone(), done),
                Err(e) => DeviceResult::failed(j.name.clone(), Failure::from(&e)),
            })
            .collect();
        match &self.guard {
            Some(g) => g.watch(station, &self.joints, done),
            None => done,
        }
    }

    /// The host's protection events so far (the last 256), in order (none for a
    /// follower of some joints).
    pub fn protection(&self) -> Vec<crate::ops::protect::Fault> {
        self.guard
            .as_ref()
            .map(guard::Guard::events)
            .unwrap_or_default()
    }

    /// The protection stop that refuses every command, if one came.
    pub fn protection_stop(&self) -> Option<crate::ops::protect::Fault> {
        self.guard.as_ref().and_then(guard::Guard::stopped)
    }

    /// Takes commands again after a protection stop (once its cause is cleared); the
    /// protection starts afresh.
    pub fn resume(&self) {
        if let Some(g) = &self.guard {
            g.resume();
        }
    }
}

#[cfg(all(test, feature = "sim"))]
mod tests {
    use super::*;

    #[test]
    fn a_command_is_checked_whole_before_anything_is_sent() {
        let station = Station::simulated().unwrap();
        let f = Follower::new(&station).unwrap();
        let n = f.joints().len();
        assert_eq!(n, 23);
        assert_eq!(
            f.plan(&vec![0.0; n - 1]).unwrap_err().kind(),
            crate::ErrorKind::BadInput
        );
        let mut t = vec![0.0; n];
        t[3] = f64::NAN;
        assert!(
            f.plan(&t)
                .unwrap_err()
                .to_string()
                .contains(&f.joints()[3].name)
        );
        t[3] = f.joints()[3].limits_rad[1] + 0.01;
        assert!(f.plan(&t).unwrap_err().to_string().contains("soft limits"));
        t[3] = 0.0;
        let plan = f.plan(&t).unwrap();
        assert_eq!(plan.len(), n);
    }
}
