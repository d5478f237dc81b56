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

use robobus_wck::{Rotation, ServoId, WheelSpeed};
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
                let (level, speed) = wheel.level(value).unwrap_or((0, 0.0));
                let device = speed * sign(scale.map.reversed);
                let rotation = if device < 0.0 {
                    Rotation::Cw
                } else {
                    Rotation::Ccw
                };
                let level = WheelSpeed::new(level).unwrap_or(WheelSpeed::MIN);
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
mod tests {
    #![allow(clippy::unwrap_used)]

    use serde_json::{Value, json};

    use crate::catalogue::{Request, run};
    use crate::ops::{Control, ErrorKind};
    use crate::robot::RobotConfig;
    use crate::robot::simulated::{DRIVE_ROBOT, sim_1108_wheel_speeds};
    use crate::station::Station;

    /// The built-in simulated station with its robot file of a wheel `s0`, a WHJ joint `j1`
    /// with velocity and effort, and `j2` with position alone ([`DRIVE_ROBOT`]); its WHJ
    /// joints enabled.
    fn station() -> (
        Station,
        robobus_sim::wck::SimHandle,
        robobus_sim::whj::WhjSimHandle,
    ) {
        let (mut station, wck, whj) = Station::simulated_with_handles().unwrap();
        station
            .set_robot(RobotConfig::from_toml_str(DRIVE_ROBOT).unwrap())
            .unwrap();
        for r in [
            json!({"op": "whj.mode", "joints": "1-2", "mode": "position"}),
            json!({"op": "whj.enable", "joints": "1-2"}),
        ] {
            run(&station, &req(r), &mut Control::none()).unwrap();
        }
        (station, wck, whj)
    }

    fn req(v: Value) -> Request {
        serde_json::from_value(v).unwrap()
    }

    fn play(station: &Station, csv: &str) -> Result<Value, crate::ops::OpError> {
        let request = req(json!({"op": "robot.play", "trajectory": csv, "rate_hz": 50}));
        run(station, &request, &mut Control::none()).map(|r| serde_json::to_value(r).unwrap())
    }

    fn wheel_angle(wck: &robobus_sim::wck::SimHandle) -> f64 {
        wck.with_bus(|b| {
            let s = b.servo(0).unwrap();
            #[allow(clippy::cast_precision_loss)] // a few rotations
            let turns = s.rotations() as f64;
            turns * 360.0 + s.angle()
        })
    }

    #[test]
    fn a_csv_of_velocities_turns_a_wheel_and_a_whj_joint_at_its_speeds() {
        let (station, wck, whj) = station();
        let level_7 = sim_1108_wheel_speeds()[6].to_degrees();
        let a0 = wheel_angle(&wck);
        let v = play(
            &station,
            &format!("time_s,s0_deg_s,j1_deg_s\n0,{level_7},30\n1,{level_7},30\n"),
        )
        .unwrap();
        assert_eq!(v["failed"], Value::Null, "{v:#}");
        assert_eq!(v["summary"]["ticks"], 51, "{v:#}");
        let rows = v["results"].as_array().unwrap();
        // The wheel: its level-7 speed, sent as that level.
        let s0 = rows[0]["sent_deg_s"].as_f64().unwrap();
        assert!((s0 - level_7).abs() < 1e-9, "{v:#}");
        // Up to speed within 31 ms at 100 rad/s², then 1 s: about 1 s of level 7.
        let turned = wheel_angle(&wck) - a0;
        assert!(
            (turned - level_7).abs() < 0.04 * level_7,
            "{turned}° for {level_7}°/s"
        );
        // The WHJ joint: 30°/s (0.002 RPM counts), 1 s less the ramp (26 ms at 20 rad/s²).
        let j1 = rows[1]["sent_deg_s"].as_f64().unwrap();
        assert!((j1 - 30.0).abs() < 0.012, "{v:#}");
        let at = rows[1]["position_deg"].as_f64().unwrap();
        assert!((at - 29.6).abs() < 1.0, "{v:#}");
        assert_eq!(rows[1]["tracking_max_deg"], 0.0);
        assert!(rows[0].get("sent_nm").is_none(), "{v:#}");
        // Left in the safe state: the WHJ joint back in position mode, holding.
        let s = whj.with_bus(|b| b.joint(1).unwrap().state());
        // (still turning at 30°/s when the play ended: its position loop brakes it to
        // the angle where the mode changed)
        assert_eq!((s.mode, s.enabled, s.target_speed), (3, true, 0), "{s:?}");
        assert!(
            (f64::from(s.target_position) * 1e-4 - at).abs() < 1.0,
            "{s:?}"
        );
        assert_eq!(
            wck.with_bus(|b| b.servo(0).unwrap().mode()),
            robobus_sim::wck::Mode::Passive
        );
    }

    #[test]
    fn a_csv_of_efforts_drives_a_whj_joint_in_current_mode() {
        let (station, _wck, whj) = station();
        let v = play(&station, "time_s,j1_nm\n0,1\n0.2,1\n").unwrap();
        assert_eq!(v["failed"], Value::Null, "{v:#}");
        let row = &v["results"][0];
        // 1 N·m is 260 mA on the WHJ30 (3.846 N·m/A), sent in 1 mA counts.
        let nm = row["sent_nm"].as_f64().unwrap();
        assert!((nm - 0.26 * 30.0 / 7.8).abs() < 1e-9, "{v:#}");
        assert!(
            row["position_deg"].as_f64().unwrap() > 0.5,
            "it turned: {v:#}"
        );
        let s = whj.with_bus(|b| b.joint(1).unwrap().state());
        assert_eq!((s.mode, s.target_current), (3, 0), "{s:?}");
    }

    /// The play's summary and j1's row (the first column).
    fn stopped(v: &Value) -> (&Value, &Value) {
        (&v["summary"], &v["results"][0])
    }

    #[test]
    fn an_obstacle_stops_a_velocity_play_within_the_stall_time_and_names_the_joint() {
        let (station, _wck, whj) = station();
        // A stop 5° above where j1 stands, and j1 told to turn up at 30°/s for 2 s: it
        // reaches the stop at about 0.17 s.
        whj.with_bus(|b| {
            let j = b.joint_mut(1).unwrap();
            let at = j.state().physical_deg + 5.0;
            j.set_obstacle(Some(robobus_sim::whj::Obstacle::above(at)));
        });
        let v = play(&station, "time_s,j1_deg_s\n0,30\n2,30\n").unwrap();
        let (s, row) = stopped(&v);
        let events = s["protection"].as_array().unwrap();
        assert_eq!(events.len(), 1, "{s:#}");
        let stop = &events[0];
        assert_eq!(
            (
                &stop["joint"],
                &stop["check"],
                &stop["quantity"],
                &stop["action"]
            ),
            (
                &json!("j1"),
                &json!("stall"),
                &json!("current_a"),
                &json!("stop")
            ),
            "{stop}"
        );
        // The WHJ30's rated current, from the models table.
        assert_eq!(stop["limit"], 7.8, "{stop}");
        let at = stop["at_s"].as_f64().unwrap();
        assert!((at - STALL_AT_S).abs() < 0.001, "{stop}");
        // The current reaches the stall current about 0.3 s into the play (the joint
        // reached the stop at about 0.17 s), and the stall time (0.3 s) later the play
        // stops: at the feedback of the tick at 0.6 s, not at 2 s.
        assert_eq!(s["ticks"], json!(STALL_TICKS), "{s}");
        assert_eq!(row["id"], "j1");
        let error = row["error"].as_str().unwrap();
        assert!(
            error.starts_with("j1: stall protection: current ")
                && error.contains("reached the limit 7.8 A at ")
                && error.contains(
                    "stopped in the safe state (the joint did not move as commanded meanwhile); \
                     its drive disabled"
                ),
            "{error}"
        );
        // j1 (a WHJ30: a pin brake) is disabled, no longer pushing into the stop.
        let j1 = whj.with_bus(|b| b.joint(1).unwrap().state());
        assert!(!j1.enabled && j1.brake_locked, "{j1:?}");
    }

    /// A wheel held still while told to turn at its level 2 (267 mA held on the
    /// simulated 1108, under its 400 mA over-load, so nothing else would stop it): read
    /// at the first tick at or past every 0.25 s (0, 0.26, 0.52, 0.78 s at 50 Hz), the
    /// stall seen at 0.26 s and held for two periods (0.5 s), the play stops at the read
    /// at 0.78 s, not at 2 s, naming the wheel, which is left passive.
    #[test]
    fn a_wheel_held_still_under_velocity_is_stopped_naming_it() {
        let (station, wck, _whj) = station();
        wck.with_bus(|b| b.servo_mut(0).unwrap().hold(true));
        let level_2 = sim_1108_wheel_speeds()[1].to_degrees();
        let v = play(
            &station,
            &format!("time_s,s0_deg_s\n0,{level_2}\n2,{level_2}\n"),
        )
        .unwrap();
        let (s, row) = stopped(&v);
        let events = s["protection"].as_array().unwrap();
        assert_eq!(events.len(), 1, "{s:#}");
        let stop = &events[0];
        assert_eq!(
            (
                &stop["joint"],
                &stop["check"],
                &stop["quantity"],
                &stop["limit"]
            ),
            (
                &json!("s0"),
                &json!("stall"),
                &json!("current_a"),
                &json!(0.2)
            ),
            "{stop}"
        );
        let at = stop["at_s"].as_f64().unwrap();
        assert!((0.78..0.79).contains(&at), "{stop}");
        assert_eq!(s["ticks"], json!(40), "{s}");
        let error = row["error"].as_str().unwrap();
        assert!(
            error.starts_with("s0: stall protection: current 0.27 A reached the limit 0.2 A"),
            "{error}"
        );
        assert_eq!(
            wck.with_bus(|b| b.servo(0).unwrap().mode()),
            robobus_sim::wck::Mode::Passive
        );
    }

    /// A play of positions (through the same protection as velocities: the monitor
    /// `robot.play` feeds) into a hand that grips the wCK servo `s0` 1 s in: each tick's
    /// position move answers with the servo's load, read as a current: 800 mA held
    /// (torque level 3, the servo's own over-load raised to 1800 mA so only the host can
    /// stop it). Its target runs away at 20°/s, so the error passes the stall's 3° at
    /// 1.12 s, and the stall time (0.4 s) later, at 1.52 s, the play stops naming the
    /// servo, which is left passive.
    #[test]
    fn a_play_of_positions_into_a_gripped_wck_servo_is_stopped_naming_it() {
        let (station, wck, _whj) = station();
        wck.with_bus(|b| {
            let s = b.servo_mut(0).unwrap();
            let e = robobus_sim::wck::Eeprom {
                overload: robobus_wck::Overload::new(199).unwrap(),
                ..*s.eeprom()
            };
            s.set_eeprom(e);
        });
        let mut on_progress = |p: &crate::ops::Progress| {
            if p.done == 50 {
                wck.with_bus(|b| b.servo_mut(0).unwrap().hold(true));
            }
        };
        let mut control = Control::none().with_progress(&mut on_progress);
        let request = req(json!({
            "op": "robot.play",
            "trajectory": "time_s,s0\n0,0\n3,60\n",
            "rate_hz": 50,
            "torque": 3,
        }));
        let v = serde_json::to_value(run(&station, &request, &mut control).unwrap()).unwrap();
        drop(control);
        let (s, row) = stopped(&v);
        let events = s["protection"].as_array().unwrap();
        assert_eq!(events.len(), 1, "{s:#}");
        let stop = &events[0];
        assert_eq!(
            (&stop["joint"], &stop["check"], &stop["action"]),
            (&json!("s0"), &json!("stall"), &json!("stop")),
            "{stop}"
        );
        let at = stop["at_s"].as_f64().unwrap();
        assert!((1.52..1.53).contains(&at), "{stop}");
        assert_eq!(s["ticks"], json!(77), "{s}");
        assert_eq!(row["id"], "s0");
        let error = row["error"].as_str().unwrap();
        assert!(
            error.starts_with("s0: stall protection: current 0.80 A reached the limit 0.2 A"),
            "{error}"
        );
        assert_eq!(
            wck.with_bus(|b| b.servo(0).unwrap().mode()),
            robobus_sim::wck::Mode::Passive
        );
    }

    /// When the obstacle test's stall stops the play, s, and its ticks by then (at 50 Hz).
    const STALL_AT_S: f64 = 0.6005;
    const STALL_TICKS: u64 = 31;

    #[test]
    fn a_hot_joint_under_velocity_is_derated_then_stopped() {
        let (station, _wck, whj) = station();
        // j1 starts at 81 °C (over the WHJ30's 80 °C derating), and is heated to 86 °C (over
        // the 85 °C stop) at the tick at 0.4 s; the temperature is read every 13 ticks.
        let heat = |celsius: f64| {
            whj.with_bus(|b| b.joint_mut(1).unwrap().set_winding_temperature(celsius));
        };
        heat(81.0);
        let mut on_progress = |p: &crate::ops::Progress| {
            if p.done == 21 {
                heat(86.0);
            }
        };
        let mut control = Control::none().with_progress(&mut on_progress);
        let request = req(json!({
            "op": "robot.play",
            "trajectory": "time_s,j1_deg_s\n0,100\n2,100\n",
            "rate_hz": 50,
        }));
        let v = serde_json::to_value(run(&station, &request, &mut control).unwrap()).unwrap();
        let (s, row) = stopped(&v);
        let events: Vec<(String, String, f64, f64)> = s["protection"]
            .as_array()
            .unwrap()
            .iter()
            .map(|e| {
                (
                    e["check"].as_str().unwrap().to_owned(),
                    e["action"].as_str().unwrap().to_owned(),
                    e["limit"].as_f64().unwrap(),
                    e["at_s"].as_f64().unwrap(),
                )
            })
            .collect();
        assert_eq!(events.len(), 2, "{s:#}");
        assert_eq!(
            (events[0].0.as_str(), events[0].1.as_str()),
            ("thermal", "derate")
        );
        assert!(
            (events[0].2 - 80.0).abs() < 1e-9 && events[0].3 < 0.001,
            "{events:?}"
        );
        assert_eq!(
            (events[1].0.as_str(), events[1].1.as_str()),
            ("thermal", "stop")
        );
        assert!((events[1].2 - 85.0).abs() < 1e-9, "{events:?}");
        assert!((events[1].3 - 0.521).abs() < 0.001, "{events:?}");
        // Derated: held to half its max_velocity (2 rad/s), not the 100°/s asked for.
        let sent = row.get("sent_deg_s").and_then(Value::as_f64);
        assert!(sent.is_none(), "a failed row: {row}");
        let error = row["error"].as_str().unwrap();
        assert!(
            error.starts_with("j1: thermal protection: temperature 86.")
                && error.contains("reached the limit 85 °C at 0.52"),
            "{error}"
        );
        let at = whj.with_bus(|b| b.joint(1).unwrap().state().position_deg);
        // 0.52 s at most at 57.3°/s is under 30°; at 100°/s it would be about 50°.
        assert!(at > 20.0 && at < 30.0, "{at}");
    }

    #[test]
    fn an_effort_that_runs_a_joint_past_its_max_velocity_stops_the_play() {
        let (station, _wck, whj) = station();
        // 4 N·m on a free j1 for 2 s: its current is the command (no stall, no collision),
        // and it speeds up past its max_velocity (2 rad/s, 114.6°/s).
        let v = play(&station, "time_s,j1_nm\n0,4\n2,4\n").unwrap();
        let (s, row) = stopped(&v);
        let events = s["protection"].as_array().unwrap();
        assert_eq!(events.len(), 1, "{s:#}");
        let stop = &events[0];
        assert_eq!(
            (&stop["check"], &stop["quantity"], &stop["action"]),
            (&json!("speed"), &json!("speed_deg_s"), &json!("stop")),
            "{stop}"
        );
        let limit = stop["limit"].as_f64().unwrap();
        assert!((limit - 2f64.to_degrees()).abs() < 1e-9, "{stop}");
        let at = stop["at_s"].as_f64().unwrap();
        // At 0.16 s (134.6°/s at that feedback), not at 2 s.
        assert!((at - 0.1605).abs() < 0.001, "{stop}");
        assert!(
            row["error"]
                .as_str()
                .unwrap()
                .starts_with("j1: speed protection: speed "),
            "{row}"
        );
        // Its current is back to zero, in position mode.
        let j1 = whj.with_bus(|b| b.joint(1).unwrap().state());
        assert_eq!((j1.mode, j1.target_current), (3, 0), "{j1:?}");
    }

    #[test]
    fn a_joint_without_the_interface_or_a_value_past_its_limit_refuses_the_play() {
        let (station, _wck, whj) = station();
        let frames = || {
            whj.with_bus(|b| {
                b.joint(2).unwrap().frames_handled() + b.joint(1).unwrap().frames_handled()
            })
        };
        let before = frames();
        let err = play(&station, "time_s,j2_deg_s\n0,10\n1,10\n").unwrap_err();
        assert_eq!(err.kind(), ErrorKind::BadInput);
        assert!(
            err.to_string().contains(
                "j2 has no velocity interface in the robot file (its interfaces: position)"
            ),
            "{err}"
        );
        let err = play(&station, "time_s,j1_deg_s\n0,10\n1,130\n").unwrap_err();
        assert!(
            err.to_string()
                .contains("trajectory line 3: j1 130 deg/s is outside -114.592..=114.592 deg/s (its max_velocity)"),
            "{err}"
        );
        let err = play(&station, "time_s,j1_nm,s0_deg_s\n0,1,0\n").unwrap_err();
        assert!(
            err.to_string().contains("one interface for every column"),
            "{err}"
        );
        let err = play(&station, "time_s,j1_nm\n0,6\n").unwrap_err();
        assert!(
            err.to_string().contains("-5..=5 N·m (its max_effort)"),
            "{err}"
        );
        assert_eq!(frames(), before, "nothing sent");
    }
}
