//! The trajectory interface on the built-in simulated robot (its simulators on their
//! virtual clocks: a trajectory plays faster than real time, each tick at its instant).

#![allow(clippy::unwrap_used, clippy::panic)] // tests

use std::sync::atomic::AtomicBool;
use std::sync::{Arc, Condvar, Mutex};
use std::time::{Duration, Instant};

use robobus::cdr::{self, JointTrajectory, JointTrajectoryControllerState, JointTrajectoryPoint};

use super::*;
use crate::{BridgeConfig, Keys, run_request};

/// How close to a point a joint must be at the tick the point is due, degrees: the
/// position a joint reports at a tick is the one it answered that tick's command with,
/// before it moved toward it (one tick of a 2 rad/s joint at 50 Hz is 2.3°).
const ON_TIME_DEG: f64 = 1.5;

/// Every controller state and result, and a gate that holds the player at its first
/// tick at or after `pause_at_s` until released.
#[derive(Default)]
struct Collect {
    states: Mutex<Vec<JointTrajectoryControllerState>>,
    results: Mutex<Vec<TrajectoryResult>>,
    changed: Condvar,
    pause_at_s: Option<f64>,
    paused: AtomicBool,
    released: AtomicBool,
}

impl Sink for Collect {
    fn state(&self, msg: &JointTrajectoryControllerState) {
        self.states.lock().unwrap().push(msg.clone());
        let t = msg.reference.time_from_start.as_secs_f64();
        if self.pause_at_s.is_some_and(|p| t >= p) && !self.released.load(Ordering::SeqCst) {
            self.paused.store(true, Ordering::SeqCst);
            self.changed.notify_all();
            let deadline = Instant::now() + Duration::from_secs(20);
            let mut g = self.states.lock().unwrap();
            while !self.released.load(Ordering::SeqCst) && Instant::now() < deadline {
                g = self
                    .changed
                    .wait_timeout(g, Duration::from_millis(20))
                    .unwrap()
                    .0;
            }
        }
    }

    fn result(&self, r: &TrajectoryResult) {
        self.results.lock().unwrap().push(r.clone());
        self.changed.notify_all();
    }
}

impl Collect {
    /// Waits for the `n`th result.
    fn result(&self, n: usize) -> TrajectoryResult {
        let deadline = Instant::now() + Duration::from_secs(60);
        let mut g = self.results.lock().unwrap();
        while g.len() < n {
            assert!(Instant::now() < deadline, "no result {n}: {:?}", *g);
            g = self
                .changed
                .wait_timeout(g, Duration::from_millis(20))
                .unwrap()
                .0;
        }
        g[n - 1].clone()
    }
}

/// A bridge's shared state on the simulated robot, armed, joints 1-7 enabled in position
/// mode, and a thread feeding the guard's heartbeat (as the command thread does) until
/// the returned flag is set.
fn armed() -> (Arc<Shared>, Arc<AtomicBool>) {
    crate::testing::armed(unarmed(), "1-7")
}

fn unarmed() -> Arc<Shared> {
    Shared::new(
        robobus::station::Station::simulated().unwrap(),
        None,
        BridgeConfig::default(),
        Keys::new(None).unwrap(),
    )
    .unwrap()
}

fn point(t: f64, positions: &[f64]) -> JointTrajectoryPoint {
    JointTrajectoryPoint {
        positions: positions.to_vec(),
        time_from_start: cdr::Duration::from_secs_f64(t),
        ..JointTrajectoryPoint::default()
    }
}

fn trajectory(names: &[&str], points: Vec<JointTrajectoryPoint>) -> Vec<u8> {
    JointTrajectory {
        joint_names: names.iter().map(|n| (*n).to_owned()).collect(),
        points,
        ..JointTrajectory::default()
    }
    .encode()
}

fn degrees(s: &Shared, names: &[&str]) -> Vec<f64> {
    let names: Vec<String> = names.iter().map(|n| (*n).to_owned()).collect();
    read(s, &names)
        .unwrap()
        .into_iter()
        .map(Option::unwrap)
        .collect()
}

/// The feedback of the tick at `t_s`, degrees, by joint.
fn feedback_at(states: &[JointTrajectoryControllerState], t_s: f64) -> Vec<f64> {
    let st = states
        .iter()
        .find(|m| (m.feedback.time_from_start.as_secs_f64() - t_s).abs() < 1e-6)
        .unwrap_or_else(|| panic!("no tick at {t_s} s"));
    st.feedback
        .positions
        .iter()
        .map(|p| p.to_degrees())
        .collect()
}

#[test]
fn the_arm_reaches_each_point_on_time_and_the_joints_it_does_not_name_hold() {
    let (s, done) = armed();
    let sink = Arc::new(Collect::default());
    let dyn_sink: Arc<dyn Sink> = sink.clone();
    let before = degrees(&s, &["j1", "j4"]);
    // j3 and j2 (in that order), 20° then back to 5°, the last point with velocities.
    let mut last = point(2.0, &[5_f64.to_radians(), -5_f64.to_radians()]);
    last.velocities = vec![0.0, 0.0];
    let payload = trajectory(
        &["j3", "j2"],
        vec![
            point(1.0, &[20_f64.to_radians(), -10_f64.to_radians()]),
            last,
        ],
    );
    take_up(&s, &dyn_sink, &payload);
    let r = sink.result(1);
    done.store(true, Ordering::SeqCst);
    assert_eq!(r.status, "reached", "{r:?}");
    assert_eq!(r.error_code, Some(0));
    assert_eq!(r.id, 1);
    assert!(
        r.error_string
            .starts_with("reached: the largest end error "),
        "{r:?}"
    );
    for j in &r.joints {
        assert!(j.error_deg.unwrap() <= GOAL_TOLERANCE_DEG, "{j:?}");
    }
    let states = sink.states.lock().unwrap().clone();
    assert_eq!(states[0].joint_names, ["j3", "j2"]);
    // On time: at each point's tick the joints are at it.
    for (t, want) in [(1.0, [20.0, -10.0]), (2.0, [5.0, -5.0])] {
        let at = feedback_at(&states, t);
        for (a, w) in at.iter().zip(want) {
            assert!((a - w).abs() < ON_TIME_DEG, "at {t} s: {at:?} for {want:?}");
        }
    }
    // The reference is the trajectory's, and the error its distance from the feedback.
    let mid = states
        .iter()
        .find(|m| (m.reference.time_from_start.as_secs_f64() - 0.5).abs() < 1e-6)
        .unwrap();
    assert!(
        (mid.reference.positions[0].to_degrees() - 10.0).abs() < 0.5,
        "{mid:?}"
    );
    assert!(
        (mid.error.positions[0] - (mid.reference.positions[0] - mid.feedback.positions[0])).abs()
            < 1e-12
    );
    // j1 and j4 were not named: they did not move.
    let after = degrees(&s, &["j1", "j4"]);
    for (a, b) in after.iter().zip(&before) {
        assert!((a - b).abs() < 0.05, "{after:?} from {before:?}");
    }
    let h = s.trajectories.health();
    assert_eq!((h.started, h.reached, h.refused), (1, 1, 0), "{h:?}");
}

#[test]
fn a_bad_trajectory_is_refused_whole_and_nothing_moves() {
    let (s, done) = armed();
    let sink = Arc::new(Collect::default());
    let dyn_sink: Arc<dyn Sink> = sink.clone();
    let before = degrees(&s, &["j2", "j3"]);
    // The first point fits; the second is outside j3's soft limits (±2 rad).
    let payload = trajectory(
        &["j2", "j3"],
        vec![point(1.0, &[0.1, 0.2]), point(2.0, &[0.1, 2.5])],
    );
    take_up(&s, &dyn_sink, &payload);
    // Faster than max_velocity (2 rad/s) between two points.
    let fast = trajectory(&["j2"], vec![point(1.0, &[0.1]), point(1.1, &[0.5])]);
    take_up(&s, &dyn_sink, &fast);
    // Not a trajectory at all.
    take_up(&s, &dyn_sink, &[0, 1, 0, 0, 9]);
    done.store(true, Ordering::SeqCst);
    let r = sink.result(1);
    assert_eq!(r.status, "refused");
    assert_eq!(r.error_code, Some(cdr::result_code::INVALID_GOAL));
    assert_eq!(
        r.error_string,
        "joint_trajectory: point 1: j3 = 2.5 rad is outside its soft limits -2..=2 rad (the \
         robot file's limits)"
    );
    let r = sink.result(2);
    assert!(
        r.error_string.contains("faster than its max_velocity"),
        "{r:?}"
    );
    let r = sink.result(3);
    assert!(
        r.error_string
            .starts_with("joint_trajectory: header.stamp.sec: the message ends"),
        "{r:?}"
    );
    assert!(sink.states.lock().unwrap().is_empty());
    let after = degrees(&s, &["j2", "j3"]);
    for (a, b) in after.iter().zip(&before) {
        assert!((a - b).abs() < 0.05, "{after:?} from {before:?}");
    }
    let h = s.trajectories.health();
    assert_eq!((h.refused, h.started), (3, 0), "{h:?}");
    assert!(
        h.last_refusal
            .is_some_and(|m| m.contains("header.stamp.sec"))
    );
}

#[test]
fn an_unarmed_bridge_refuses_a_trajectory() {
    let s = unarmed();
    let sink = Arc::new(Collect::default());
    let dyn_sink: Arc<dyn Sink> = sink.clone();
    take_up(
        &s,
        &dyn_sink,
        &trajectory(&["j3"], vec![point(1.0, &[0.2])]),
    );
    let r = sink.result(1);
    assert_eq!(r.status, "refused");
    assert!(
        r.error_string
            .starts_with("joint_trajectory: not armed: motion needs this bridge armed"),
        "{r:?}"
    );
    assert!(sink.states.lock().unwrap().is_empty());
    assert_eq!(s.trajectories.health().refused, 1);
}

/// Starts `first` with the player held at its first tick at or after `pause_at_s`, takes
/// up `second` there, then lets the player go; both results.
fn replace_at(
    pause_at_s: f64,
    first: &[u8],
    second: &[u8],
) -> (
    Arc<Shared>,
    Arc<Collect>,
    TrajectoryResult,
    TrajectoryResult,
) {
    let (s, done) = armed();
    let sink = Arc::new(Collect {
        pause_at_s: Some(pause_at_s),
        ..Collect::default()
    });
    let dyn_sink: Arc<dyn Sink> = sink.clone();
    take_up(&s, &dyn_sink, first);
    let deadline = Instant::now() + Duration::from_secs(30);
    while !sink.paused.load(Ordering::SeqCst) {
        assert!(
            Instant::now() < deadline,
            "the first never reached {pause_at_s} s"
        );
        std::thread::sleep(Duration::from_millis(5));
    }
    take_up(&s, &dyn_sink, second);
    sink.released.store(true, Ordering::SeqCst);
    sink.changed.notify_all();
    let (a, b) = (sink.result(1), sink.result(2));
    done.store(true, Ordering::SeqCst);
    (s, sink, a, b)
}

/// j3's and j2's output (the targets sent), degrees, and the time each tick was published
/// at, s: per tick in order.
fn outputs(states: &[JointTrajectoryControllerState]) -> Vec<(f64, f64, f64)> {
    states
        .iter()
        .map(|m| {
            (
                m.output.time_from_start.as_secs_f64(),
                m.output.positions[0].to_degrees(),
                m.output.positions[1].to_degrees(),
            )
        })
        .collect()
}

/// As `joint_trajectory_controller` replaces the rest of a trajectory: the newer one
/// (j3 only, to 10° at 1 s with velocity and acceleration 0: a quintic) starts from the
/// position, velocity and acceleration the playing one (j3 to 60° and j2 to -30° in 3 s:
/// 20°/s and -10°/s) commands at the swap tick, in the same run: no stop, no held tick,
/// no jump. The swap is `BLEND_AHEAD_TICKS` after the tick it came at (1.00 s), at 1.32 s:
/// j3 commanded at 26.4° and 20°/s; j2, which the newer one does not name, holds its
/// commanded -13.2° from there. The newer one's point is reached on time (1 s after it
/// came: its 0.68 s from the swap).
#[test]
fn a_newer_trajectory_is_blended_in_from_the_commanded_state_without_a_stop() {
    let first = trajectory(
        &["j3", "j2"],
        vec![point(3.0, &[60_f64.to_radians(), -30_f64.to_radians()])],
    );
    let mut to = point(1.0, &[10_f64.to_radians()]);
    to.velocities = vec![0.0];
    to.accelerations = vec![0.0];
    let (s, sink, first, second) = replace_at(1.0, &first, &trajectory(&["j3"], vec![to]));
    assert_eq!(
        (first.id, first.status, first.error_code),
        (1, "replaced", None),
        "{first:?}"
    );
    assert_eq!(
        first.error_string,
        "replaced by trajectory 2, blended in at 1.320 s of this one from the position, \
         velocity and acceleration it commanded there (no stop)"
    );
    assert_eq!((second.id, second.status), (2, "reached"), "{second:?}");
    assert_eq!(second.joints.len(), 1);
    assert!((second.joints[0].position_deg.unwrap() - 10.0).abs() <= GOAL_TOLERANCE_DEG);
    let states = sink.states.lock().unwrap().clone();
    let out = outputs(&states);
    // One run, a tick every 20 ms: the first's ticks up to 1.30 s, then the newer one's
    // from its 0 s (the run's 1.32 s).
    let swap = out
        .iter()
        .position(|o| o.0 == 0.0 && o.1 > 20.0)
        .expect("no blended tick");
    assert_eq!(swap, 66, "{out:?}");
    assert!((out[swap - 1].0 - 1.30).abs() < 1e-9, "{:?}", out[swap - 1]);
    for (k, o) in out[swap..].iter().enumerate().take(40) {
        #[allow(clippy::cast_precision_loss)]
        let want = k as f64 * 0.02;
        assert!((o.0 - want).abs() < 1e-6, "tick {k} after the swap: {o:?}");
    }
    // j3: at the swap tick exactly where the first commanded it; its step per tick goes
    // on as it was (0.4° at 20°/s), no stop, no jump: the change in a step is what a tick
    // of the quintic gives (its jerk at the start, under 0.01°; then at most 0.128°: down
    // to -54°/s and back to rest at 10° in 0.68 s, at most 320°/s²).
    assert!((out[swap].1 - 26.4).abs() < 1e-9, "{:?}", out[swap]);
    let step = |k: usize| out[k].1 - out[k - 1].1;
    for k in swap - 3..=swap {
        assert!((step(k) - 0.4).abs() < 1e-9, "step {k}: {}", step(k));
    }
    assert!((step(swap + 1) - 0.4).abs() < 0.01, "{}", step(swap + 1));
    for k in swap + 1..swap + 34 {
        assert!(
            (step(k + 1) - step(k)).abs() < 0.13,
            "tick {k}: {} then {}",
            step(k),
            step(k + 1)
        );
    }
    // j2 went on at -10°/s to the swap and holds its commanded -13.2° from there.
    assert!((out[swap - 1].2 + 13.0).abs() < 1e-9, "{:?}", out[swap - 1]);
    for o in &out[swap..] {
        assert!((o.2 + 13.2).abs() < 1e-9, "{o:?}");
    }
    // On time: at its 0.68 s the reference is the point, and j3 is at it.
    let at = states
        .iter()
        .rev()
        .find(|m| (m.reference.time_from_start.as_secs_f64() - 0.68).abs() < 1e-6)
        .unwrap();
    assert!(
        (at.reference.positions[0].to_degrees() - 10.0).abs() < 1e-9,
        "{at:?}"
    );
    assert!(
        (at.feedback.positions[0].to_degrees() - 10.0).abs() < ON_TIME_DEG,
        "{at:?}"
    );
    let h = s.trajectories.health();
    assert_eq!(
        (h.started, h.replaced, h.reached, h.refused),
        (2, 1, 1, 0),
        "{h:?}"
    );
}

/// A newer trajectory whose blend from the commanded state would take a joint past its
/// limits is refused whole, and the one playing plays on to its end: j3 at 60°/s is
/// commanded at 49.2° at the swap (0.82 s); back to 30° at rest 0.28 s later it would
/// swing to -156°/s, its acceleration 2005°/s² 0.04 s after the swap, past its
/// `max_acceleration` (1500°/s²). From standstill where it is (about 30°) the same
/// trajectory would fit.
#[test]
fn a_blend_past_a_limit_from_the_commanded_state_is_refused_and_the_one_playing_plays_on() {
    // To 60° in 1 s, then held there to 1.5 s.
    let at = [60_f64.to_radians(), -20_f64.to_radians()];
    let first = trajectory(&["j3", "j2"], vec![point(1.0, &at), point(1.5, &at)]);
    let mut back = point(0.6, &[30_f64.to_radians()]);
    back.velocities = vec![0.0];
    back.accelerations = vec![0.0];
    let (s, _sink, first, second) = replace_at(0.5, &first, &trajectory(&["j3"], vec![back]));
    // The refusal comes first (the first plays on to its end).
    assert_eq!((first.id, first.status), (2, "refused"), "{first:?}");
    assert_eq!(first.error_code, Some(cdr::result_code::INVALID_GOAL));
    assert!(
        first.error_string.starts_with(
            "joint_trajectory: on the curve its velocities and accelerations make, at 0.040 \
             s from the start: j3 accelerates at -2004.9°/s², more than its \
             max_acceleration 1500.0°/s²"
        ),
        "{first:?}"
    );
    assert_eq!((second.id, second.status), (1, "reached"), "{second:?}");
    assert!((second.joints[0].position_deg.unwrap() - 60.0).abs() <= GOAL_TOLERANCE_DEG);
    let h = s.trajectories.health();
    assert_eq!(
        (h.started, h.replaced, h.reached, h.refused),
        (1, 0, 1, 1),
        "{h:?}"
    );
}

/// A newer trajectory naming a joint the one playing does not move replaces it from
/// standstill: the one playing stopped, its joints held, then the newer one played from
/// where they are.
#[test]
fn a_newer_trajectory_naming_another_joint_replaces_the_one_playing_from_standstill() {
    let first = trajectory(&["j3", "j2"], vec![point(3.0, &[60_f64.to_radians(), 0.0])]);
    let second = trajectory(&["j4"], vec![point(1.0, &[-10_f64.to_radians()])]);
    let (s, _sink, first, second) = replace_at(1.0, &first, &second);
    assert_eq!(
        (first.id, first.status, first.error_code),
        (1, "replaced", None)
    );
    assert!(
        first
            .error_string
            .starts_with("replaced by a newer trajectory (its joints held"),
        "{first:?}"
    );
    // It never got near 60°.
    let p = first.joints[0].position_deg.unwrap();
    assert!(p < 40.0, "{first:?}");
    assert_eq!((second.id, second.status), (2, "reached"), "{second:?}");
    assert!((second.joints[0].position_deg.unwrap() + 10.0).abs() <= GOAL_TOLERANCE_DEG);
    let h = s.trajectories.health();
    assert_eq!((h.started, h.replaced, h.reached), (2, 1, 1), "{h:?}");
}

fn stamped(names: &[&str], points: Vec<JointTrajectoryPoint>, start_unix_s: f64) -> Vec<u8> {
    JointTrajectory {
        stamp: cdr::Time::from_unix_ms(start_unix_s * 1e3),
        joint_names: names.iter().map(|n| (*n).to_owned()).collect(),
        points,
        ..JointTrajectory::default()
    }
    .encode()
}

#[test]
fn a_stamp_in_the_past_skips_the_points_already_due_and_one_that_ended_is_refused() {
    let (s, done) = armed();
    let sink = Arc::new(Collect::default());
    let dyn_sink: Arc<dyn Sink> = sink.clone();
    let points = || {
        vec![
            point(1.0, &[10_f64.to_radians()]),
            point(2.0, &[20_f64.to_radians()]),
            point(3.0, &[15_f64.to_radians()]),
        ]
    };
    // Started 1.5 s ago: the point at 1 s is skipped, the one at 2 s is due in 0.5 s.
    take_up(
        &s,
        &dyn_sink,
        &stamped(&["j3"], points(), unix_now_s() - 1.5),
    );
    let r = sink.result(1);
    assert_eq!((r.status, r.skipped_points), ("reached", 1), "{r:?}");
    assert!((r.late_s - 1.5).abs() < 0.5, "{r:?}");
    assert!((r.joints[0].position_deg.unwrap() - 15.0).abs() <= GOAL_TOLERANCE_DEG);
    // It never went to the skipped point's 10° first: j3 rose from 0° straight to 20°.
    let states = sink.states.lock().unwrap().clone();
    let peak = states
        .iter()
        .map(|m| m.reference.positions[0].to_degrees())
        .fold(f64::MIN, f64::max);
    assert!((peak - 20.0).abs() < 0.5, "{peak}");
    // Started 4 s ago: its last point (3 s) is past.
    take_up(
        &s,
        &dyn_sink,
        &stamped(&["j3"], points(), unix_now_s() - 4.0),
    );
    done.store(true, Ordering::SeqCst);
    let r = sink.result(2);
    assert_eq!(r.status, "refused");
    assert_eq!(r.error_code, Some(cdr::result_code::OLD_HEADER_TIMESTAMP));
    assert!(r.error_string.contains("it ended 1."), "{r:?}");
}

#[test]
fn a_stamp_in_the_future_starts_it_then() {
    let (s, done) = armed();
    let sink = Arc::new(Collect::default());
    let dyn_sink: Arc<dyn Sink> = sink.clone();
    let start = unix_now_s() + 0.4;
    take_up(
        &s,
        &dyn_sink,
        &stamped(&["j3"], vec![point(0.5, &[5_f64.to_radians()])], start),
    );
    let r = sink.result(1);
    done.store(true, Ordering::SeqCst);
    assert_eq!((r.status, r.late_s), ("reached", 0.0), "{r:?}");
    // Its first tick was published after the stamp's time, not before.
    let first = sink.states.lock().unwrap()[0].stamp;
    let first_s = f64::from(first.sec) + f64::from(first.nanosec) / 1e9;
    assert!(first_s >= start, "first tick at {first_s}, start {start}");
    // Too far ahead: refused.
    take_up(
        &s,
        &dyn_sink,
        &stamped(&["j3"], vec![point(0.5, &[0.0])], unix_now_s() + 120.0),
    );
    let r = sink.result(2);
    assert_eq!(r.status, "refused");
    assert!(
        r.error_string.contains("more than the 60 s allowed"),
        "{r:?}"
    );
}

#[test]
fn a_joint_robot_play_cannot_move_refuses_the_trajectory_before_anything_moves() {
    let (s, done) = armed();
    run_request(&s, r#"{"op":"whj.disable","joints":"5"}"#).unwrap();
    let sink = Arc::new(Collect::default());
    let dyn_sink: Arc<dyn Sink> = sink.clone();
    let before = degrees(&s, &["j4", "j5"]);
    take_up(
        &s,
        &dyn_sink,
        &trajectory(&["j4", "j5"], vec![point(1.0, &[0.2, 0.2])]),
    );
    let r = sink.result(1);
    done.store(true, Ordering::SeqCst);
    assert_eq!(r.status, "refused", "{r:?}");
    assert_eq!(r.error_code, Some(cdr::result_code::INVALID_GOAL));
    assert!(r.error_string.contains("joint 5 is disabled"), "{r:?}");
    assert!(sink.states.lock().unwrap().is_empty());
    let after = degrees(&s, &["j4", "j5"]);
    for (a, b) in after.iter().zip(&before) {
        assert!((a - b).abs() < 0.05, "{after:?} from {before:?}");
    }
    let h = s.trajectories.health();
    assert_eq!((h.refused, h.aborted), (1, 0), "{h:?}");
}

#[test]
fn disarming_stops_a_trajectory_on_the_way() {
    let (s, done) = armed();
    let sink = Arc::new(Collect {
        pause_at_s: Some(0.5),
        ..Collect::default()
    });
    let dyn_sink: Arc<dyn Sink> = sink.clone();
    take_up(
        &s,
        &dyn_sink,
        &trajectory(&["j3"], vec![point(2.0, &[40_f64.to_radians()])]),
    );
    let deadline = Instant::now() + Duration::from_secs(30);
    while !sink.paused.load(Ordering::SeqCst) {
        assert!(Instant::now() < deadline, "it never reached 0.5 s");
        std::thread::sleep(Duration::from_millis(5));
    }
    s.set_armed(false).unwrap();
    sink.released.store(true, Ordering::SeqCst);
    sink.changed.notify_all();
    let r = sink.result(1);
    done.store(true, Ordering::SeqCst);
    assert_eq!(r.status, "aborted", "{r:?}");
    assert_eq!(
        r.error_code,
        Some(cdr::result_code::PATH_TOLERANCE_VIOLATED)
    );
    // Held near where it was at 0.5 s (10°), far from 40°.
    let at = r.joints[0].position_deg.unwrap();
    assert!(at < 15.0, "{r:?}");
    assert_eq!(s.trajectories.health().aborted, 1);
}

/// A trajectory joint 1 cannot follow (its current limit at 300 mA: it cannot reach
/// 60°/s in time) is refused whole by the pre-flight on the simulator seeded with it:
/// the result names the tick, its time, the joint and the reason, nothing moved, no
/// tick was published, and the health counts it.
#[test]
fn a_trajectory_the_preflight_refuses_is_refused_whole_before_anything_moves() {
    let (s, done) = armed();
    let port = s.station.whj(None).unwrap();
    let j = port
        .bus()
        .joint(robobus_whj::JointId::new(1).unwrap())
        .unwrap();
    j.disable().unwrap();
    j.write_register("LIT_MAX_CURRENT", 300.0).unwrap();
    j.enable().unwrap();
    drop(j);
    drop(port);
    let sink = Arc::new(Collect::default());
    let dyn_sink: Arc<dyn Sink> = sink.clone();
    let before = degrees(&s, &["j1", "j2"]);
    let payload = trajectory(
        &["j1", "j2"],
        vec![
            point(1.0, &[60_f64.to_radians(), 5_f64.to_radians()]),
            point(2.0, &[0.0, 0.0]),
        ],
    );
    take_up(&s, &dyn_sink, &payload);
    let r = sink.result(1);
    done.store(true, Ordering::SeqCst);
    assert_eq!(r.status, "refused", "{r:?}");
    assert_eq!(r.error_code, Some(cdr::result_code::INVALID_GOAL));
    assert!(
        r.error_string
            .starts_with("joint_trajectory: refused by the pre-flight on the simulator: tick ")
            && r.error_string.contains(
                " s: j1 (joint 1 on sim-whj): the joint lagged behind the plan: its set-point \
                 was clamped "
            )
            && r.error_string.ends_with("; nothing moved"),
        "{r:?}"
    );
    assert!(sink.states.lock().unwrap().is_empty());
    let after = degrees(&s, &["j1", "j2"]);
    for (a, b) in after.iter().zip(&before) {
        assert!((a - b).abs() < 0.05, "{after:?} from {before:?}");
    }
    let h = s.trajectories.health();
    assert_eq!(
        (h.refused, h.preflight_refused, h.aborted, h.reached),
        (1, 1, 0, 0),
        "{h:?}"
    );
    assert_eq!(h.last_refusal.as_deref(), Some(r.error_string.as_str()));
}
