//! `NS/joint_trajectory`: ROS 2 trajectories (`trajectory_msgs/msg/JointTrajectory`) played
//! as `joint_trajectory_controller` plays them; their progress on `NS/controller_state`
//! (`control_msgs/msg/JointTrajectoryControllerState`) and their end on
//! `NS/joint_trajectory/result` (JSON, [`TrajectoryResult`]).
//!
//! The semantics are the library's ([`robobus::robot::trajectory::ros`]): this module
//! decodes, waits for a stamp's start, reads where the joints are, hands the checked plan
//! to `robot.play` (admitted as any motion request: armed, through the guard), publishes
//! each tick and the end, and blends a newer trajectory into the one playing
//! ([`robobus::catalogue::robot::Blend`]: from the state it commands
//! `BLEND_AHEAD_TICKS` ahead, between two of its ticks).

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Condvar, Mutex, PoisonError};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use robobus::ErrorKind;
use robobus::catalogue::operation::PlayTick;
use robobus::catalogue::robot::{Blend, Play, Sample};
use robobus::catalogue::whj::PreflightArg;
use robobus::catalogue::{Interaction, NoInteraction, Request, run_typed};
use robobus::cdr::{
    self, JointTrajectory, JointTrajectoryControllerState, JointTrajectoryPoint, result_code,
};
use robobus::ops::{Control, OpError, Outcome, StopToken};
use robobus::robot::trajectory::Trajectory;
use robobus::robot::trajectory::ros::{self, Checked, GOAL_TOLERANCE_DEG, JointEnd};
use serde::Serialize;
use zenoh::Wait as _;
use zenoh::bytes::Encoding;

use crate::{BridgeError, MAX_REQUEST, Shared, zerr};

/// The rate a trajectory is played at, ticks a second (`robot.play`'s default).
pub const TRAJECTORY_RATE_HZ: f64 = 50.0;

/// How many ticks after the playing one's next a newer trajectory is blended in (0.3 s at
/// [`TRAJECTORY_RATE_HZ`]: the time its plan and its pre-flight take); the newer one's
/// points stay due at their `time_from_start` from its stamp.
pub(crate) const BLEND_AHEAD_TICKS: u64 = 15;

/// The keys of the trajectory interface under a namespace prefix (`bot/` or empty).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TrajectoryKeys {
    /// `NS/joint_trajectory`: the trajectories taken.
    pub trajectory: String,
    /// `NS/controller_state`: each tick's reference, feedback, error and output.
    pub state: String,
    /// `NS/joint_trajectory/result`: each trajectory's end (JSON).
    pub result: String,
}

impl TrajectoryKeys {
    /// Under `prefix` (as [`crate::namespace_prefix`] makes it).
    #[must_use]
    pub fn under(prefix: &str) -> Self {
        Self {
            trajectory: format!("{prefix}joint_trajectory"),
            state: format!("{prefix}controller_state"),
            result: format!("{prefix}joint_trajectory/result"),
        }
    }
}

/// How a trajectory ended, as published on `NS/joint_trajectory/result`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TrajectoryResult {
    /// The trajectory's number on this bridge (1, 2, ...: in the order received).
    pub id: u64,
    /// `reached`, `missed` (played, a joint ended outside the tolerance), `aborted`
    /// (stopped on the way: a joint failed, the host's protection, disarming),
    /// `replaced` (by a newer trajectory), `refused` (nothing moved).
    pub status: &'static str,
    /// `control_msgs/action/FollowJointTrajectory`'s result code (0 reached; -1 invalid
    /// goal, -2 invalid joints, -3 old header timestamp, -4 aborted on the way, -5 goal
    /// tolerance violated); `None` for a replaced trajectory.
    pub error_code: Option<i32>,
    /// What happened, in words.
    pub error_string: String,
    /// The goal tolerance, degrees.
    pub tolerance_deg: f64,
    /// Each joint against its last point, read after the end (empty when refused).
    pub joints: Vec<JointEnd>,
    /// Points skipped because they were already due (a stamp in the past).
    pub skipped_points: usize,
    /// How late it started after its stamp, s.
    pub late_s: f64,
}

/// The trajectories' counts in the health.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize)]
pub struct TrajectoryHealth {
    /// Received.
    pub received: u64,
    /// Refused whole (nothing moved), with their reasons in `last_refusal`.
    pub refused: u64,
    /// Of those, refused by the pre-flight on the simulator (a WHJ joint that would lag
    /// behind it, fault or be derated).
    pub preflight_refused: u64,
    /// Replaced by a newer one before this one was taken up.
    pub superseded: u64,
    /// Started.
    pub started: u64,
    /// Ended within the tolerance.
    pub reached: u64,
    /// Ended outside the tolerance.
    pub missed: u64,
    /// Stopped on the way.
    pub aborted: u64,
    /// Replaced by a newer one while playing.
    pub replaced: u64,
    /// The one playing now.
    pub playing: Option<u64>,
    /// The newest refusal.
    pub last_refusal: Option<String>,
}

#[derive(Debug, Default)]
struct Counts {
    received: AtomicU64,
    refused: AtomicU64,
    preflight_refused: AtomicU64,
    superseded: AtomicU64,
    started: AtomicU64,
    reached: AtomicU64,
    missed: AtomicU64,
    aborted: AtomicU64,
    replaced: AtomicU64,
}

fn bump(c: &AtomicU64) {
    c.fetch_add(1, Ordering::Relaxed);
}

/// The one playing.
#[derive(Debug)]
struct Playing {
    id: u64,
    token: StopToken,
    replaced: Arc<AtomicBool>,
    /// Through which a newer one is blended in.
    blend: Arc<Blend>,
    /// The newer ones offered to the blend and not yet taken, by the tick they start at.
    next: Arc<Mutex<Vec<(u64, Current)>>>,
    thread: JoinHandle<()>,
}

/// A trajectory as its player publishes it: its number, its checked message, the
/// reference it plays (the run's joints; from `origin_s` of the run), the points skipped
/// and how late it started.
#[derive(Debug)]
struct Current {
    id: u64,
    checked: Checked,
    reference: Trajectory,
    origin_s: f64,
    skipped: usize,
    late_s: f64,
}

/// Where a trajectory's progress and end go (Zenoh publishers; a test's lists).
pub(crate) trait Sink: Send + Sync {
    fn state(&self, msg: &JointTrajectoryControllerState);
    fn result(&self, r: &TrajectoryResult);
}

/// The trajectory interface's state, shared by the subscriber, its thread and the
/// players.
#[derive(Debug, Default)]
pub(crate) struct Trajectories {
    inbox: Mutex<Option<Vec<u8>>>,
    ready: Condvar,
    playing: Mutex<Option<Playing>>,
    counts: Counts,
    last_refusal: Mutex<Option<String>>,
    next_id: AtomicU64,
}

impl Trajectories {
    /// A message arrived (its payload bounded by the caller): the newest waits, an older
    /// one not yet taken is superseded.
    pub(crate) fn post(&self, payload: Vec<u8>) {
        bump(&self.counts.received);
        let mut inbox = self.inbox.lock().unwrap_or_else(PoisonError::into_inner);
        if inbox.replace(payload).is_some() {
            bump(&self.counts.superseded);
        }
        drop(inbox);
        self.ready.notify_all();
    }

    /// The counts for the health.
    pub(crate) fn health(&self) -> TrajectoryHealth {
        let c = &self.counts;
        let g = |a: &AtomicU64| a.load(Ordering::Relaxed);
        TrajectoryHealth {
            received: g(&c.received),
            refused: g(&c.refused),
            preflight_refused: g(&c.preflight_refused),
            superseded: g(&c.superseded),
            started: g(&c.started),
            reached: g(&c.reached),
            missed: g(&c.missed),
            aborted: g(&c.aborted),
            replaced: g(&c.replaced),
            playing: self
                .playing
                .lock()
                .unwrap_or_else(PoisonError::into_inner)
                .as_ref()
                .filter(|p| !p.thread.is_finished())
                .map(|p| p.id),
            last_refusal: self
                .last_refusal
                .lock()
                .unwrap_or_else(PoisonError::into_inner)
                .clone(),
        }
    }

    /// The newest message, waiting at most `wait`.
    fn take(&self, wait: Duration, stop: &StopToken) -> Option<Vec<u8>> {
        let inbox = self.inbox.lock().unwrap_or_else(PoisonError::into_inner);
        let (mut inbox, _) = self
            .ready
            .wait_timeout_while(inbox, wait, |m| m.is_none() && !stop.is_stopped())
            .unwrap_or_else(PoisonError::into_inner);
        inbox.take()
    }

    /// Waits until `until` unless a newer message or the stop comes first: whether the
    /// time came.
    fn wait_until(&self, until: Instant, stop: &StopToken) -> bool {
        let mut inbox = self.inbox.lock().unwrap_or_else(PoisonError::into_inner);
        loop {
            if inbox.is_some() || stop.is_stopped() {
                return false;
            }
            let now = Instant::now();
            if now >= until {
                return true;
            }
            inbox = self
                .ready
                .wait_timeout(inbox, until - now)
                .unwrap_or_else(PoisonError::into_inner)
                .0;
        }
    }

    /// Stops the one playing (a newer one replaces it, or the bridge ends) and waits for
    /// its end (its joints brought to the robot file's safe state by `robot.play`).
    fn stop_playing(&self, replaced: bool) {
        let playing = self
            .playing
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .take();
        if let Some(p) = playing {
            p.replaced.store(replaced, Ordering::SeqCst);
            p.token.stop();
            let _ = p.thread.join();
        }
    }
}

fn unix_now_s() -> f64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0.0, |d| d.as_secs_f64())
}

fn refused(id: u64, code: i32, message: String) -> TrajectoryResult {
    TrajectoryResult {
        id,
        status: "refused",
        error_code: Some(code),
        error_string: message,
        tolerance_deg: GOAL_TOLERANCE_DEG,
        joints: Vec::new(),
        skipped_points: 0,
        late_s: 0.0,
    }
}

impl Shared {
    fn refuse_trajectory(&self, sink: &dyn Sink, r: &TrajectoryResult) {
        let t = &self.trajectories;
        bump(&t.counts.refused);
        tracing::debug!("trajectory {} refused: {}", r.id, r.error_string);
        *t.last_refusal
            .lock()
            .unwrap_or_else(PoisonError::into_inner) = Some(r.error_string.clone());
        sink.result(r);
    }
}

/// Where `names` are now, degrees (a fresh reading; `None` for a joint that did not
/// answer).
fn read(s: &Shared, names: &[String]) -> Result<Vec<Option<f64>>, OpError> {
    let report = run_typed(
        &s.station,
        &Sample {},
        &mut Control::none(),
        &mut NoInteraction,
    )?;
    Ok(names
        .iter()
        .map(|n| {
            report
                .results
                .iter()
                .find(|r| &r.id == n)
                .and_then(|r| match &r.outcome {
                    Outcome::Ok(x) => Some(x.position_deg),
                    Outcome::Failed(_) => None,
                })
        })
        .collect())
}

/// Where every one of `names` is now, degrees; or why not (one did not answer).
fn read_all(s: &Shared, names: &[String]) -> Result<Vec<f64>, String> {
    let from = read(s, names).map_err(|e| format!("joint_trajectory: {e}"))?;
    if let Some(all) = from.iter().copied().collect::<Option<Vec<f64>>>() {
        return Ok(all);
    }
    let silent: Vec<&str> = names
        .iter()
        .zip(&from)
        .filter(|(_, f)| f.is_none())
        .map(|(n, _)| n.as_str())
        .collect();
    Err(format!(
        "joint_trajectory: {} did not answer: nothing moved",
        silent.join(", ")
    ))
}

/// Takes up one message: refused whole (published, counted), or started in place of the
/// one playing. A stamp in the future is waited for (a newer message meanwhile replaces
/// this one, counted superseded).
pub(crate) fn take_up(s: &Arc<Shared>, sink: &Arc<dyn Sink>, payload: &[u8]) {
    let t = &s.trajectories;
    let id = t.next_id.fetch_add(1, Ordering::Relaxed) + 1;
    let refuse =
        |code: i32, message: String| s.refuse_trajectory(&**sink, &refused(id, code, message));
    let msg = match JointTrajectory::decode(payload) {
        Ok(m) => m,
        Err(e) => return refuse(result_code::INVALID_GOAL, format!("joint_trajectory: {e}")),
    };
    let Some(config) = s.station.robot().cloned() else {
        return refuse(
            result_code::INVALID_JOINTS,
            "joint_trajectory: the station has no robot file".into(),
        );
    };
    if let Err(r) = s.admission.check_motion(s.arming(), "joint_trajectory") {
        return refuse(result_code::INVALID_GOAL, r.to_string());
    }
    let checked = match ros::check(&msg, &config) {
        Ok(c) => c,
        Err(e) => return refuse(e.code, e.message),
    };
    if let Err(e) = checked.check_start(unix_now_s()) {
        return refuse(e.code, e.message);
    }
    let ahead = checked.start_in_s(unix_now_s());
    if ahead > 0.0 && !t.wait_until(Instant::now() + Duration::from_secs_f64(ahead), &s.stop) {
        if !s.stop.is_stopped() {
            bump(&t.counts.superseded);
        }
        return;
    }
    // A start waited for is on time (the thread's wake-up is not the trajectory's delay).
    let late_s = if ahead > 0.0 {
        0.0
    } else {
        (-checked.start_in_s(unix_now_s())).max(0.0)
    };
    // Into the one playing, from the state it commands a few ticks ahead.
    if blend_in(s, sink, id, &checked, late_s) {
        return;
    }
    // Where the joints are (the one playing still moves them: it stops only once this one
    // is found to fit).
    let from = match read_all(s, &checked.joints) {
        Ok(f) => f,
        Err(why) => return refuse(result_code::INVALID_GOAL, why),
    };
    let planned = match ros::plan(&checked, &config, &from, late_s) {
        Ok(p) => p,
        Err(e) => return refuse(e.code, e.message),
    };
    let play = match admitted_play(s, &planned.csv) {
        Ok(p) => p,
        Err(why) => return refuse(result_code::INVALID_GOAL, why),
    };
    // It fits: it replaces the one playing from here.
    t.stop_playing(true);
    if s.stop.is_stopped() {
        return;
    }
    let current = Current {
        id,
        checked,
        reference: planned.trajectory,
        origin_s: 0.0,
        skipped: planned.skipped,
        late_s,
    };
    if let Err(e) = start(s, sink, current, play) {
        refuse(
            result_code::INVALID_GOAL,
            format!("joint_trajectory: cannot start its thread: {e}"),
        );
    }
}

/// The `robot.play` of a planned trajectory (`csv`) at [`TRAJECTORY_RATE_HZ`], pre-flown
/// by default (a trajectory of at most 60 s: `robot.play` runs it first on WHJ
/// simulators seeded with its WHJ joints and refuses it before its first tick), once the
/// admission let it through (armed, the guard's checks); else why not.
fn admitted_play(s: &Shared, csv: &str) -> Result<Play, String> {
    let play = Play {
        trajectory: csv.to_owned(),
        rate_hz: TRAJECTORY_RATE_HZ,
        torque: 2,
        preflight: PreflightArg::default(),
    };
    s.admission
        .admit(s.arming(), Request::RobotPlay(play.clone()))
        .map_err(|r| r.to_string())?;
    Ok(play)
}

/// Starts playing `current` (`play`, its trajectory) on a thread of its own.
fn start(
    s: &Arc<Shared>,
    sink: &Arc<dyn Sink>,
    current: Current,
    play: Play,
) -> std::io::Result<()> {
    let t = &s.trajectories;
    bump(&t.counts.started);
    let id = current.id;
    let token = StopToken::new();
    let replaced = Arc::new(AtomicBool::new(false));
    let blend = Arc::new(Blend::new());
    let next = Arc::new(Mutex::new(Vec::new()));
    let player = Player {
        shared: Arc::clone(s),
        sink: Arc::clone(sink),
        current,
        replaced: Arc::clone(&replaced),
        blend: Arc::clone(&blend),
        next: Arc::clone(&next),
    };
    let run_token = token.clone();
    let thread = std::thread::Builder::new()
        .name(format!("robobus-trajectory-{id}"))
        .spawn(move || player.run(&play, &run_token))?;
    *t.playing.lock().unwrap_or_else(PoisonError::into_inner) = Some(Playing {
        id,
        token,
        replaced,
        blend,
        next,
        thread,
    });
    Ok(())
}

/// Blends `checked` (trajectory `id`, started `late_s` after its stamp) into the one
/// playing as `joint_trajectory_controller` replaces the rest of a trajectory: planned
/// from the position, velocity and acceleration the one playing commands
/// `BLEND_AHEAD_TICKS` ahead (a joint it does not name holds its commanded position
/// there), checked as `robot.play` checks a trajectory (pre-flight included), and
/// taken by the player at that tick. Whether it was handled (blended, or refused and
/// published); `false` when nothing plays, the one playing ends before that tick or
/// passed it meanwhile, or this one names a joint the one playing does not move (it then
/// starts from standstill in its place).
fn blend_in(
    s: &Arc<Shared>,
    sink: &Arc<dyn Sink>,
    id: u64,
    checked: &Checked,
    late_s: f64,
) -> bool {
    let t = &s.trajectories;
    let refuse =
        |code: i32, message: String| s.refuse_trajectory(&**sink, &refused(id, code, message));
    let (blend, next) = {
        let playing = t.playing.lock().unwrap_or_else(PoisonError::into_inner);
        match playing.as_ref().filter(|p| !p.thread.is_finished()) {
            Some(p) => (Arc::clone(&p.blend), Arc::clone(&p.next)),
            None => return false,
        }
    };
    let Some(config) = s.station.robot().cloned() else {
        return false;
    };
    let Some(at) = blend.commanded(BLEND_AHEAD_TICKS) else {
        return false;
    };
    let Some(start) = at.start_of(&checked.joints) else {
        return false;
    };
    let planned = match ros::plan_from(checked, &config, &start, late_s + at.ahead_s) {
        Ok(p) => p,
        Err(e) => {
            refuse(e.code, e.message);
            return true;
        }
    };
    let blended = match Blend::blended(&at, &planned.trajectory) {
        Ok(b) => b,
        Err(e) => {
            refuse(result_code::INVALID_GOAL, format!("joint_trajectory: {e}"));
            return true;
        }
    };
    let play = match admitted_play(s, &planned.csv) {
        Ok(p) => p,
        Err(why) => {
            refuse(result_code::INVALID_GOAL, why);
            return true;
        }
    };
    let current = Current {
        id,
        checked: checked.clone(),
        reference: blended.clone(),
        origin_s: at.t_s,
        skipped: planned.skipped,
        late_s,
    };
    lock(&next).push((at.tick, current));
    let offered = blend.offer(&s.station, &play, &at, &blended, &Control::new(&s.stop));
    if !matches!(offered, Ok(true)) {
        lock(&next).retain(|(_, c)| c.id != id);
    }
    match offered {
        Ok(true) => true,
        Ok(false) => false,
        Err(e) => {
            let message = refusal(t, &e).unwrap_or_else(|| format!("joint_trajectory: {e}"));
            refuse(result_code::INVALID_GOAL, message);
            true
        }
    }
}

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(PoisonError::into_inner)
}

/// What `robot.play` refused a trajectory for before it sent anything, in the result's
/// words (a pre-flight's refusal counted); `None` for another error.
fn refusal(t: &Trajectories, e: &OpError) -> Option<String> {
    match e {
        // Refused by the pre-flight on the simulator before the first tick: the tick, its
        // time, the joint and what the simulated joint did.
        OpError::Preflight(r) => {
            bump(&t.counts.preflight_refused);
            Some(format!(
                "joint_trajectory: refused by the pre-flight on the simulator: tick {} at \
                 {:.3} s: {}: {}; nothing moved",
                r.frame, r.at_s, r.joint, r.reason
            ))
        }
        // Refused before it sent anything (a joint silent, outside its limits, not enabled
        // in position mode; a step too large at its rate).
        e if matches!(e.kind(), ErrorKind::BadInput | ErrorKind::Refused) => {
            Some(format!("joint_trajectory: {e}"))
        }
        _ => None,
    }
}

/// One trajectory being played (and those blended into it).
struct Player {
    shared: Arc<Shared>,
    sink: Arc<dyn Sink>,
    current: Current,
    replaced: Arc<AtomicBool>,
    blend: Arc<Blend>,
    next: Arc<Mutex<Vec<(u64, Current)>>>,
}

/// Publishes each tick as a controller state, and the end of one a newer one was
/// blended into.
struct Progress<'a> {
    shared: &'a Shared,
    sink: &'a dyn Sink,
    current: Current,
    blend: &'a Arc<Blend>,
    next: &'a Mutex<Vec<(u64, Current)>>,
    /// The blends taken so far.
    blends: u64,
}

impl Progress<'_> {
    /// A newer trajectory was blended in at this tick: the one it replaced ends
    /// (`replaced`, its joints as they reported themselves this tick), the newer one is
    /// published from here.
    fn blended(&mut self, tick: &PlayTick<'_>) {
        let taken = self.blend.taken();
        if taken.count == self.blends {
            return;
        }
        self.blends = taken.count;
        let t = &self.shared.trajectories;
        let newer = {
            let mut next = lock(self.next);
            // Offers for earlier ticks were passed over by a later one.
            let newest = next
                .iter()
                .rposition(|(k, _)| *k == taken.tick)
                .map(|i| next.remove(i).1);
            let before = next.len();
            next.retain(|(k, _)| *k > taken.tick);
            for _ in next.len()..before {
                bump(&t.counts.superseded);
            }
            newest
        };
        let Some(newer) = newer else { return };
        bump(&t.counts.started);
        if let Some(p) = t
            .playing
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .as_mut()
        {
            p.id = newer.id;
        }
        let old = std::mem::replace(&mut self.current, newer);
        let ends: Vec<Option<f64>> = old
            .checked
            .joints
            .iter()
            .map(|j| {
                let c = tick.joints.iter().position(|x| x == j)?;
                tick.positions.get(c).copied().flatten()
            })
            .collect();
        let (_, joints) = ros::outcome(&old.checked, &ends);
        bump(&t.counts.replaced);
        self.sink.result(&TrajectoryResult {
            id: old.id,
            status: "replaced",
            error_code: None,
            error_string: format!(
                "replaced by trajectory {}, blended in at {:.3} s of this one from the \
                 position, velocity and acceleration it commanded there (no stop)",
                self.current.id,
                taken.t_s - old.origin_s
            ),
            tolerance_deg: GOAL_TOLERANCE_DEG,
            joints,
            skipped_points: old.skipped,
            late_s: old.late_s,
        });
    }
}

impl Interaction for Progress<'_> {
    fn play_tick(&mut self, tick: &PlayTick<'_>) -> Result<(), OpError> {
        self.blended(tick);
        let rad = |v: &[f64]| v.iter().map(|d| d.to_radians()).collect::<Vec<f64>>();
        // The time since the start of the trajectory playing.
        let t_s = tick.t_s - self.current.origin_s;
        let at = cdr::Duration::from_secs_f64(t_s.max(0.0));
        let point = |positions: Vec<f64>| JointTrajectoryPoint {
            positions,
            time_from_start: at,
            ..JointTrajectoryPoint::default()
        };
        let reference = rad(&self.current.reference.at(t_s));
        // A joint that did not answer this tick: NaN (never an older reading).
        let feedback: Vec<f64> = tick
            .positions
            .iter()
            .map(|p| p.map_or(f64::NAN, f64::to_radians))
            .collect();
        let error = reference
            .iter()
            .zip(&feedback)
            .map(|(r, f)| r - f)
            .collect();
        self.sink.state(&JointTrajectoryControllerState {
            stamp: cdr::Time::from_unix_ms(unix_now_s() * 1e3),
            frame_id: String::new(),
            joint_names: tick.joints.to_vec(),
            reference: point(reference),
            feedback: point(feedback),
            error: point(error),
            output: point(rad(tick.targets)),
        });
        Ok(())
    }

    fn play_blend(&self) -> Option<Arc<Blend>> {
        Some(Arc::clone(self.blend))
    }
}

impl Player {
    fn run(self, play: &Play, token: &StopToken) {
        let s = &self.shared;
        let t = &s.trajectories;
        let _ticket = s.guard.running(token);
        let mut control = Control::new(token);
        let mut progress = Progress {
            shared: s,
            sink: &*self.sink,
            current: self.current,
            blend: &self.blend,
            next: &self.next,
            blends: 0,
        };
        let report = run_typed(&s.station, play, &mut control, &mut progress);
        let current = progress.current;
        // Offers the run ended before taking: superseded.
        for _ in lock(&self.next).drain(..) {
            bump(&t.counts.superseded);
        }
        let ends = read(s, &current.checked.joints)
            .unwrap_or_else(|_| vec![None; current.checked.joints.len()]);
        let (code, joints) = ros::outcome(&current.checked, &ends);
        let worst = joints
            .iter()
            .filter_map(|j| j.error_deg.map(|e| (e, &j.joint)))
            .fold(None, |w: Option<(f64, &String)>, (e, j)| match w {
                Some((we, _)) if we >= e => w,
                _ => Some((e, j)),
            });
        let worst_text = worst.map_or_else(
            || "no joint answered at the end".to_owned(),
            |(e, j)| format!("the largest end error {e:.3}° ({j})"),
        );
        let why_refused = report.as_ref().err().and_then(|e| refusal(t, e));
        let (status, error_code, error_string) = match report {
            _ if self.replaced.load(Ordering::SeqCst) => (
                "replaced",
                None,
                "replaced by a newer trajectory (its joints held where they were, then the \
                 newer one played from there)"
                    .to_owned(),
            ),
            // Refused by `robot.play` before it sent anything (the pre-flight on the
            // simulator; a joint silent, outside its limits, not enabled in position mode;
            // a step too large at its rate).
            Err(_) if why_refused.is_some() => (
                "refused",
                Some(result_code::INVALID_GOAL),
                why_refused.clone().unwrap_or_default(),
            ),
            Err(e) => (
                "aborted",
                Some(result_code::PATH_TOLERANCE_VIOLATED),
                e.to_string(),
            ),
            Ok(r) if r.summary.as_ref().is_some_and(|s| s.interrupted) => (
                "aborted",
                Some(result_code::PATH_TOLERANCE_VIOLATED),
                "stopped on the way (disarmed, the guard's safe stop or the bridge's end); its \
                 buses brought to the robot file's safe state"
                    .to_owned(),
            ),
            Ok(r) if r.failed.is_some() => (
                "aborted",
                Some(result_code::PATH_TOLERANCE_VIOLATED),
                r.error.unwrap_or_else(|| "a joint failed".into()),
            ),
            Ok(_) if code == result_code::SUCCESSFUL => (
                "reached",
                Some(code),
                format!("reached: {worst_text}, within the {GOAL_TOLERANCE_DEG}° tolerance"),
            ),
            Ok(_) => (
                "missed",
                Some(code),
                format!(
                    "played to its end, but {worst_text} is outside the {GOAL_TOLERANCE_DEG}° tolerance"
                ),
            ),
        };
        if status == "refused" {
            *t.last_refusal
                .lock()
                .unwrap_or_else(PoisonError::into_inner) = Some(error_string.clone());
        }
        bump(match status {
            "refused" => &t.counts.refused,
            "reached" => &t.counts.reached,
            "missed" => &t.counts.missed,
            "replaced" => &t.counts.replaced,
            _ => &t.counts.aborted,
        });
        self.sink.result(&TrajectoryResult {
            id: current.id,
            status,
            error_code,
            error_string,
            tolerance_deg: GOAL_TOLERANCE_DEG,
            joints,
            skipped_points: current.skipped,
            late_s: current.late_s,
        });
    }
}

/// The Zenoh publishers of the progress and the ends.
struct Publishers {
    state: zenoh::pubsub::Publisher<'static>,
    result: zenoh::pubsub::Publisher<'static>,
}

impl Sink for Publishers {
    fn state(&self, msg: &JointTrajectoryControllerState) {
        if let Err(e) = self.state.put(msg.encode()).wait() {
            tracing::warn!("controller state: {e}");
        }
    }

    fn result(&self, r: &TrajectoryResult) {
        let text = serde_json::to_string(r).unwrap_or_default();
        if let Err(e) = self.result.put(text).wait() {
            tracing::warn!("trajectory result: {e}");
        }
    }
}

/// The thread that takes up the trajectories, until the bridge stops (then the one
/// playing is stopped and waited for).
pub(crate) fn serve(s: &Arc<Shared>, sink: &Arc<dyn Sink>) {
    while !s.stop.is_stopped() {
        if let Some(payload) = s.trajectories.take(Duration::from_millis(50), &s.stop) {
            take_up(s, sink, &payload);
        }
    }
    s.trajectories.stop_playing(false);
}

/// Declares the subscriber and the publishers on `session`, and starts the thread.
pub(crate) fn declare(
    s: &Arc<Shared>,
    session: &zenoh::Session,
    declared: &mut Vec<Box<dyn std::any::Any + Send>>,
) -> Result<Vec<JoinHandle<()>>, BridgeError> {
    if s.follower.is_none() || s.config.read_only {
        return Ok(Vec::new());
    }
    let prefix = crate::namespace_prefix(s.config.namespace.as_deref())?;
    let keys = TrajectoryKeys::under(&prefix);
    let sink: Arc<dyn Sink> = Arc::new(Publishers {
        state: session
            .declare_publisher(keys.state.clone())
            .encoding(Encoding::APPLICATION_CDR)
            .wait()
            .map_err(zerr)?,
        result: session
            .declare_publisher(keys.result.clone())
            .encoding(Encoding::APPLICATION_JSON)
            .wait()
            .map_err(zerr)?,
    });
    let shared = Arc::clone(s);
    let sub = session
        .declare_subscriber(keys.trajectory)
        .callback(move |sample| {
            let payload = sample.payload();
            if payload.len() > MAX_REQUEST {
                let t = &shared.trajectories;
                bump(&t.counts.received);
                bump(&t.counts.refused);
                *t.last_refusal
                    .lock()
                    .unwrap_or_else(PoisonError::into_inner) = Some(format!(
                    "joint_trajectory: a message of {} bytes: more than the {MAX_REQUEST} read",
                    payload.len()
                ));
                return;
            }
            shared.trajectories.post(payload.to_bytes().into_owned());
        })
        .wait()
        .map_err(zerr)?;
    declared.push(Box::new(sub));
    let shared = Arc::clone(s);
    let thread = std::thread::Builder::new()
        .name("robobus-trajectories".into())
        .spawn(move || serve(&shared, &sink))?;
    Ok(vec![thread])
}

#[cfg(test)]
mod tests;
