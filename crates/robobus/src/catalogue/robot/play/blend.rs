//! A newer trajectory blended into a play of positions between two of its ticks, as
//! `joint_trajectory_controller` replaces the rest of its trajectory with a newer one:
//! no stop, no hold, no tick missed.
//!
//! A front end holds a [`Blend`] and hands it to the run through
//! [`Interaction::play_blend`](crate::catalogue::Interaction::play_blend). To replace the
//! rest of the run it asks for the state the run commands a few ticks ahead
//! ([`Blend::commanded`]: each joint's position, velocity and acceleration at that tick,
//! from the targets the run plays), plans the newer trajectory from it
//! ([`crate::robot::trajectory::ros::plan_from`]), makes it a trajectory of the run's
//! joints ([`Blend::blended`]: a joint it does not name holds its commanded position at
//! that tick) and offers it ([`Blend::offer`]): checked as a play's trajectory is (the
//! robot file's limits and `max_velocity`, the step limits at the run's rate, and the
//! pre-flight on the simulator where it is on, of the rest of the run up to that tick
//! then the blend), then taken by the run's tick loop at that tick, the blend's time 0
//! there. An offer that comes too late (the run passed that tick, or ended) is not taken
//! and says so; a refused one leaves the run as it was.

use std::sync::{Arc, Mutex, PoisonError};

use crate::ops::OpError;
use crate::robot::trajectory::Trajectory;
use crate::robot::trajectory::ros::{self, Start};

/// What a run plays: its trajectory after the lead-in from where the joints were, or
/// the trajectory blended in last from its time 0.
#[derive(Debug, Clone)]
pub(super) struct Course {
    first: Arc<Trajectory>,
    from: Vec<f64>,
    lead_in: f64,
    /// The trajectory blended in last and the run's time its time 0 is at, s.
    blended: Option<(Arc<Trajectory>, f64)>,
}

impl Course {
    /// `traj` after a lead-in of `lead_in` s from `from`.
    pub(super) fn new(traj: &Trajectory, from: &[f64], lead_in: f64) -> Self {
        Self {
            first: Arc::new(traj.clone()),
            from: from.to_vec(),
            lead_in,
            blended: None,
        }
    }

    /// The targets at `t_s` since the start of the run (joint degrees, by column).
    pub(super) fn at(&self, t_s: f64) -> Vec<f64> {
        if let Some((b, origin)) = &self.blended {
            return b.at(t_s - origin);
        }
        if t_s < self.lead_in {
            // From rest to rest: a joint that must accelerate is not asked to jump to its
            // speed (it would lag, and its targets would be held back).
            let f = (1.0 - (std::f64::consts::PI * t_s / self.lead_in).cos()) / 2.0;
            self.from
                .iter()
                .zip(self.first.first())
                .map(|(a, b)| a + (b - a) * f)
                .collect()
        } else {
            self.first.at(t_s - self.lead_in)
        }
    }

    /// `traj` from here on, its time 0 at `origin_s` since the start of the run.
    pub(super) fn blend_in(&mut self, traj: Arc<Trajectory>, origin_s: f64) {
        self.blended = Some((traj, origin_s));
    }

    /// When it ends, s since the start of the run.
    pub(super) fn end_s(&self) -> f64 {
        match &self.blended {
            Some((b, origin)) => origin + b.duration_s(),
            None => self.lead_in + self.first.duration_s(),
        }
    }

    /// With `blended` taken at `origin_s`.
    pub(super) fn with(&self, blended: Option<&(u64, Arc<Trajectory>, f64)>) -> Self {
        let mut c = self.clone();
        if let Some((_, b, origin)) = blended {
            c.blended = Some((Arc::clone(b), *origin));
        }
        c
    }
}

/// The handle through which a front end blends a newer trajectory into a running play
/// of positions, handed to the run by
/// [`Interaction::play_blend`](crate::catalogue::Interaction::play_blend): the state the
/// run commands a few ticks ahead ([`Blend::commanded`]), the newer trajectory planned
/// from it and made one of the run's joints ([`Blend::blended`]), then offered
/// ([`Blend::offer`]): checked as a play's trajectory is, pre-flight included, and taken
/// by the run's tick loop at that tick, or refused and the run left as it was. One run at
/// a time uses it.
#[derive(Debug, Default)]
pub struct Blend {
    pub(super) inner: Mutex<Inner>,
}

#[derive(Debug, Default)]
pub(super) struct Inner {
    /// The run playing now (`None` before its first tick and after its end).
    pub(super) live: Option<Live>,
    /// Runs begun so far (tells an offer for an ended run).
    runs: u64,
    /// The trajectory offered: the tick it is taken at, it, and that tick's time, s.
    pub(super) offered: Option<(u64, Arc<Trajectory>, f64)>,
    /// The blends taken so far.
    taken: Taken,
}

/// The blends a run took so far: how many, and the last one's tick and time since the
/// start of the run, s.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Taken {
    /// How many.
    pub count: u64,
    /// The last one's tick.
    pub tick: u64,
    /// Its time since the start of the run, s.
    pub t_s: f64,
}

#[derive(Debug)]
pub(super) struct Live {
    pub(super) run: u64,
    joints: Vec<String>,
    pub(super) index: Vec<usize>,
    pub(super) course: Course,
    pub(super) period_s: f64,
    /// The last tick run.
    pub(super) tick: Option<u64>,
    /// The last tick of the run as it stands.
    last: u64,
    /// Per column, its WHJ bus's step limit, degrees.
    pub(super) step_limits: Vec<Option<f64>>,
}

/// The state a run commands at one of its ticks: where a blend starts from.
#[derive(Debug, Clone, PartialEq)]
pub struct Commanded {
    pub(super) run: u64,
    /// The tick (of the run).
    pub tick: u64,
    /// Its time since the start of the run, s.
    pub t_s: f64,
    /// How long after the last tick run it is, s (of the run's time).
    pub ahead_s: f64,
    /// The run's joints.
    pub joints: Vec<String>,
    /// Each joint's commanded position, velocity and acceleration at the tick (degrees,
    /// a second, a second²; the velocity and acceleration from the targets of the ticks
    /// either side).
    pub state: Start,
}

impl Commanded {
    /// The state of `joints` (some of the run's, in their order); `None` when one is not
    /// the run's.
    #[must_use]
    pub fn start_of(&self, joints: &[String]) -> Option<Start> {
        let mut s = Start::still(&[]);
        for j in joints {
            let c = self.joints.iter().position(|x| x == j)?;
            s.position_deg.push(self.state.position_deg[c]);
            s.velocity_deg_s.push(self.state.velocity_deg_s[c]);
            s.acceleration_deg_s2
                .push(self.state.acceleration_deg_s2[c]);
        }
        Some(s)
    }
}

pub(super) fn lock(m: &Mutex<Inner>) -> std::sync::MutexGuard<'_, Inner> {
    m.lock().unwrap_or_else(PoisonError::into_inner)
}

impl Blend {
    /// A handle no run uses yet.
    #[must_use]
    pub fn new() -> Self {
        Self::default()
    }

    /// The state the run commands `ahead` ticks after its next one (each joint's
    /// position, velocity and acceleration, with a trajectory offered and not yet taken
    /// counted as taken); `None` when no run plays, or it ends before that tick.
    #[must_use]
    pub fn commanded(&self, ahead: u64) -> Option<Commanded> {
        let g = lock(&self.inner);
        let live = g.live.as_ref()?;
        let now = live.tick?;
        let tick = now.saturating_add(1).saturating_add(ahead);
        if tick > live.last {
            return None;
        }
        let course = live.course.with(g.offered.as_ref());
        let h = live.period_s;
        #[allow(clippy::cast_precision_loss)] // ticks of at most an hour
        let t_s = tick as f64 * h;
        let (before, at, after) = (course.at(t_s - h), course.at(t_s), course.at(t_s + h));
        let velocity = before
            .iter()
            .zip(&after)
            .map(|(a, b)| (b - a) / (2.0 * h))
            .collect();
        let acceleration = before
            .iter()
            .zip(&at)
            .zip(&after)
            .map(|((a, p), b)| (b - 2.0 * p + a) / (h * h))
            .collect();
        #[allow(clippy::cast_precision_loss)]
        let ahead_s = (tick - now) as f64 * h;
        Some(Commanded {
            run: live.run,
            tick,
            t_s,
            ahead_s,
            joints: live.joints.clone(),
            state: Start {
                position_deg: at,
                velocity_deg_s: velocity,
                acceleration_deg_s2: acceleration,
            },
        })
    }

    /// `planned` (a trajectory of some of the run's joints, from `at`'s state at its time
    /// 0) as a trajectory of all the run's joints: one it does not name holds its
    /// commanded position at `at`'s tick.
    ///
    /// # Errors
    ///
    /// [`OpError::BadInput`](OpError::invalid) naming a joint the run does not play.
    pub fn blended(at: &Commanded, planned: &Trajectory) -> Result<Trajectory, OpError> {
        let columns: Vec<Option<usize>> = at
            .joints
            .iter()
            .map(|j| planned.joints().iter().position(|x| x == j))
            .collect();
        if let Some(j) = planned.joints().iter().find(|j| !at.joints.contains(j)) {
            return Err(OpError::invalid(
                "trajectory",
                j,
                format!(
                    "not a joint of the play it would blend into (its joints: {})",
                    at.joints.join(", ")
                ),
            ));
        }
        let rows: Vec<(f64, Vec<f64>)> = ros::times(planned)
            .into_iter()
            .map(|t| {
                let p = planned.at(t);
                let row = columns
                    .iter()
                    .zip(&at.state.position_deg)
                    .map(|(c, &hold)| c.and_then(|c| p.get(c).copied()).unwrap_or(hold))
                    .collect();
                (t, row)
            })
            .collect();
        parse(&at.joints, &rows)
    }

    /// The blends taken so far.
    #[must_use]
    pub fn taken(&self) -> Taken {
        lock(&self.inner).taken
    }

    /// A run begins: its joints (the robot file's `index`), what it plays, its period and
    /// last tick, and its columns' step limits.
    pub(super) fn begin(
        &self,
        (joints, index): (&[String], &[usize]),
        course: &Course,
        period_s: f64,
        last: u64,
        step_limits: Vec<Option<f64>>,
    ) {
        let mut g = lock(&self.inner);
        g.runs += 1;
        g.offered = None;
        g.live = Some(Live {
            run: g.runs,
            joints: joints.to_vec(),
            index: index.to_vec(),
            course: course.clone(),
            period_s,
            tick: None,
            last,
            step_limits,
        });
    }

    /// The run is at tick `k`: the trajectory offered for it (or a tick it skipped) and
    /// the run's time its time 0 is at, taken.
    pub(super) fn at_tick(&self, k: u64) -> Option<(Arc<Trajectory>, f64)> {
        let mut g = lock(&self.inner);
        let take = g.offered.as_ref().is_some_and(|o| o.0 <= k);
        let taken = if take { g.offered.take() } else { None };
        if let Some((tick, _, origin)) = &taken {
            g.taken = Taken {
                count: g.taken.count + 1,
                tick: *tick,
                t_s: *origin,
            };
        }
        if let Some(live) = g.live.as_mut() {
            live.tick = Some(k);
            if let Some((_, b, origin)) = &taken {
                live.course.blended = Some((Arc::clone(b), *origin));
            }
        }
        taken.map(|(_, b, origin)| (b, origin))
    }

    /// The run's last tick is now `last`.
    pub(super) fn last(&self, last: u64) {
        if let Some(live) = lock(&self.inner).live.as_mut() {
            live.last = last;
        }
    }

    /// The run ended (an offer not taken is dropped).
    pub(super) fn end(&self) {
        let mut g = lock(&self.inner);
        g.live = None;
        g.offered = None;
    }
}

/// The trajectory of `rows` (time, joint degrees) of `joints`.
pub(super) fn parse(joints: &[String], rows: &[(f64, Vec<f64>)]) -> Result<Trajectory, OpError> {
    Trajectory::parse(&crate::robot::trajectory::ros::csv_of(joints, rows))
        .map_err(|e| OpError::invalid("trajectory", "(blend)", e.to_string()))
}
