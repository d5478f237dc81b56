//! `robot.play`'s tick loop ([`Player`]): each tick's targets (the lead-in from rest to
//! rest, then the trajectory), held back where a WHJ joint lags or a derated joint may
//! not go so fast, sent to every bus at the same instant, what the joints reported fed to
//! the host's protection, and the run's timing.

use std::time::{Duration, Instant};

use super::blend::{Blend, Course};
use super::group::{Group, Outcomes, Sensed, step_limits, steps_of};
use super::{LEAD_IN_PEAK, MAX_TIMED_TICKS, Play, PlayTick, Played, TEMPERATURE_EVERY_S};
use crate::ops::protect::{self, Action, Fault, Monitor, Reading};
use crate::ops::{Control, Failure, OpError, Progress};
use crate::robot::RobotConfig;
use crate::robot::trajectory::Trajectory;
use crate::station::clock::BusClock;

/// What the tick loop measured.
#[derive(Debug, Default)]
pub(super) struct Timing {
    pub(super) ticks: u64,
    pub(super) overruns: u64,
    pub(super) skew: Vec<Duration>,
    pub(super) late: Vec<Duration>,
    pub(super) interrupted: bool,
}

pub(super) struct Player<'a> {
    traj: &'a Trajectory,
    /// The trajectory's joints in the robot file, by column.
    index: Vec<usize>,
    from: &'a [f64],
    /// What it plays: the lead-in, the trajectory, and a trajectory blended in.
    course: Course,
    /// Through which a front end blends a newer trajectory in (`None`: none).
    pub(super) blend: Option<&'a Blend>,
    period: Duration,
    groups: &'a [Group],
    clock: &'a BusClock,
    torque: u8,
    /// Per column, how far a WHJ joint's target may be from where it last reported
    /// itself (`None`: a wCK servo, which takes any target in its range).
    steps: Vec<Option<f64>>,
    /// Per column, the joint's `max_velocity`, degrees a second (a derated joint keeps
    /// its share of it).
    max_speed_deg: Vec<f64>,
    /// The host's protection of the joints, by column.
    monitor: Monitor,
    /// Its events so far.
    pub(super) faults: Vec<Fault>,
    /// The first target sent short of the trajectory's (what the pre-flight refuses).
    pub(super) held_back: Option<HeldBack>,
}

/// A target sent short of the trajectory's: the tick, its time, the column, what was
/// sent and what the trajectory asked, degrees.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct HeldBack {
    pub(super) tick: u64,
    pub(super) t_s: f64,
    pub(super) column: usize,
    pub(super) sent: f64,
    pub(super) target: f64,
}

impl From<(u64, f64, usize, f64, f64)> for HeldBack {
    fn from((tick, t_s, column, sent, target): (u64, f64, usize, f64, f64)) -> Self {
        Self {
            tick,
            t_s,
            column,
            sent,
            target,
        }
    }
}

impl<'a> Player<'a> {
    /// The player of `r` for the trajectory `traj` (its columns the robot file's
    /// joints `index`) on `groups` paced by `clock`, from the joints' positions `from`
    /// after the lead-in `lead_in`; `models` the WHJ joints' (by column).
    pub(super) fn new(
        r: &Play,
        config: &RobotConfig,
        (traj, index): (&'a Trajectory, &[usize]),
        (groups, clock): (&'a [Group], &'a BusClock),
        (from, lead_in): (&'a [f64], f64),
        models: &[Option<robobus_whj::units::Model>],
    ) -> Result<Self, OpError> {
        let monitor = Monitor::new(
            clock.now(),
            index
                .iter()
                .zip(models)
                .map(|(&i, &m)| {
                    let j = &config.joints[i];
                    (j.name.clone(), config.protection_of(j, m))
                })
                .collect(),
        );
        Ok(Self {
            traj,
            index: index.to_vec(),
            from,
            course: Course::new(traj, from, lead_in),
            blend: None,
            period: Duration::from_secs_f64(1.0 / r.rate_hz),
            groups,
            clock,
            torque: r.torque,
            steps: steps_of(groups, traj.joints().len())?,
            max_speed_deg: index
                .iter()
                .map(|&i| config.joints[i].max_velocity.to_degrees())
                .collect(),
            monitor,
            faults: Vec::new(),
            held_back: None,
        })
    }
}

/// How long a half-cosine lead-in over `distance` degrees takes to peak at no more than
/// `max_speed` deg/s and `max_accel` deg/s²: its peak speed is pi/2 · d / T, its peak
/// acceleration pi²/2 · d / T².
pub(super) fn lead_in_s(distance: f64, max_speed: f64, max_accel: f64) -> f64 {
    let by_speed = LEAD_IN_PEAK * distance / max_speed;
    let by_accel = std::f64::consts::PI * (distance / (2.0 * max_accel)).sqrt();
    by_speed.max(by_accel)
}

impl Player<'_> {
    /// The targets at `t_s` since the start (joint degrees, by column).
    fn targets(&self, t_s: f64) -> Vec<f64> {
        self.course.at(t_s)
    }

    /// Plays the ticks (a trajectory offered through [`Player::blend`] taken at its
    /// tick); each tick to `on_tick`.
    pub(super) fn run(
        &mut self,
        rows: &mut [Played],
        control: &mut Control<'_>,
        on_tick: &mut dyn FnMut(&PlayTick<'_>) -> Result<(), OpError>,
    ) -> Result<Timing, OpError> {
        let run = self.ticks(rows, control, on_tick);
        if let Some(b) = self.blend {
            b.end();
        }
        run
    }

    fn ticks(
        &mut self,
        rows: &mut [Played],
        control: &mut Control<'_>,
        on_tick: &mut dyn FnMut(&PlayTick<'_>) -> Result<(), OpError>,
    ) -> Result<Timing, OpError> {
        let mut total = self.course.end_s();
        let clock = self.clock;
        let start = clock.now();
        let mut timing = Timing::default();
        let mut before: Option<Vec<f64>> = None;
        let mut last_at: Vec<Option<f64>> = self.from.iter().map(|&f| Some(f)).collect();
        let mut last_sent: Vec<f64> = self.from.to_vec();
        let mut next_temperature = 0.0;
        let period_s = self.period.as_secs_f64();
        let mut k: u64 = 0;
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)] // ≤ 3600 s × 500 Hz
        let last_of = |total: f64| (total / period_s).ceil() as u64;
        let mut last = last_of(total);
        self.begin_blend(period_s, last)?;
        while k <= last {
            let due = start + self.period * u32::try_from(k).unwrap_or(u32::MAX);
            if !control.sleep_with(due, |until| {
                if let Some(t) = until {
                    clock.sleep_until(t);
                }
                clock.now()
            }) {
                timing.interrupted = true;
                break;
            }
            if let Some(end) = self.blend_at(k, &last_of) {
                (total, last) = end;
            }
            let t_s = (due - start).as_secs_f64().min(total);
            let targets = self.targets(t_s);
            let sent = self.held(&targets, &last_at, &last_sent, period_s);
            let temperature = t_s >= next_temperature;
            if temperature {
                next_temperature = t_s + TEMPERATURE_EVERY_S;
            }
            let (sensed, sends) = self.tick(&sent, temperature);
            let stop = self.protect(clock.now(), &sensed, &last_sent);
            last_sent.clone_from(&sent);
            let positions: Vec<Result<f64, Failure>> =
                sensed.into_iter().map(|r| r.map(|s| s.position)).collect();
            if let (Some(first), Some(last)) = (sends.iter().min(), sends.iter().max())
                && timing.skew.len() < MAX_TIMED_TICKS
            {
                timing.skew.push(last.saturating_duration_since(*first));
                timing.late.push(last.saturating_duration_since(due));
            }
            for (c, (row, p)) in rows.iter_mut().zip(&positions).enumerate() {
                let target = targets.get(c).copied().unwrap_or(f64::NAN);
                let prior = before.as_ref().and_then(|b| b.get(c).copied());
                row.take(target, p, prior);
                if let Some(&x) = sent.get(c).filter(|&&x| (x - target).abs() > 1e-9) {
                    row.limited += 1;
                    let at = (timing.ticks, t_s, c, x, target);
                    self.held_back.get_or_insert(HeldBack::from(at));
                }
                if let (Ok(at), Some(slot)) = (p, last_at.get_mut(c)) {
                    *slot = Some(*at);
                }
            }
            let reported: Vec<Option<f64>> =
                positions.iter().map(|p| p.as_ref().ok().copied()).collect();
            on_tick(&PlayTick {
                t_s,
                joints: self.traj.joints(),
                targets: &sent,
                positions: &reported,
            })?;
            before = Some(targets);
            timing.ticks += 1;
            control.report(&Progress::new("play", k + 1, Some(last + 1)));
            if stop {
                break;
            }
            // Ticks a slow one ran past are skipped, not caught up.
            let now = clock.now().saturating_duration_since(start);
            #[allow(clippy::cast_possible_truncation)] // ticks of at most an hour
            let behind = (now.as_nanos() / self.period.as_nanos().max(1)) as u64;
            if behind > k + 1 {
                timing.overruns += behind - k - 1;
                k = behind;
            } else {
                k += 1;
            }
        }
        Ok(timing)
    }

    /// `targets` as sent: a WHJ joint lagging behind (where it was last `at`) no further
    /// than its step allows; a derated one no faster than its share of its `max_velocity`
    /// from what it was sent last (`last_sent`, a tick of `period_s` before).
    fn held(
        &self,
        targets: &[f64],
        last_at: &[Option<f64>],
        last_sent: &[f64],
        period_s: f64,
    ) -> Vec<f64> {
        targets
            .iter()
            .zip(&self.steps)
            .zip(last_at)
            .enumerate()
            .map(|(c, ((&t, step), at))| {
                let t = match (step, at) {
                    (Some(s), Some(a)) => t.clamp(a - s, a + s),
                    _ => t,
                };
                let share = self.monitor.speed_share(c);
                match (share < 1.0, last_sent.get(c), self.max_speed_deg.get(c)) {
                    (true, Some(&prev), Some(&v)) => {
                        let most = share * v * period_s;
                        t.clamp(prev - most, prev + most)
                    }
                    _ => t,
                }
            })
            .collect()
    }

    /// Tells the blend (if any) a run begins: what it plays, its period, its last tick.
    fn begin_blend(&self, period_s: f64, last: u64) -> Result<(), OpError> {
        if let Some(b) = self.blend {
            let limits = step_limits(self.groups, self.index.len())?;
            b.begin(
                (self.traj.joints(), &self.index),
                &self.course,
                period_s,
                last,
                limits,
            );
        }
        Ok(())
    }

    /// At tick `k`: a trajectory blended in at it (or at a tick skipped) plays from here;
    /// the run's new end (s) and last tick (`last_of` the end).
    fn blend_at(&mut self, k: u64, last_of: &dyn Fn(f64) -> u64) -> Option<(f64, u64)> {
        let b = self.blend?;
        let (blended, origin) = b.at_tick(k)?;
        self.course.blend_in(blended, origin);
        let total = self.course.end_s();
        let last = last_of(total).max(k);
        b.last(last);
        Some((total, last))
    }

    /// Feeds what the joints reported at `now` to the protection (the following error
    /// against the targets sent the tick before); whether it stops the run.
    fn protect(
        &mut self,
        now: Instant,
        sensed: &[Result<Sensed, Failure>],
        sent_before: &[f64],
    ) -> bool {
        let mut stop = false;
        for (c, s) in sensed.iter().enumerate() {
            let Ok(s) = s else { continue };
            let reading = Reading {
                at: now,
                position_deg: Some(s.position),
                error_deg: sent_before.get(c).map(|t| (s.position - t).abs()),
                target_deg: sent_before.get(c).copied(),
                current_a: s.current_a,
                temperature_c: s.temperature_c,
            };
            for f in self.monitor.feed(c, &reading) {
                stop |= f.action == Action::Stop;
                tracing::warn!("{f}");
                if self.faults.len() < protect::MAX_EVENTS || f.action == Action::Stop {
                    self.faults.push(f);
                }
            }
        }
        stop
    }

    /// Sends one tick's targets, each bus from its own thread (a WHJ joint's temperature
    /// read after its command when `temperature`); each joint's outcome by column and
    /// each bus's first send (this clock).
    fn tick(
        &self,
        targets: &[f64],
        temperature: bool,
    ) -> (Vec<Result<Sensed, Failure>>, Vec<Instant>) {
        let n = targets.len();
        let mut positions: Vec<Result<Sensed, Failure>> = (0..n)
            .map(|_| {
                Err(Failure::of(
                    crate::ErrorKind::Device,
                    &"not commanded this tick",
                ))
            })
            .collect();
        let mut sends = Vec::with_capacity(self.groups.len());
        let clock = self.clock;
        let torque = self.torque;
        let results: Vec<(Option<Instant>, Outcomes)> = std::thread::scope(|s| {
            let handles: Vec<_> = self
                .groups
                .iter()
                .enumerate()
                .map(|(i, g)| {
                    s.spawn(move || {
                        // Every bus is at the tick (the clock slept them there); the
                        // instant its first send goes, on the clock's time line.
                        let sent = clock.bus_now(i);
                        (sent, g.send(targets, torque, temperature))
                    })
                })
                .collect();
            handles
                .into_iter()
                .map(|h| h.join().unwrap_or((None, Vec::new())))
                .collect()
        });
        for (sent, outcomes) in results {
            sends.extend(sent);
            for (c, o) in outcomes {
                if let Some(slot) = positions.get_mut(c) {
                    *slot = o;
                }
            }
        }
        (positions, sends)
    }
}
