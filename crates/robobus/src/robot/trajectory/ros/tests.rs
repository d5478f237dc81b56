#![allow(clippy::float_cmp)] // exact sampled values

use super::*;
use crate::cdr::{Duration, JointTrajectoryPoint, Time};

const ROBOT: &str = r#"
        [buses.a]
        kind = "whj-external"
        [[joints]]
        name = "j1"
        bus = "a"
        id = 1
        limits = [-1.0, 1.0]
        max_velocity = 1.0
        max_acceleration = 10.0
        [[joints]]
        name = "j2"
        bus = "a"
        id = 2
        limits = [-2.0, 2.0]
        max_velocity = 2.0
        max_acceleration = 10.0
    "#;

fn robot() -> RobotConfig {
    RobotConfig::from_toml_str(ROBOT).unwrap()
}

fn point(t: f64, positions: &[f64]) -> JointTrajectoryPoint {
    JointTrajectoryPoint {
        positions: positions.to_vec(),
        time_from_start: Duration::from_secs_f64(t),
        ..JointTrajectoryPoint::default()
    }
}

fn msg(names: &[&str], points: Vec<JointTrajectoryPoint>) -> JointTrajectory {
    JointTrajectory {
        joint_names: names.iter().map(|s| (*s).to_owned()).collect(),
        points,
        ..JointTrajectory::default()
    }
}

#[test]
fn a_subset_of_joints_plays_from_where_they_are_to_each_point_on_time() {
    let m = msg(&["j2"], vec![point(1.0, &[0.5]), point(2.0, &[1.0])]);
    let c = check(&m, &robot()).unwrap();
    assert_eq!(c.index, [1]);
    let p = plan(&c, &robot(), &[10.0], 0.0).unwrap();
    assert_eq!(
        p.csv,
        format!(
            "time_s,j2\n0,10\n1,{}\n2,{}\n",
            0.5_f64.to_degrees(),
            1.0_f64.to_degrees()
        )
    );
    assert_eq!(p.trajectory.at(1.0), [0.5_f64.to_degrees()]);
    assert_eq!(p.skipped, 0);
}

#[test]
fn a_late_stamp_skips_the_points_already_due_and_goes_to_the_next_in_the_time_left() {
    let m = msg(
        &["j1"],
        vec![point(1.0, &[0.1]), point(2.0, &[0.2]), point(3.0, &[0.3])],
    );
    let c = check(&m, &robot()).unwrap();
    let p = plan(&c, &robot(), &[0.0], 1.5).unwrap();
    assert_eq!(p.skipped, 1);
    assert_eq!(
        p.csv,
        format!(
            "time_s,j1\n0,0\n0.5,{}\n1.5,{}\n",
            0.2_f64.to_degrees(),
            0.3_f64.to_degrees()
        )
    );
    let e = plan(&c, &robot(), &[0.0], 3.0).unwrap_err();
    assert_eq!(e.code, result_code::OLD_HEADER_TIMESTAMP);
}

#[test]
fn the_stamp_says_when_it_starts() {
    let mut m = msg(&["j1"], vec![point(1.0, &[0.1])]);
    m.stamp = Time {
        sec: 100,
        nanosec: 0,
    };
    let c = check(&m, &robot()).unwrap();
    assert_eq!(c.start_in_s(99.0), 1.0);
    assert_eq!(c.start_in_s(100.5), -0.5);
    c.check_start(99.0).unwrap();
    assert_eq!(
        c.check_start(101.5).unwrap_err().code,
        result_code::OLD_HEADER_TIMESTAMP
    );
    let e = c.check_start(30.0).unwrap_err();
    assert_eq!(e.code, result_code::INVALID_GOAL);
    assert!(e.message.contains("70.000 s from now"), "{e}");
    m.stamp = Time::default();
    assert_eq!(check(&m, &robot()).unwrap().start_in_s(12345.0), 0.0);
}

#[test]
fn velocities_at_both_ends_make_the_cubic_through_them() {
    let mut a = point(1.0, &[0.5]);
    a.velocities = vec![0.0];
    let mut b = point(2.0, &[1.0]);
    b.velocities = vec![0.0];
    let c = check(&msg(&["j2"], vec![a, b]), &robot()).unwrap();
    let p = plan(&c, &robot(), &[0.5_f64.to_degrees()], 0.0).unwrap();
    // The joints start still: the first stretch is a cubic too (already there: it
    // stays), then the second; 50 samples each and the first point.
    let half = p.trajectory.at(1.5)[0];
    assert!((half - 0.75_f64.to_degrees()).abs() < 1e-9, "{half}");
    // The smoothstep is slow at its ends: at 1.1 s, 2.8 % of the way.
    let early = p.trajectory.at(1.1)[0] - 0.5_f64.to_degrees();
    assert!(
        (early - 0.028 * 0.5_f64.to_degrees()).abs() < 1e-6,
        "{early}"
    );
    assert_eq!(p.trajectory.len(), 1 + 50 + 50);
}

/// A point of one joint with its velocity, and its acceleration where given.
fn full(at: f64, position: f64, velocity: f64, acc: Option<f64>) -> JointTrajectoryPoint {
    let mut q = point(at, &[position]);
    q.velocities = vec![velocity];
    q.accelerations = acc.into_iter().collect();
    q
}

#[test]
fn accelerations_at_both_ends_make_the_quintic_through_them() {
    // From rest at 0 to 0.5 rad at rest in 1 s: the quintic is the minimum-jerk
    // curve 10s³ - 15s⁴ + 6s⁵ of the way; the cubic (velocities only) 3s² - 2s³.
    let d = 0.5_f64.to_degrees();
    let r = robot();
    let quintic = check(&msg(&["j2"], vec![full(1.0, 0.5, 0.0, Some(0.0))]), &r).unwrap();
    let p = plan(&quintic, &r, &[0.0], 0.0).unwrap();
    for (t, share) in [(0.1, 0.008_56), (0.5, 0.5), (0.9, 0.991_44)] {
        let at = p.trajectory.at(t)[0];
        assert!((at - share * d).abs() < 1e-9, "at {t} s: {at}");
    }
    let cubic = check(&msg(&["j2"], vec![full(1.0, 0.5, 0.0, None)]), &r).unwrap();
    let at = plan(&cubic, &r, &[0.0], 0.0).unwrap().trajectory.at(0.1)[0];
    assert!((at - 0.028 * d).abs() < 1e-9, "{at}");
    // With an acceleration at the end: the quintic's own shape (at 0.5 s,
    // p0/2 + p1/2 + (a0 + a1) h²/64 when the velocities are 0).
    let ending = check(&msg(&["j2"], vec![full(1.0, 0.5, 0.0, Some(-1.0))]), &r).unwrap();
    let at = plan(&ending, &r, &[0.0], 0.0).unwrap().trajectory.at(0.5)[0];
    let want = d / 2.0 - 1.0_f64.to_degrees() / 64.0;
    assert!((at - want).abs() < 1e-9, "{at} against {want}");
}

#[test]
fn accelerations_are_checked_against_max_acceleration() {
    let r = robot();
    for (m, says) in [
        (
            msg(&["j1"], vec![full(1.0, 0.1, 0.0, Some(20.0))]),
            "point 0: j1's acceleration 20 rad/s² is more than its max_acceleration 10 \
                 rad/s²",
        ),
        (
            {
                let mut q = point(1.0, &[0.1]);
                q.accelerations = vec![0.0];
                msg(&["j1"], vec![q])
            },
            "point 0: accelerations without velocities",
        ),
    ] {
        let e = check(&m, &r).unwrap_err();
        assert_eq!(e.code, result_code::INVALID_GOAL, "{e}");
        assert!(e.message.contains(says), "{says:?} in {e}");
    }
    // 0.5 rad in 1 s from rest to rest peaks at 10/√3 × 0.5 = 2.89 rad/s²: refused
    // at 2 rad/s², naming the time and the joint.
    let slow = RobotConfig::from_toml_str(&ROBOT.replacen(
        "max_velocity = 2.0\n        max_acceleration = 10.0",
        "max_velocity = 2.0\n        max_acceleration = 2.0",
        1,
    ))
    .unwrap();
    let c = check(&msg(&["j2"], vec![full(1.0, 0.5, 0.0, Some(0.0))]), &slow).unwrap();
    let e = plan(&c, &slow, &[0.0], 0.0).unwrap_err();
    assert!(
        e.message.contains(
            "on the curve its velocities and accelerations make, at 0.100 s from the \
                 start: j2 accelerates at"
        ) && e
            .message
            .contains("more than its max_acceleration 114.6°/s² (2 rad/s²)"),
        "{e}"
    );
    assert!(plan(&c, &r, &[0.0], 0.0).is_ok());
}

#[test]
fn a_replacement_starts_from_the_commanded_position_and_velocity() {
    let r = robot();
    let v0 = 30.0;
    let start = Start {
        position_deg: vec![10.0],
        velocity_deg_s: vec![v0],
        acceleration_deg_s2: vec![0.0],
    };
    let p1 = 0.5_f64.to_degrees();
    // A first point with a velocity: the cubic from the commanded state, which
    // leaves it at its velocity (at 0.5 s, p0/2 + p1/2 + (v0 - v1) h / 8).
    let c = check(&msg(&["j2"], vec![full(1.0, 0.5, 0.0, None)]), &r).unwrap();
    let p = plan_from(&c, &r, &start, 0.0).unwrap();
    assert_eq!(p.trajectory.at(0.0), [10.0]);
    let at = p.trajectory.at(0.5)[0];
    assert!((at - (5.0 + p1 / 2.0 + v0 / 8.0)).abs() < 1e-9, "{at}");
    let first = p.trajectory.at(0.02)[0] - 10.0;
    let cubic = v0 * 0.02
        + (3.0 * (p1 - 10.0) - 2.0 * v0) * 0.02 * 0.02
        + (-2.0 * (p1 - 10.0) + v0) * 0.02 * 0.02 * 0.02;
    assert!((first - cubic).abs() < 1e-9, "{first} against {cubic}");
    // With an acceleration too: the quintic from the commanded acceleration.
    let start_acc = Start {
        acceleration_deg_s2: vec![40.0],
        ..start.clone()
    };
    let c = check(&msg(&["j2"], vec![full(1.0, 0.5, 0.0, Some(0.0))]), &r).unwrap();
    let at = plan_from(&c, &r, &start_acc, 0.0)
        .unwrap()
        .trajectory
        .at(0.5)[0];
    // At s = 1/2: (p0 + p1)/2 + (v0 - v1) h (5/32) + (a0 + a1) h² / 64.
    let want = 5.0 + p1 / 2.0 + v0 * 5.0 / 32.0 + 40.0 / 64.0;
    assert!((at - want).abs() < 1e-9, "{at} against {want}");
    // Positions only: linearly from the commanded position (the controller's
    // interpolation between a state with velocities and a point without).
    let c = check(&msg(&["j2"], vec![point(1.0, &[0.5])]), &r).unwrap();
    let p = plan_from(&c, &r, &start, 0.0).unwrap();
    assert_eq!(p.csv, format!("time_s,j2\n0,10\n1,{p1}\n"));
    // The blended curve is checked as any: a commanded velocity that carries j1
    // past its limit before it turns back is refused.
    let past = Start {
        position_deg: vec![0.9_f64.to_degrees()],
        velocity_deg_s: vec![1.0_f64.to_degrees()],
        acceleration_deg_s2: vec![0.0],
    };
    let c = check(&msg(&["j1"], vec![full(1.0, 0.9, 0.0, None)]), &r).unwrap();
    let e = plan_from(&c, &r, &past, 0.0).unwrap_err();
    assert!(e.message.contains("outside its soft limits"), "{e}");
    assert!(plan(&c, &r, &[0.9_f64.to_degrees()], 0.0).is_ok());
}

#[test]
fn a_bad_trajectory_is_refused_whole_naming_what_does_not_fit() {
    let r = robot();
    let mut with_effort = point(1.0, &[0.1]);
    with_effort.effort = vec![1.0];
    let mut fast_velocity = point(1.0, &[0.1]);
    fast_velocity.velocities = vec![1.5];
    let mut negative = point(1.0, &[0.1]);
    negative.time_from_start = Duration {
        sec: -1,
        nanosec: 0,
    };
    for (m, code, says) in [
        (
            msg(&[], vec![point(1.0, &[])]),
            result_code::INVALID_JOINTS,
            "0 joint names",
        ),
        (
            msg(&["j9"], vec![point(1.0, &[0.0])]),
            result_code::INVALID_JOINTS,
            "joint j9 is not in the robot file (its joints: j1, j2)",
        ),
        (
            msg(&["j1", "j1"], vec![point(1.0, &[0.0, 0.0])]),
            result_code::INVALID_JOINTS,
            "joint j1 appears twice",
        ),
        (msg(&["j1"], vec![]), result_code::INVALID_GOAL, "no points"),
        (
            msg(&["j1"], vec![point(1.0, &[0.0, 1.0])]),
            result_code::INVALID_GOAL,
            "point 0: 2 positions for 1 joints",
        ),
        (
            msg(&["j1"], vec![point(1.0, &[f64::NAN])]),
            result_code::INVALID_GOAL,
            "point 0: j1's position NaN is not finite",
        ),
        (
            msg(&["j1"], vec![point(1.0, &[1.5])]),
            result_code::INVALID_GOAL,
            "point 0: j1 = 1.5 rad is outside its soft limits -1..=1 rad",
        ),
        (
            msg(&["j1"], vec![point(1.0, &[0.1]), point(1.0, &[0.2])]),
            result_code::INVALID_GOAL,
            "point 1: time_from_start 1 s is not later than the point before (1 s)",
        ),
        (
            msg(&["j1"], vec![negative]),
            result_code::INVALID_GOAL,
            "point 0: time_from_start -1 s 0 ns",
        ),
        (
            msg(&["j1"], vec![point(4000.0, &[0.1])]),
            result_code::INVALID_GOAL,
            "more than the 3600 s",
        ),
        (
            msg(&["j1"], vec![with_effort]),
            result_code::INVALID_GOAL,
            "efforts are given",
        ),
        (
            msg(&["j1"], vec![fast_velocity]),
            result_code::INVALID_GOAL,
            "j1's velocity 1.5 rad/s is faster than its max_velocity 1 rad/s",
        ),
    ] {
        let e = check(&m, &r).unwrap_err();
        assert_eq!(e.code, code, "{e}");
        assert!(e.message.contains(says), "{says:?} in {e}");
    }
    // Too fast from where the joint is (0.8 rad in 0.5 s at 1 rad/s), and between
    // two points.
    let c = check(&msg(&["j1"], vec![point(0.5, &[0.8])]), &r).unwrap();
    let e = plan(&c, &r, &[0.0], 0.0).unwrap_err();
    assert!(
        e.message
            .contains("point 0: j1 is at 0.000° and would move 45.837° in 0.500 s"),
        "{e}"
    );
    let c = check(
        &msg(&["j1"], vec![point(1.0, &[0.0]), point(1.5, &[0.8])]),
        &r,
    )
    .unwrap();
    let e = plan(&c, &r, &[0.0], 0.0).unwrap_err();
    assert!(e.message.contains("faster than its max_velocity"), "{e}");
    // A first point due at once is where the joint is, or refused.
    let c = check(
        &msg(&["j1"], vec![point(0.0, &[0.0]), point(1.0, &[0.1])]),
        &r,
    )
    .unwrap();
    assert_eq!(plan(&c, &r, &[0.3], 0.0).unwrap().trajectory.len(), 2);
    assert!(plan(&c, &r, &[5.0], 0.0).is_err());
}

#[test]
fn a_spline_that_overshoots_a_limit_is_refused_naming_the_time() {
    let mut rising = point(1.0, &[0.9]);
    rising.velocities = vec![1.0];
    let mut falling = point(3.0, &[0.9]);
    falling.velocities = vec![-1.0];
    let robot = robot();
    let checked = check(&msg(&["j1"], vec![rising, falling]), &robot).unwrap();
    let e = plan(&checked, &robot, &[0.9_f64.to_degrees()], 0.0).unwrap_err();
    assert!(
        e.message.contains("on the curve its velocities make, at "),
        "{e}"
    );
    assert!(e.message.contains("outside its soft limits"), "{e}");
}

#[test]
fn the_end_is_reached_within_the_goal_tolerance() {
    let r = robot();
    let c = check(&msg(&["j1", "j2"], vec![point(1.0, &[0.0, 0.5])]), &r).unwrap();
    let goal = 0.5_f64.to_degrees();
    let (code, ends) = outcome(&c, &[Some(0.4), Some(goal - 0.9)]);
    assert_eq!(code, result_code::SUCCESSFUL);
    assert_eq!(ends[1].error_deg.map(|e| (e * 10.0).round()), Some(9.0));
    assert_eq!(
        outcome(&c, &[Some(0.0), Some(goal + 1.5)]).0,
        result_code::GOAL_TOLERANCE_VIOLATED
    );
    assert_eq!(
        outcome(&c, &[None, Some(goal)]).0,
        result_code::GOAL_TOLERANCE_VIOLATED
    );
}
