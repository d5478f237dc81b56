//! The host's protection of followed joint targets (a ROS 2 position stream through the
//! bridge): every command's answers go to the one protection monitor
//! ([`crate::ops::protect::Monitor`]), as `robot.play`'s ticks do.
//!
//! Each joint's reading is where it reported itself at its command (the feedback of its
//! servo frame or its move) against the position it was sent by the command before, a
//! WHJ joint's current or a wCK servo's load (its move's reply, read as a current), and
//! every [`TEMPERATURE_EVERY`] its temperature (a status query). A derated joint is
//! stepped at its share of its `max_velocity` (per second since its last command). A
//! stop brings the joint that tripped to its safe stop ([`SafeState::apply`]: disabled
//! where every product of its model has a pin brake, else held where it is; a wCK servo
//! passive) and latches: every later command is refused whole, nothing sent, naming the
//! fault, until [`Follower::resume`](super::Follower::resume).

use std::sync::{Mutex, PoisonError};
use std::time::{Duration, Instant};

use robobus_whj::units::Model;

use super::{FollowedJoint, Units};
use crate::ops::protect::{self, Action, Fault, MAX_EVENTS, Monitor};
use crate::ops::{DeviceResult, ErrorKind, Failure, Family, OpError};
use crate::station::Station;
use crate::station::clock::BusClock;
use crate::station::jog::guard::{model, reading_of, safe_stop, temperature_of};
use crate::station::jog::{JogRequest, Jogged};

/// How often each WHJ joint's temperature is read while commands come.
pub(super) const TEMPERATURE_EVERY: Duration = crate::station::jog::guard::TEMPERATURE_EVERY;

/// What the guard keeps between commands.
#[derive(Debug)]
struct State {
    /// Made at the first command (the joints' models are known once they were jogged).
    monitor: Option<Monitor>,
    models: Vec<Option<Model>>,
    /// Per joint, the device position last sent (WHJ degrees, wCK steps) and when.
    last_sent: Vec<Option<(Instant, f64)>>,
    next_temperature: Option<Instant>,
    /// The stop, once one came.
    stopped: Option<Fault>,
    /// Every event, the last [`MAX_EVENTS`].
    events: Vec<Fault>,
}

/// The protection of a [`Follower`](super::Follower)'s joints.
#[derive(Debug)]
pub(super) struct Guard {
    clock: BusClock,
    /// Per joint, its index in the robot file (its limits, its `max_velocity`).
    joints: Vec<usize>,
    state: Mutex<State>,
}

impl Guard {
    /// The guard of `joints` (their indices in the station's robot file).
    pub(super) fn new(station: &Station, joints: Vec<usize>) -> Result<Self, OpError> {
        let config = station.robot().ok_or_else(|| {
            OpError::invalid("robot", "none", "protection needs the robot file's joints")
        })?;
        let n = joints.len();
        Ok(Self {
            clock: BusClock::of(station, config)?,
            joints,
            state: Mutex::new(State {
                monitor: None,
                models: vec![None; n],
                last_sent: vec![None; n],
                next_temperature: None,
                stopped: None,
                events: Vec::new(),
            }),
        })
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, State> {
        self.state.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// The stop that latched, if any.
    pub(super) fn stopped(&self) -> Option<Fault> {
        self.lock().stopped.clone()
    }

    /// The events so far (the last 256), in order.
    pub(super) fn events(&self) -> Vec<Fault> {
        self.lock().events.clone()
    }

    /// Clears a stop: commands are taken again (the monitor starts afresh).
    pub(super) fn resume(&self) {
        let mut s = self.lock();
        s.stopped = None;
        s.monitor = None;
        s.last_sent.fill(None);
    }

    /// The refusal of a command after a stop, one failure per joint (nothing sent).
    pub(super) fn refusal(
        &self,
        joints: &[FollowedJoint],
    ) -> Option<Vec<DeviceResult<String, Jogged>>> {
        let stop = self.lock().stopped.clone()?;
        Some(
            joints
                .iter()
                .map(|j| {
                    DeviceResult::failed(
                        j.name.clone(),
                        Failure::of(
                            ErrorKind::Refused,
                            &format!(
                                "protection stopped the followed joints ({stop}); nothing was \
                                 sent: resume once the cause is cleared"
                            ),
                        ),
                    )
                })
                .collect(),
        )
    }

    /// A derated joint's target: at most its share of `max_velocity` (device units a
    /// second) since its last command.
    pub(super) fn derate(&self, station: &Station, plan: &mut [JogRequest]) {
        let s = self.lock();
        let Some(monitor) = &s.monitor else { return };
        let now = self.clock.now();
        let Some(config) = station.robot() else {
            return;
        };
        for (i, jog) in plan.iter_mut().enumerate() {
            let share = monitor.speed_share(i);
            let (Some(Some((at, prev))), Some(j)) = (
                s.last_sent.get(i),
                self.joints.get(i).and_then(|&k| config.joints.get(k)),
            ) else {
                continue;
            };
            if share >= 1.0 {
                continue;
            }
            let per_s = match jog.family {
                Family::Wck => {
                    j.max_velocity.to_degrees() / robobus_wck::Position::DEGREES_PER_STEP
                }
                _ => j.max_velocity.to_degrees(),
            };
            let dt = now.saturating_duration_since(*at).as_secs_f64();
            let most = share * per_s * dt;
            jog.target = jog.target.clamp(prev - most, prev + most);
        }
    }

    /// Feeds the answers of one command to the monitor; on a stop, brings the joint that
    /// tripped to its safe stop, fails its result with the fault and latches.
    pub(super) fn watch(
        &self,
        station: &Station,
        joints: &[FollowedJoint],
        mut results: Vec<DeviceResult<String, Jogged>>,
    ) -> Vec<DeviceResult<String, Jogged>> {
        let now = self.clock.now();
        let mut s = self.lock();
        if s.monitor.is_none() {
            let Some(config) = station.robot() else {
                return results;
            };
            s.models = joints
                .iter()
                .map(|j| model(station, j.family, &j.bus, j.id))
                .collect();
            let limits = joints
                .iter()
                .zip(&self.joints)
                .zip(&s.models)
                .map(|((f, &k), &m)| {
                    let limits = config
                        .joints
                        .get(k)
                        .map_or(protect::Limits::OFF, |j| config.protection_of(j, m));
                    (f.name.clone(), limits)
                })
                .collect();
            s.monitor = Some(Monitor::new(now, limits));
        }
        let temperature = s.next_temperature.is_none_or(|t| now >= t);
        if temperature {
            s.next_temperature = Some(now + TEMPERATURE_EVERY);
        }
        let mut stop: Option<(usize, Fault)> = None;
        for (i, (j, r)) in joints.iter().zip(&results).enumerate() {
            let crate::ops::Outcome::Ok(jogged) = &r.outcome else {
                continue;
            };
            // The device position it answered with: WHJ degrees, wCK steps.
            let key = match j.units {
                Units::Whj(_) => "position_deg",
                Units::Wck(_) => "position",
            };
            let position = jogged.feedback.get(key).and_then(serde_json::Value::as_f64);
            let deg = |device: f64| match j.units {
                Units::Whj(_) => device,
                Units::Wck(_) => device * robobus_wck::Position::DEGREES_PER_STEP,
            };
            let before = s.last_sent.get(i).copied().flatten().map(|(_, p)| deg(p));
            let reading = reading_of(
                now,
                &jogged.feedback,
                position,
                before,
                deg,
                temperature
                    .then(|| temperature_of(station, j.family, &j.bus, j.id))
                    .flatten(),
            );
            if let Some(slot) = s.last_sent.get_mut(i) {
                *slot = Some((now, jogged.sent));
            }
            let faults = s
                .monitor
                .as_mut()
                .map(|m| m.feed(i, &reading))
                .unwrap_or_default();
            for f in faults {
                tracing::warn!("{f}");
                if f.action == Action::Stop && stop.is_none() {
                    stop = Some((i, f.clone()));
                }
                if s.events.len() == MAX_EVENTS {
                    s.events.remove(0);
                }
                s.events.push(f);
            }
        }
        if let Some((i, fault)) = stop {
            let model = s.models.get(i).copied().flatten();
            s.stopped = Some(fault.clone());
            drop(s);
            let end = joints.get(i).map_or_else(String::new, |j| {
                safe_stop(station, j.family, &j.bus, j.id, model)
            });
            if let Some(r) = results.get_mut(i) {
                *r = DeviceResult::failed(
                    r.id.clone(),
                    Failure::of(ErrorKind::Device, &format!("{fault}{end}")),
                );
            }
        }
        results
    }
}

#[cfg(all(test, feature = "sim"))]
mod tests {
    #![allow(clippy::unwrap_used)]

    use std::time::Duration;

    use crate::ops::{ErrorKind, Outcome};
    use crate::station::clock::BusClock;
    use crate::station::follow::Follower;

    #[test]
    fn a_followed_joint_pushing_into_an_obstacle_is_stopped_and_later_commands_refused() {
        let file = "[buses.sim-whj]\nkind = \"whj-external\"\n\n\
            [[joints]]\nname = \"j1\"\nbus = \"sim-whj\"\nid = 1\nlimits = [-2.0, 2.0]\n\
            max_velocity = 2.0\nmax_acceleration = 20.0\n\n\
            [[joints]]\nname = \"j2\"\nbus = \"sim-whj\"\nid = 2\nlimits = [-2.0, 2.0]\n\
            max_velocity = 2.0\nmax_acceleration = 20.0\n";
        let (station, whj) = crate::station::follow::testing::enabled(file, "1-2");
        whj.with_bus(|b| {
            b.joint_mut(1)
                .unwrap()
                .set_obstacle(Some(robobus_sim::whj::Obstacle::above(5.0)));
        });
        let follower = Follower::new(&station).unwrap();
        let clock = BusClock::of(&station, station.robot().unwrap()).unwrap();
        let start = clock.now();
        // A position stream at 50 Hz: j1 toward 30° at 20°/s, j2 still.
        let mut stopped_at = None;
        for k in 0..100u32 {
            clock.sleep_until(start + Duration::from_millis(20) * k);
            let t = f64::from(k) * 0.02;
            let plan = follower
                .plan(&[(20.0 * t).min(30.0).to_radians(), 0.0])
                .unwrap();
            let done = follower.apply(&station, &plan);
            if let Outcome::Failed(f) = &done[0].outcome {
                assert_eq!(f.kind, ErrorKind::Device, "{f:?}");
                assert!(
                    f.error.starts_with("j1: stall protection: current ")
                        && f.error.contains("reached the limit 7.8 A at ")
                        && f.error.ends_with("its drive disabled (its brake holds it: holding would keep it pushing or heating)"),
                    "{}",
                    f.error
                );
                stopped_at = Some(t);
                break;
            }
        }
        // j1 reaches the stop at 0.25 s; the stall current comes within 0.25 s and the
        // stall time (0.3 s) later the stream is stopped.
        let t = stopped_at.unwrap();
        assert!((0.55..=0.85).contains(&t), "{t}");
        let events = follower.protection();
        assert_eq!(events.len(), 1, "{events:?}");
        assert_eq!(
            (events[0].joint.as_str(), events[0].quantity),
            ("j1", "current_a")
        );
        let j1 = whj.with_bus(|b| b.joint(1).unwrap().state());
        assert!(!j1.enabled && j1.current_a.abs() < 1e-9, "{j1:?}");
        // Every later command is refused whole, nothing sent: j2 stays where it is.
        let j2 = whj.with_bus(|b| b.joint(2).unwrap().state().target_position);
        let plan = follower.plan(&[0.0, 0.1]).unwrap();
        let done = follower.apply(&station, &plan);
        for r in &done {
            let Outcome::Failed(f) = &r.outcome else {
                panic!("{r:?}")
            };
            assert_eq!(f.kind, ErrorKind::Refused, "{f:?}");
            assert!(
                f.error.contains("protection stopped the followed joints"),
                "{f:?}"
            );
        }
        assert_eq!(
            whj.with_bus(|b| b.joint(2).unwrap().state().target_position),
            j2
        );
        assert!(follower.protection_stop().is_some());
        // Resumed, commands are taken again (j2 moves; j1, disabled, is refused by itself).
        follower.resume();
        let done = follower.apply(&station, &plan);
        assert!(matches!(done[1].outcome, Outcome::Ok(_)), "{:?}", done[1]);
    }

    /// A followed wCK servo gripped by the simulator's hand, its own over-load at its
    /// highest (1800 mA, so only the host can stop it): its move replies answer with the
    /// load it pushes with (read as a current), so the stream is stopped naming it, and
    /// the servo is passive.
    #[test]
    fn a_followed_wck_servo_gripped_is_stopped_naming_it_and_left_passive() {
        let (station, wck, _) = crate::station::Station::simulated_with_handles().unwrap();
        wck.with_bus(|b| {
            let s = b.servo_mut(1).unwrap();
            let e = robobus_sim::wck::Eeprom {
                overload: robobus_wck::Overload::new(199).unwrap(),
                ..*s.eeprom()
            };
            s.set_eeprom(e);
            s.hold(true);
        });
        let follower = Follower::new(&station).unwrap();
        let s1 = follower
            .joints()
            .iter()
            .position(|j| j.name == "s1")
            .unwrap();
        // s1 toward 30°, every other joint where it is (the WHJ joints, not enabled,
        // refuse their steps by themselves).
        let mut targets = vec![0.0; follower.joints().len()];
        targets[s1] = 30f64.to_radians();
        let clock = BusClock::of(&station, station.robot().unwrap()).unwrap();
        let start = clock.now();
        // A position stream at 50 Hz toward 30°.
        let mut stopped_at = None;
        for k in 0..100u32 {
            clock.sleep_until(start + Duration::from_millis(20) * k);
            let plan = follower.plan(&targets).unwrap();
            let done = follower.apply(&station, &plan);
            if let Outcome::Failed(f) = &done[s1].outcome {
                assert_eq!(f.kind, ErrorKind::Device, "{f:?}");
                assert!(
                    f.error.starts_with(
                        "s1: stall protection: current 1.20 A reached the limit 0.2 A at "
                    ) && f
                        .error
                        .ends_with("; passive (its torque off: holding would keep it pushing)"),
                    "{}",
                    f.error
                );
                stopped_at = Some(k);
                break;
            }
        }
        assert!(stopped_at.is_some(), "never stopped");
        let events = follower.protection();
        assert_eq!(events.len(), 1, "{events:?}");
        assert_eq!(
            (events[0].joint.as_str(), events[0].quantity),
            ("s1", "current_a")
        );
        // s1 pushes with 1.2 A from its second command (0.04 s); the wCK stall time
        // (0.4 s) later the stream is stopped.
        assert!((events[0].at_s - 0.443).abs() < 0.005, "{:?}", events[0]);
        wck.with_bus(|b| {
            let s = b.servo(1).unwrap();
            assert_eq!(s.mode(), robobus_sim::wck::Mode::Passive);
            assert_eq!(
                s.overload_trips(),
                0,
                "the host stopped it, not its own protection"
            );
        });
    }
}
