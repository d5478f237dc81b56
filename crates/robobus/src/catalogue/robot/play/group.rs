//! `robot.play`'s buses: the trajectory's joints grouped by bus ([`Group`], [`groups`]),
//! a tick's targets sent to a group's devices and what each reported ([`Sensed`]), and
//! what the groups' WHJ joints allow (their step limits, [`check_steps`]; their models).

use super::LEAD_IN_PEAK;
use crate::actuator::{JointMap, WckScale};
use crate::ops::whj::ServoLoop;
use crate::ops::{Failure, OpError, Outcome};
use crate::robot::RobotConfig;
use crate::robot::trajectory::Trajectory;
use crate::station::Station;
use crate::station::WhjPort;
use crate::station::clock::BusClock;
use crate::station::handles::{WckGroup, WhjGroup};

/// What a joint reported in a tick: its position (joint degrees), and where read, its
/// current and temperature.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Sensed {
    pub(super) position: f64,
    pub(super) current_a: Option<f64>,
    pub(super) temperature_c: Option<f64>,
}

impl Sensed {
    pub(super) const fn at(position: f64) -> Self {
        Self {
            position,
            current_a: None,
            temperature_c: None,
        }
    }
}

/// A joint's outcome in a tick, by its column: what it reported, or why not.
pub(super) type Outcomes = Vec<(usize, Result<Sensed, Failure>)>;

/// The joints of one bus and their handle, each by its column with how its angles turn
/// into its device's units.
pub(super) enum Group {
    Wck(WckGroup, Vec<(usize, WckScale)>),
    Whj(WhjGroup, WhjPort, Vec<(usize, JointMap)>),
}

impl Group {
    pub(super) fn columns(&self) -> Vec<usize> {
        match self {
            Self::Wck(_, c) => c.iter().map(|x| x.0).collect(),
            Self::Whj(_, _, c) => c.iter().map(|x| x.0).collect(),
        }
    }

    /// Sends `targets` (joint degrees, by column) to the group's devices: each column's
    /// outcome, what it reported (with `temperature`, a WHJ joint's temperature read
    /// after its command).
    pub(super) fn send(&self, targets: &[f64], torque: u8, temperature: bool) -> Outcomes {
        let rad = |c: usize| targets.get(c).copied().unwrap_or(0.0).to_radians();
        let results: Result<Outcomes, OpError> = match self {
            Self::Wck(h, cols) => {
                let steps: Vec<f64> = cols
                    .iter()
                    .map(|&(c, s)| s.to_position(rad(c)).map_or(-1.0, |p| f64::from(p.get())))
                    .collect();
                h.move_to(&steps, torque).map(|r| {
                    cols.iter()
                        .zip(r)
                        .map(|(&(c, s), d)| {
                            let at = match d.outcome {
                                Outcome::Ok(reading) => {
                                    robobus_wck::Position::new(reading.position)
                                        .map(|p| Sensed {
                                            // The load, as a current, for the protection.
                                            current_a: reading
                                                .load
                                                .map(crate::ops::protect::wck_load_a),
                                            ..Sensed::at(s.to_rad(p).to_degrees())
                                        })
                                        .map_err(|e| Failure::of(crate::ErrorKind::Device, &e))
                                }
                                Outcome::Failed(f) => Err(f),
                            };
                            (c, at)
                        })
                        .collect()
                })
            }
            Self::Whj(h, port, cols) => {
                let degrees: Vec<f64> = cols
                    .iter()
                    .map(|&(c, m)| m.to_device(rad(c)).to_degrees())
                    .collect();
                h.command(ServoLoop::Position, &degrees)
                    .map(|r| {
                        cols.iter()
                            .zip(r)
                            .map(|(&(c, m), d)| {
                                let at = match d.outcome {
                                    Outcome::Ok(fb) => Ok(Sensed {
                                    position: m.to_joint(fb.position_deg.to_radians()).to_degrees(),
                                    #[allow(clippy::cast_precision_loss)] // mA of a joint
                                    current_a: Some(fb.current_ma as f64 / 1e3),
                                    temperature_c: None,
                                }),
                                    Outcome::Failed(f) => Err(f),
                                };
                                (c, at)
                            })
                            .collect::<Outcomes>()
                    })
                    .map(|mut out| {
                        if temperature {
                            let bus = port.bus();
                            for ((_, o), id) in out.iter_mut().zip(h.ids()) {
                                let Ok(sensed) = o else { continue };
                                let Ok(joint) = robobus_whj::JointId::new(id) else {
                                    continue;
                                };
                                match bus.joint_unchecked(joint).status() {
                                    Ok(st) => {
                                        sensed.temperature_c =
                                            Some(f64::from(st.temperature.celsius()));
                                    }
                                    Err(e) => *o = Err(Failure::from(&OpError::from(e))),
                                }
                            }
                        }
                        out
                    })
            }
        };
        results.unwrap_or_else(|e| {
            let f = Failure::from(&e);
            self.columns()
                .into_iter()
                .map(|c| (c, Err(f.clone())))
                .collect()
        })
    }
}

/// The trajectory's joints grouped by bus, in the file's bus order, with the clock of
/// those buses.
pub(super) fn groups(
    station: &Station,
    config: &RobotConfig,
    traj: &Trajectory,
    index: &[usize],
) -> Result<(Vec<Group>, BusClock), OpError> {
    let mut groups = Vec::new();
    for name in config.buses.keys() {
        let cols: Vec<(usize, &crate::robot::JointConfig)> = index
            .iter()
            .enumerate()
            .filter_map(|(c, &i)| config.joints.get(i).map(|j| (c, j)))
            .filter(|(_, j)| &j.bus == name)
            .collect();
        let Some((_, first)) = cols.first() else {
            continue;
        };
        let ids: Vec<u8> = cols.iter().map(|(_, j)| j.id).collect();
        groups.push(if config.is_wck(first) {
            Group::Wck(
                WckGroup::new(station, Some(name), &ids)?,
                cols.iter().map(|(c, j)| (*c, j.wck_scale())).collect(),
            )
        } else {
            Group::Whj(
                WhjGroup::new(station, Some(name), &ids)?,
                station.whj(Some(name))?,
                cols.iter().map(|(c, j)| (*c, j.map())).collect(),
            )
        });
    }
    let clock = BusClock::of(station, &super::super::only(config, traj.joints()))?;
    Ok((groups, clock))
}

/// Per column, its WHJ bus's step limit, degrees (`None` for a wCK servo).
pub(super) fn step_limits(groups: &[Group], columns: usize) -> Result<Vec<Option<f64>>, OpError> {
    let mut steps = vec![None; columns];
    for g in groups {
        if let Group::Whj(h, _, cols) = g {
            let limit = h.step_limit_deg()?;
            for &(c, _) in cols {
                if let Some(s) = steps.get_mut(c) {
                    *s = Some(limit);
                }
            }
        }
    }
    Ok(steps)
}

/// Per column, how far a WHJ joint's target may be sent from where it last reported
/// itself: 0.8 of its bus's step limit (`None` for a wCK servo).
pub(super) fn steps_of(groups: &[Group], columns: usize) -> Result<Vec<Option<f64>>, OpError> {
    Ok(step_limits(groups, columns)?
        .into_iter()
        .map(|l| l.map(|l| 0.8 * l))
        .collect())
}

/// Refuses a trajectory whose WHJ joints (`limits`: each column's bus step limit, as
/// [`step_limits`]) would step more than half their bus's step limit in one tick (a
/// joint lagging by a tick would then be refused its next frame): the fastest segment,
/// and the lead-in, at `rate_hz`.
pub(super) fn check_steps(
    limits: &[Option<f64>],
    traj: &Trajectory,
    from: &[f64],
    lead_in: f64,
    rate_hz: f64,
) -> Result<(), OpError> {
    for (c, limit) in limits.iter().enumerate() {
        let Some(limit) = *limit else { continue };
        let lead = match (traj.first().get(c), from.get(c)) {
            (Some(a), Some(b)) if lead_in > 0.0 => LEAD_IN_PEAK * (a - b).abs() / lead_in,
            _ => 0.0,
        };
        let speed = traj.max_speed(c).max(lead);
        let step = speed / rate_hz;
        if step > limit / 2.0 {
            let name = traj.joints().get(c).map_or("?", String::as_str);
            return Err(OpError::invalid(
                "--rate-hz",
                rate_hz,
                format!(
                    "{name} moves up to {speed:.1}°/s: at {rate_hz} Hz a tick steps \
                     {step:.2}°, more than half its bus's {limit}° step limit; play at \
                     --rate-hz {} or more",
                    (2.0 * speed / limit).ceil()
                ),
            ));
        }
    }
    Ok(())
}

/// Per column, the model a WHJ joint identified as (`None`: a wCK servo).
pub(super) fn models_of(
    index: &[usize],
    groups: &[Group],
) -> Vec<Option<robobus_whj::units::Model>> {
    (0..index.len())
        .map(|c| {
            groups.iter().find_map(|g| match g {
                Group::Whj(h, port, cols) => {
                    let k = cols.iter().position(|x| x.0 == c)?;
                    let id = robobus_whj::JointId::new(*h.ids().get(k)?).ok()?;
                    port.bus()
                        .joint_unchecked(id)
                        .identity()
                        .ok()
                        .map(|i| i.model)
                }
                Group::Wck(..) => None,
            })
        })
        .collect()
}
