//! `robot.play` of velocities or efforts: a trajectory file whose header names its joints'
//! interface by the columns' unit, `NAME_deg_s` (velocities, degrees a second, in the
//! joint frame) or `NAME_nm` (efforts, N·m), every column the same.
//!
//! Checked whole before anything is sent: every joint in the robot file with that
//! interface (`interfaces`), every value within its `max_velocity` / `max_effort` and (a
//! wCK servo's speed) what its top wheel level turns it at, naming the line. The joints are
//! read (a silent one refuses the run), switched at rest (a WHJ joint to speed or current
//! mode with a zero target, a wCK servo to wheel mode at level 0), and played each tick,
//! linearly between the points, ramped at `max_acceleration` / `max_effort_rate`: a speed
//! servo frame or a current servo frame per WHJ joint (the current of the model's torque
//! constant; a WHJ joint never heads for a soft limit faster than it can stop there, and an
//! effort pushing it past one it stands on is dropped), a wheel command per wCK servo (the
//! nearest level of `wheel_speeds`). At the end every joint gets a zero target, the WHJ
//! joints go back to position mode (holding where they stand), and every bus goes to the
//! robot file's `safe_state`. The front end gets no ticks (nothing is recorded).
//!
//! The host's protection watches the WHJ joints ([`Monitor::feed_driven`]): each servo
//! frame's feedback (its current and speed) against the set-point sent the tick before,
//! and the temperature every [`TEMPERATURE_EVERY_S`] s. In velocity a stall is the stall
//! current while the joint turns at under half its commanded speed, a collision a jump of
//! the current; in effort the current is the command, and the joint is stopped when it
//! turns faster than its `max_velocity`; heat warns, derates (a derated joint's speed, or
//! effort, is held to its `derate` share of `max_velocity` / `max_effort`) and stops in
//! both. A stop ends the play, fails the joint's row naming the fault (in
//! `summary.protection`) and leaves the joint's drive disabled where its brake holds it.
//! A wCK wheel's command reply carries no load: every [`TEMPERATURE_EVERY_S`] s a status
//! read gives its load (as a current, [`protect::wck_load_a`]) and position, its speed
//! the position's change since the read before; it is watched on those readings alone
//! (in velocity, as a WHJ joint; no temperature), with the wCK limits
//! ([`protect::Limits::wck`]) sized to that period.

use std::f64::consts::TAU;
use std::time::Duration;

use robobus_wck::ServoId;
use robobus_whj::units::{Current, CurrentScale, TargetSpeed};
use robobus_whj::{JointId, WorkMode};

use super::{PlaySummary, Played, PlayedRun, Spread, TEMPERATURE_EVERY_S};
use crate::actuator::{JointMap, WckScale};
use crate::ops::protect::{self, Action, Drive, Fault, Monitor, Reading};
use crate::ops::{Control, Failure, OpError, Progress};
use crate::robot::trajectory::Trajectory;
use crate::robot::{EffortScale, Interface, RobotConfig, WheelSpeeds};
use crate::station::clock::BusClock;
use crate::station::{Station, WckPort, WhjPort};

/// The header suffix of a column of `interface` (none for positions).
const fn suffix(interface: Interface) -> &'static str {
    match interface {
        Interface::Position => "",
        Interface::Velocity => "_deg_s",
        Interface::Effort => "_nm",
    }
}

/// The interface a trajectory's header names, and the text with the joints' plain names
/// (unchanged for positions). Columns naming different interfaces are refused.
pub(super) fn header(text: &str) -> Result<(Interface, String), OpError> {
    let Some((at, line)) = text
        .lines()
        .enumerate()
        .find(|(_, l)| !l.trim().is_empty() && !l.trim_start().starts_with('#'))
    else {
        return Ok((Interface::Position, text.to_owned()));
    };
    let cells: Vec<&str> = line.split(',').map(str::trim).collect();
    let of = |c: &str| {
        [Interface::Velocity, Interface::Effort]
            .into_iter()
            .find(|&i| c.ends_with(suffix(i)) && c.len() > suffix(i).len())
            .unwrap_or(Interface::Position)
    };
    let kinds: Vec<Interface> = cells.iter().skip(1).map(|c| of(c)).collect();
    let Some(&first) = kinds.first() else {
        return Ok((Interface::Position, text.to_owned()));
    };
    if let Some(other) = kinds.iter().find(|&&k| k != first) {
        return Err(OpError::invalid(
            "trajectory",
            format!("line {}: {line}", at + 1),
            format!(
                "one interface for every column: plain joint names (positions, degrees), \
                 NAME_deg_s (velocities) or NAME_nm (efforts), not {first} and {other}"
            ),
        ));
    }
    if first == Interface::Position {
        return Ok((first, text.to_owned()));
    }
    let plain: Vec<&str> = cells
        .iter()
        .enumerate()
        .map(|(k, c)| {
            if k == 0 {
                c
            } else {
                c.strip_suffix(suffix(first)).unwrap_or(c)
            }
        })
        .collect();
    let mut out = String::with_capacity(text.len());
    for (k, l) in text.lines().enumerate() {
        if k == at {
            out.push_str(&plain.join(","));
        } else {
            out.push_str(l);
        }
        out.push('\n');
    }
    Ok((first, out))
}

/// Parses and checks a velocity or effort trajectory (`text` with plain names) against
/// `config`: the trajectory and each column's joint in the file.
pub(super) fn check(
    text: &str,
    interface: Interface,
    config: &RobotConfig,
) -> Result<(Trajectory, Vec<usize>), OpError> {
    let bad = |what: String| OpError::invalid("trajectory", "(file)", what);
    let traj = Trajectory::parse(text).map_err(|e| bad(e.to_string()))?;
    let mut index = Vec::with_capacity(traj.joints().len());
    for name in traj.joints() {
        let Some(i) = config.joints.iter().position(|j| &j.name == name) else {
            return Err(bad(format!(
                "{name}{} is not a joint of the robot file: {}",
                suffix(interface),
                config.joint_names()
            )));
        };
        let j = &config.joints[i];
        if !j.has(interface) {
            return Err(bad(format!(
                "{name} has no {interface} interface in the robot file (its interfaces: {})",
                crate::robot::interface_list(&j.interfaces())
            )));
        }
        index.push(i);
    }
    // Every value, by its line.
    let mut rows = text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty() && !l.trim_start().starts_with('#'))
        .skip(1);
    for (line, l) in rows.by_ref() {
        for (cell, &i) in l.split(',').skip(1).zip(&index) {
            let Ok(v) = cell.trim().parse::<f64>() else {
                continue; // the parse refused it already
            };
            let j = &config.joints[i];
            let fault = if interface == Interface::Velocity {
                let most = j.max_velocity.to_degrees();
                if v.abs() > most {
                    Some(format!("-{most:.3}..={most:.3} deg/s (its max_velocity)"))
                } else {
                    j.wheel_speeds
                        .as_ref()
                        .filter(|w| w.level(v.to_radians()).is_none())
                        .map(|w| {
                            let top = w.top().to_degrees();
                            format!("-{top:.3}..={top:.3} deg/s (its top wheel level)")
                        })
                }
            } else {
                let most = j.max_effort.unwrap_or(0.0);
                (v.abs() > most).then(|| format!("-{most}..={most} N·m (its max_effort)"))
            };
            if let Some(range) = fault {
                return Err(bad(format!(
                    "trajectory line {}: {} {v} {} is outside {range}",
                    line + 1,
                    j.name,
                    match interface {
                        Interface::Velocity => "deg/s",
                        _ => "N·m",
                    }
                )));
            }
        }
    }
    Ok((traj, index))
}

/// One joint of the play: its device, limits and set-point.
struct Joint {
    name: String,
    device: Device,
    limits: (f64, f64),
    /// rad/s² (velocity) or N·m/s (effort).
    ramp: f64,
    /// The set-point, rad/s or N·m.
    set: f64,
    /// Where it last reported itself, rad.
    at: f64,
    /// Its speed (°/s) and current (A) in the last feedback (a WHJ joint's, or a wCK
    /// wheel's status read, taken by the next protection reading).
    speed_deg_s: Option<f64>,
    current_a: Option<f64>,
    /// The most speed (velocity, rad/s) or effort (N·m) its derating scales.
    most: f64,
    /// A wCK wheel's last status read: when, and where (joint degrees, and whether the
    /// reading was at the end of its range).
    wck_last: Option<(std::time::Instant, f64, bool)>,
}

enum Device {
    Wck {
        port: WckPort,
        id: ServoId,
        scale: WckScale,
        wheel: WheelSpeeds,
    },
    Whj {
        port: WhjPort,
        id: JointId,
        map: JointMap,
        current: CurrentScale,
        effort: Option<EffortScale>,
    },
}

impl Joint {
    /// Sends `value` (rad/s or N·m, after the limits) in `interface`; what it reported
    /// (rad) and what was sent at the device's resolution.
    fn send(&mut self, interface: Interface, value: f64) -> Result<f64, OpError> {
        let sign = |reversed: bool| if reversed { -1.0 } else { 1.0 };
        match &self.device {
            Device::Wck {
                port,
                id,
                scale,
                wheel,
            } => {
                let (rotation, level, speed) = wheel.command(value, scale.map.reversed);
                let st = port.lock().servo(*id).wheel(rotation, level)?;
                self.at = scale.to_rad(st.position);
                Ok(speed)
            }
            Device::Whj {
                port,
                id,
                map,
                current,
                effort,
            } => {
                let joint = port.bus().joint_unchecked(*id);
                let (fb, sent) = if interface == Interface::Velocity {
                    let rpm = value * sign(map.reversed) * 60.0 / TAU;
                    let target = TargetSpeed::from_rpm(rpm)
                        .map_err(|e| OpError::invalid("trajectory", value, e.to_string()))?;
                    let sent = target.rpm() * TAU / 60.0 * sign(map.reversed);
                    (joint.command_speed(target)?, sent)
                } else {
                    let k = effort.map_or(1.0, |e| e.nm_per_a);
                    let ma = value / k * 1e3 * sign(map.reversed);
                    let counts = Current::from_milliamps(ma, *current)
                        .map_err(|e| OpError::invalid("trajectory", value, e.to_string()))?;
                    #[allow(clippy::cast_precision_loss)] // mA of a joint
                    let sent_ma = counts.milliamps(*current) as f64;
                    (
                        joint.command_current(sent_ma)?,
                        sent_ma / 1e3 * k * sign(map.reversed),
                    )
                };
                self.at = map.to_joint(fb.position.degrees().to_radians());
                self.speed_deg_s = Some(fb.speed.rpm() * 6.0 * sign(map.reversed));
                #[allow(clippy::cast_precision_loss)] // mA of a joint
                let ma = fb.current.milliamps(*current) as f64;
                self.current_a = Some(ma / 1e3);
                Ok(sent)
            }
        }
    }

    /// The set-point for `target` after `dt_s`: ramped, and for a WHJ joint kept from
    /// running past a soft limit (see the module docs).
    fn step(&mut self, interface: Interface, target: f64, dt_s: f64, accel: f64) -> f64 {
        let step = self.ramp * dt_s;
        let mut set = if (target - self.set).abs() <= step {
            target
        } else {
            self.set + step.copysign(target - self.set)
        };
        if matches!(self.device, Device::Whj { .. }) {
            let (lo, hi) = self.limits;
            let room = if set > 0.0 {
                hi - self.at
            } else {
                self.at - lo
            };
            let room = (room - self.set.abs() * dt_s).max(0.0);
            set = match interface {
                Interface::Velocity => {
                    let stoppable = (2.0 * accel * room).sqrt();
                    set.clamp(-stoppable, stoppable)
                }
                _ if room <= 0.0 => 0.0,
                _ => set,
            };
        }
        self.set = set;
        set
    }
}

impl Joint {
    /// A WHJ joint's temperature, °C, by a status query; for a wCK servo, a status read
    /// of its load and position for the protection (`None`: it has no temperature).
    fn temperature(&mut self, now: std::time::Instant) -> Result<Option<f64>, OpError> {
        match &self.device {
            Device::Wck {
                port, id, scale, ..
            } => {
                let st = port.lock().servo(*id).status()?;
                let deg = scale.to_rad(st.position).to_degrees();
                let edge = st.position == robobus_wck::Position::MIN
                    || st.position == robobus_wck::Position::MAX;
                self.speed_deg_s = self.wck_last.and_then(|(t, before, was_edge)| {
                    let dt = now.saturating_duration_since(t).as_secs_f64();
                    let changed = (deg - before).abs() > 1e-9;
                    (dt > 0.0 && !(changed && (edge || was_edge))).then(|| (deg - before) / dt)
                });
                self.current_a = Some(protect::wck_load_a(st.load.get()));
                self.wck_last = Some((now, deg, edge));
                self.at = deg.to_radians();
                Ok(None)
            }
            Device::Whj { port, id, .. } => {
                let st = port.bus().joint_unchecked(*id).status()?;
                Ok(Some(f64::from(st.temperature.celsius())))
            }
        }
    }
}

/// The host's protection of a play's joints, by column, and its events so far.
struct Watch {
    monitor: Monitor,
    faults: Vec<Fault>,
    /// Each joint's `max_velocity`, °/s (an effort's runaway speed).
    max_deg_s: Vec<f64>,
}

impl Watch {
    /// Feeds joint `c`'s feedback (read at `now`, answering the set-point `before` of the
    /// tick before, rad/s or N·m) and its `temperature_c`; whether it stops the play.
    fn feed(
        &mut self,
        c: usize,
        j: &Joint,
        interface: Interface,
        before: f64,
        temperature_c: Option<f64>,
        now: std::time::Instant,
    ) -> bool {
        let reading = Reading {
            position_deg: Some(j.at.to_degrees()),
            current_a: j.current_a,
            temperature_c,
            ..Reading::at(now)
        };
        let drive = match interface {
            Interface::Velocity => Drive::Velocity {
                commanded_deg_s: before.to_degrees(),
            },
            _ => Drive::Effort {
                max_deg_s: self.max_deg_s.get(c).copied().unwrap_or(f64::INFINITY),
            },
        };
        let mut stop = false;
        if matches!(j.device, Device::Wck { .. }) && j.current_a.is_none() {
            // A wheel is read every TEMPERATURE_EVERY_S s, not every tick.
            return false;
        }
        for f in self.monitor.feed_driven(c, &reading, j.speed_deg_s, drive) {
            stop |= f.action == Action::Stop;
            tracing::warn!("{f}");
            if self.faults.len() < protect::MAX_EVENTS || f.action == Action::Stop {
                self.faults.push(f);
            }
        }
        stop
    }
}

/// `robot.play` of velocities or efforts (see the [module docs](self)).
#[allow(clippy::too_many_lines)] // the checks, the switch, the ticks, the end
pub(super) fn run(
    station: &Station,
    r: &super::Play,
    control: &mut Control<'_>,
) -> Result<PlayedRun, OpError> {
    let (interface, text) = header(&r.trajectory)?;
    let config = station
        .robot()
        .cloned()
        .ok_or_else(super::super::no_robot)?;
    let (traj, index) = check(&text, interface, &config)?;
    let clock = BusClock::of(station, &super::super::only(&config, traj.joints()))?;
    let from = super::super::ready_at(station, &config, traj.joints(), "a trajectory")?;
    let mut joints = Vec::with_capacity(index.len());
    let mut models = Vec::with_capacity(index.len());
    for (&i, &start) in index.iter().zip(&from) {
        let j = &config.joints[i];
        let device = if config.is_wck(j) {
            models.push(None);
            Device::Wck {
                port: station.wck(Some(&j.bus))?,
                id: ServoId::new(j.id).map_err(|e| OpError::invalid("id", j.id, e.to_string()))?,
                scale: j.wck_scale(),
                wheel: j
                    .wheel_speeds
                    .clone()
                    .unwrap_or_else(|| WheelSpeeds::linear(1.0)),
            }
        } else {
            let port = station.whj(Some(&j.bus))?;
            let id = JointId::new(j.id).map_err(|e| OpError::invalid("id", j.id, e.to_string()))?;
            let identity = port.bus().joint_unchecked(id).identity()?;
            let effort = EffortScale::of(identity.model, identity.reduction_ratio);
            models.push(Some(identity.model));
            if interface == Interface::Effort && effort.is_none() {
                return Err(OpError::Refused(format!(
                    "{}: its model {} (reduction ratio {}) has no torque constant in the models \
                     table; nothing was moved",
                    j.name, identity.model, identity.reduction_ratio
                )));
            }
            Device::Whj {
                port,
                id,
                map: j.map(),
                current: identity.current_scale(),
                effort,
            }
        };
        joints.push(Joint {
            name: j.name.clone(),
            device,
            limits: (j.limits[0], j.limits[1]),
            ramp: match interface {
                Interface::Velocity => j.max_acceleration,
                _ => j.effort_rate(),
            },
            set: 0.0,
            at: start.to_radians(),
            speed_deg_s: None,
            current_a: None,
            most: match interface {
                Interface::Velocity => j.max_velocity,
                _ => j.max_effort.unwrap_or(0.0),
            },
            wck_last: None,
        });
    }
    let mut watch = Watch {
        monitor: Monitor::new(
            clock.now(),
            index
                .iter()
                .zip(&models)
                .map(|(&i, &m)| {
                    let j = &config.joints[i];
                    let limits = if m.is_some() {
                        config.protection_of(j, m)
                    } else {
                        // A wCK wheel, read every TEMPERATURE_EVERY_S s.
                        config
                            .protection_of(j, None)
                            .for_reading_period(Duration::from_secs_f64(TEMPERATURE_EVERY_S))
                    };
                    (j.name.clone(), limits)
                })
                .collect(),
        ),
        faults: Vec::new(),
        max_deg_s: index
            .iter()
            .map(|&i| config.joints[i].max_velocity.to_degrees())
            .collect(),
    };
    let mut next_temperature = 0.0;
    let accels: Vec<f64> = index
        .iter()
        .map(|&i| config.joints[i].max_acceleration)
        .collect();
    let mut rows: Vec<Played> = from.iter().map(|&s| Played::new(s)).collect();
    // Switched at rest: a WHJ joint's mode (the joint takes zero targets, §6.2), then zero.
    let switched: Result<(), OpError> = joints.iter_mut().try_for_each(|j| {
        if let Device::Whj { port, id, .. } = &j.device {
            port.bus().joint_unchecked(*id).set_mode(match interface {
                Interface::Velocity => WorkMode::Speed,
                _ => WorkMode::Current,
            })?;
        }
        j.send(interface, 0.0).map(drop)
    });
    let period = Duration::from_secs_f64(1.0 / r.rate_hz);
    let period_s = period.as_secs_f64();
    let total = traj.duration_s();
    let start = clock.now();
    let (mut ticks, mut overruns, mut late, mut interrupted) = (0_u64, 0_u64, Vec::new(), false);
    let mut k: u64 = 0;
    #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)] // ≤ 3600 s × 500 Hz
    let last = (total / period_s).ceil() as u64;
    let ran = switched.map(|()| {
        while k <= last {
            let due = start + period * u32::try_from(k).unwrap_or(u32::MAX);
            if !control.sleep_with(due, |until| {
                if let Some(t) = until {
                    clock.sleep_until(t);
                }
                clock.now()
            }) {
                interrupted = true;
                break;
            }
            let t_s = (due - start).as_secs_f64().min(total);
            let values = traj.at(t_s);
            if late.len() < super::MAX_TIMED_TICKS {
                late.push(clock.now().saturating_duration_since(due));
            }
            let temperature = t_s >= next_temperature;
            if temperature {
                next_temperature = t_s + TEMPERATURE_EVERY_S;
            }
            let mut stop = false;
            for (c, (j, row)) in joints.iter_mut().zip(rows.iter_mut()).enumerate() {
                let target = values.get(c).copied().unwrap_or(0.0);
                let target = match interface {
                    Interface::Velocity => target.to_radians(),
                    _ => target,
                };
                // A derated joint keeps its share of its max_velocity (or max_effort).
                let most = watch.monitor.speed_share(c) * j.most;
                let target = target.clamp(-most, most);
                let accel = accels.get(c).copied().unwrap_or(0.0);
                let before = j.set;
                let set = j.step(interface, target, period_s, accel);
                if (set - target).abs() > 1e-9 {
                    row.limited += 1;
                }
                match j.send(interface, set) {
                    Ok(done) => {
                        row.commands += 1;
                        row.position_deg = Some(j.at.to_degrees());
                        if interface == Interface::Velocity {
                            row.sent_deg_s = Some(done.to_degrees());
                        } else {
                            row.sent_nm = Some(done);
                        }
                        let temperature_c = if temperature {
                            match j.temperature(clock.now()) {
                                Ok(t) => t,
                                Err(e) => {
                                    row.failed += 1;
                                    row.last_error = Some(Failure::from(&e));
                                    None
                                }
                            }
                        } else {
                            None
                        };
                        stop |= watch.feed(c, j, interface, before, temperature_c, clock.now());
                        if matches!(j.device, Device::Wck { .. }) {
                            // Taken: the next reading is the next status read's.
                            j.current_a = None;
                            j.speed_deg_s = None;
                        }
                    }
                    Err(e) => {
                        row.failed += 1;
                        row.last_error = Some(Failure::from(&e));
                    }
                }
            }
            ticks += 1;
            control.report(&Progress::new("play", k + 1, Some(last + 1)));
            if stop {
                break;
            }
            let now = clock.now().saturating_duration_since(start);
            #[allow(clippy::cast_possible_truncation)] // ticks of at most an hour
            let behind = (now.as_nanos() / period.as_nanos().max(1)) as u64;
            if behind > k + 1 {
                overruns += behind - k - 1;
                k = behind;
            } else {
                k += 1;
            }
        }
    });
    // Finished, stopped or failed: zero, back to position mode, then the safe state.
    for j in &mut joints {
        j.set = 0.0;
        if let Err(e) = j.send(interface, 0.0) {
            tracing::warn!(joint = %j.name, "could not send the zero target: {e}");
        }
        if let Device::Whj { port, id, .. } = &j.device
            && let Err(e) = port.bus().joint_unchecked(*id).set_mode(WorkMode::Position)
        {
            tracing::warn!(joint = %j.name, "could not go back to position mode: {e}");
        }
    }
    let faults = watch.faults;
    let torque_off = super::fail_protection_stop(&faults, traj.joints(), &mut rows, &models);
    let settled = super::super::settle_with(station, &config, traj.joints(), &torque_off);
    ran.inspect_err(|_| settled.log())?;
    let names = traj.joints();
    Ok(PlayedRun {
        joints: settled.fail_rows(
            names
                .iter()
                .zip(rows)
                .map(|(n, row)| row.result(n))
                .collect(),
        ),
        summary: PlaySummary {
            lead_in_s: 0.0,
            duration_s: total,
            ticks,
            overruns,
            buses: clock.buses().map(|b| b.name().to_owned()).collect(),
            skew_ms: Spread::of(&[]),
            late_ms: Spread::of(&late),
            interrupted,
            safe_state: settled.buses,
            protection: faults,
            preflight: None,
        },
    })
}

#[cfg(all(test, feature = "sim"))]
mod tests;
