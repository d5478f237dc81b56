//! ROS 2 trajectories (`trajectory_msgs/msg/JointTrajectory`) with the semantics of
//! `ros2_controllers`' `joint_trajectory_controller`, turned into the trajectory
//! [`robot.play`](crate::catalogue::robot::Play) plays.
//!
//! - **Joints**: the message's `joint_names` are some of the robot file's joints (each at
//!   most once, in any order); the file's other joints are not moved (they hold).
//! - **Points**: each has one position per joint (rad, the robot file's joint frame),
//!   velocities for every joint or none (rad/s), accelerations for every joint or none
//!   (rad/s², only with velocities), no efforts (the joints are position controlled).
//!   `time_from_start` is not negative and grows from point to point.
//! - **Start**: a zero `header.stamp` starts it when it is received; a stamp in the
//!   future at that time (at most [`MAX_START_DELAY_S`] ahead); a stamp in the past
//!   starts it now with the points already due skipped (as the controller samples a late
//!   trajectory at the time it reads it), and one whose last point is already due is
//!   refused (`OLD_HEADER_TIMESTAMP`, as the controller refuses it).
//! - **Motion**: from the joints' commanded state at the start ([`Start`]: where they
//!   are, still; or, for a trajectory that replaces the one playing, the position,
//!   velocity and acceleration that one commands at that instant) to the first point
//!   due, then point to point, as the controller interpolates: where both ends of a
//!   segment give velocities and accelerations, on the quintic through them; where both
//!   give velocities, on the cubic; linearly otherwise. Curves are sampled every
//!   [`SPLINE_STEP_S`].
//! - **Checked whole before anything moves** ([`plan`]): names, sizes, finite values,
//!   times, every position within the joint's soft limits, every velocity and every
//!   stretch of the motion (the first included) within its `max_velocity`, every
//!   acceleration given and a quintic's all along within its `max_acceleration`; a refusal
//!   names the point, the joint and the value, with
//!   [`result_code`]'s code.
//! - **The end** ([`outcome`]): reached when every joint ends within
//!   [`GOAL_TOLERANCE_DEG`] of its last point.

use super::{MAX_DURATION_S, MAX_JOINTS, Trajectory};
use crate::cdr::{JointTrajectory, result_code};
use crate::robot::RobotConfig;

/// The furthest in the future a trajectory's stamp may start it, s.
pub const MAX_START_DELAY_S: f64 = 60.0;
/// How often a segment with velocities at both ends is sampled, s (at most: a long
/// trajectory is sampled more coarsely to stay within [`super::MAX_POINTS`]).
pub const SPLINE_STEP_S: f64 = 0.02;
/// How far from its last point a joint may end for the trajectory to count as reached,
/// degrees.
pub const GOAL_TOLERANCE_DEG: f64 = 1.0;
/// How far from where a joint is a first point due at time 0 may be, degrees (it cannot
/// be reached in no time).
pub const AT_ONCE_DEG: f64 = 0.5;

/// Why a trajectory is refused: the code of `control_msgs/action/FollowJointTrajectory`'s
/// result and what does not fit.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Refused {
    /// [`result_code`]'s `INVALID_GOAL`, `INVALID_JOINTS` or `OLD_HEADER_TIMESTAMP`.
    pub code: i32,
    /// The point, the joint and the value against what is allowed.
    pub message: String,
}

impl std::fmt::Display for Refused {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.message)
    }
}

impl std::error::Error for Refused {}

fn invalid(message: impl std::fmt::Display) -> Refused {
    Refused {
        code: result_code::INVALID_GOAL,
        message: format!("joint_trajectory: {message}"),
    }
}

/// A trajectory whose values were checked (names, sizes, finite values, times, limits,
/// velocities): what [`check`] finds before the joints are read.
#[derive(Debug, Clone, PartialEq)]
pub struct Checked {
    /// The joints, in the message's order.
    pub joints: Vec<String>,
    /// Each joint's index in the robot file.
    pub index: Vec<usize>,
    /// Each point.
    points: Vec<Point>,
    /// The stamp's start, seconds since the epoch (`None`: when received).
    start_unix_s: Option<f64>,
}

/// Checks the message's joints, sizes, values and times against `robot` (the first of
/// [`plan`]'s checks, which need no reading of the joints).
///
/// # Errors
///
/// [`Refused`] naming the joint, the point and the value.
pub fn check(msg: &JointTrajectory, robot: &RobotConfig) -> Result<Checked, Refused> {
    let names = &msg.joint_names;
    let bad_joints = |m: String| Refused {
        code: result_code::INVALID_JOINTS,
        message: format!("joint_trajectory: {m}"),
    };
    if names.is_empty() || names.len() > MAX_JOINTS {
        return Err(bad_joints(format!(
            "{} joint names; 1..={MAX_JOINTS} allowed",
            names.len()
        )));
    }
    let mut index = Vec::with_capacity(names.len());
    for (k, name) in names.iter().enumerate() {
        if names[..k].contains(name) {
            return Err(bad_joints(format!("joint {name} appears twice")));
        }
        let Some(i) = robot.joints.iter().position(|j| &j.name == name) else {
            return Err(bad_joints(format!(
                "joint {} is not in the robot file (its joints: {})",
                crate::ops::cut(name),
                robot.joint_names()
            )));
        };
        index.push(i);
    }
    if msg.points.is_empty() {
        return Err(invalid("no points: nothing to play"));
    }
    let mut points = Vec::with_capacity(msg.points.len());
    let mut before: Option<f64> = None;
    for (k, p) in msg.points.iter().enumerate() {
        let point = check_point(k, p, names, &index, robot, before)?;
        before = Some(point.0);
        points.push(point);
    }
    Ok(Checked {
        joints: names.clone(),
        index,
        points,
        start_unix_s: msg.stamp.as_unix_s(),
    })
}

/// A point: its time from the start (s), positions (degrees), velocities (degrees a
/// second, where given) and accelerations (degrees a second², where given).
type Point = (f64, Vec<f64>, Option<Vec<f64>>, Option<Vec<f64>>);

/// Checks point `k` (after one at `before` s), in the joints' order (`index` into the
/// robot file).
#[allow(clippy::many_single_char_names)] // a point's time and values by their usual letters
fn check_point(
    k: usize,
    p: &crate::cdr::JointTrajectoryPoint,
    names: &[String],
    index: &[usize],
    robot: &RobotConfig,
    before: Option<f64>,
) -> Result<Point, Refused> {
    let n = names.len();
    let at = |what: &str| format!("point {k}: {what}");
    if p.positions.len() != n {
        return Err(invalid(at(&format!(
            "{} positions for {n} joints",
            p.positions.len()
        ))));
    }
    for (what, v) in [
        ("velocities", &p.velocities),
        ("accelerations", &p.accelerations),
    ] {
        if !v.is_empty() && v.len() != n {
            return Err(invalid(at(&format!(
                "{} {what} for {n} joints (give one per joint or none)",
                v.len()
            ))));
        }
    }
    if !p.accelerations.is_empty() && p.velocities.is_empty() {
        return Err(invalid(at(
            "accelerations without velocities (give velocities with them: the quintic \
             through a point needs both)",
        )));
    }
    if !p.effort.is_empty() {
        return Err(invalid(at(
            "efforts are given: the bridge plays positions (and velocities), not efforts",
        )));
    }
    for (what, v) in [
        ("position", &p.positions),
        ("velocity", &p.velocities),
        ("acceleration", &p.accelerations),
    ] {
        if let Some((j, x)) = v.iter().enumerate().find(|(_, x)| !x.is_finite()) {
            return Err(invalid(at(&format!(
                "{}'s {what} {x} is not finite",
                names[j]
            ))));
        }
    }
    let d = p.time_from_start;
    if d.sec < 0 || d.nanosec >= 1_000_000_000 {
        return Err(invalid(at(&format!(
            "time_from_start {} s {} ns: not a time from the start (sec >= 0, \
             nanosec < 1e9)",
            d.sec, d.nanosec
        ))));
    }
    let t = d.as_secs_f64();
    if t > MAX_DURATION_S {
        return Err(invalid(at(&format!(
            "time_from_start {t} s: more than the {MAX_DURATION_S} s a trajectory may last"
        ))));
    }
    if let Some(b) = before
        && t <= b
    {
        return Err(invalid(at(&format!(
            "time_from_start {t} s is not later than the point before ({b} s)"
        ))));
    }
    let mut deg = Vec::with_capacity(n);
    for (c, (&x, &i)) in p.positions.iter().zip(index).enumerate() {
        let j = &robot.joints[i];
        let (lo, hi) = (j.limits[0].min(j.limits[1]), j.limits[0].max(j.limits[1]));
        if x < lo - 1e-12 || x > hi + 1e-12 {
            return Err(invalid(at(&format!(
                "{} = {x} rad is outside its soft limits {lo}..={hi} rad (the robot \
                 file's limits)",
                names[c]
            ))));
        }
        deg.push(x.to_degrees());
    }
    let (vel, acc) = rates(k, p, names, index, robot)?;
    Ok((t, deg, vel, acc))
}

/// A point's velocities or accelerations, where given.
type Rates = Option<Vec<f64>>;

/// Point `k`'s velocities and accelerations (where given), each checked against its
/// joint's `max_velocity` and `max_acceleration`, in degrees.
fn rates(
    k: usize,
    p: &crate::cdr::JointTrajectoryPoint,
    names: &[String],
    index: &[usize],
    robot: &RobotConfig,
) -> Result<(Rates, Rates), Refused> {
    let at = |what: &str| format!("point {k}: {what}");
    let vel = if p.velocities.is_empty() {
        None
    } else {
        for (c, (&v, &i)) in p.velocities.iter().zip(index).enumerate() {
            let vmax = robot.joints[i].max_velocity;
            if v.abs() > vmax * (1.0 + 1e-9) {
                return Err(invalid(at(&format!(
                    "{}'s velocity {v} rad/s is faster than its max_velocity {vmax} rad/s",
                    names[c]
                ))));
            }
        }
        Some(p.velocities.iter().map(|v| v.to_degrees()).collect())
    };
    let acc = if p.accelerations.is_empty() {
        None
    } else {
        for (c, (&a, &i)) in p.accelerations.iter().zip(index).enumerate() {
            let amax = robot.joints[i].max_acceleration;
            if a.abs() > amax * (1.0 + 1e-9) {
                return Err(invalid(at(&format!(
                    "{}'s acceleration {a} rad/s² is more than its max_acceleration {amax} \
                     rad/s²",
                    names[c]
                ))));
            }
        }
        Some(p.accelerations.iter().map(|a| a.to_degrees()).collect())
    };
    Ok((vel, acc))
}

impl Checked {
    /// Seconds from `now_unix_s` to the trajectory's start (0 for a zero stamp; negative
    /// for a stamp in the past).
    #[must_use]
    pub fn start_in_s(&self, now_unix_s: f64) -> f64 {
        self.start_unix_s.map_or(0.0, |s| s - now_unix_s)
    }

    /// Refuses a start too far ahead or an end already past, at `now_unix_s`.
    ///
    /// # Errors
    ///
    /// [`Refused`]: `INVALID_GOAL` for a start more than [`MAX_START_DELAY_S`] ahead,
    /// `OLD_HEADER_TIMESTAMP` for a last point already due.
    pub fn check_start(&self, now_unix_s: f64) -> Result<(), Refused> {
        let ahead = self.start_in_s(now_unix_s);
        if ahead > MAX_START_DELAY_S {
            return Err(invalid(format!(
                "header.stamp starts it {ahead:.3} s from now, more than the \
                 {MAX_START_DELAY_S} s allowed"
            )));
        }
        let last = self.points.last().map_or(0.0, |p| p.0);
        if ahead + last < 0.0 {
            return Err(Refused {
                code: result_code::OLD_HEADER_TIMESTAMP,
                message: format!(
                    "joint_trajectory: header.stamp is {:.3} s ago and its last point was due \
                     {last} s after it: it ended {:.3} s ago",
                    -ahead,
                    -(ahead + last)
                ),
            });
        }
        Ok(())
    }

    /// The last point's positions, degrees, in the order of [`Checked::joints`].
    #[must_use]
    pub fn goal_deg(&self) -> &[f64] {
        self.points.last().map_or(&[], |p| p.1.as_slice())
    }
}

/// A trajectory ready to play: checked whole against the robot file and where its joints
/// are.
#[derive(Debug, Clone, PartialEq)]
pub struct Planned {
    /// The trajectory file `robot.play` plays (joint degrees): where the joints are at
    /// 0 s, then the points.
    pub csv: String,
    /// It, parsed.
    pub trajectory: Trajectory,
    /// The points skipped because they were already due (a stamp in the past).
    pub skipped: usize,
    /// How much of the message's time was already over at the start, s.
    pub late_s: f64,
}

/// A segment's curve from `(t0, p0, v0, a0)` to `(t1, p1, v1, a1)` (s, degrees, degrees a
/// second, degrees a second²), as `joint_trajectory_controller` interpolates: the quintic
/// where both ends give velocities and accelerations, the cubic where both give
/// velocities; its polynomial's coefficients in the time since `t0`.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Spline {
    t0: f64,
    c: [f64; 6],
}

/// One end of a segment: time, position, and the velocity and acceleration where given.
type End = (f64, f64, Option<f64>, Option<f64>);

impl Spline {
    /// The curve between `a` and `b`, or `None` (linear) when they do not both give
    /// velocities.
    fn between((t0, p0, v0, a0): End, (t1, p1, v1, a1): End) -> Option<Self> {
        let (v0, v1) = (v0?, v1?);
        let h = t1 - t0;
        let d = p1 - p0;
        let c = match (a0, a1) {
            (Some(a0), Some(a1)) => {
                let (h2, h3) = (h * h, h * h * h);
                [
                    p0,
                    v0,
                    a0 / 2.0,
                    (20.0 * d - (8.0 * v1 + 12.0 * v0) * h - (3.0 * a0 - a1) * h2) / (2.0 * h3),
                    (-30.0 * d + (14.0 * v1 + 16.0 * v0) * h + (3.0 * a0 - 2.0 * a1) * h2)
                        / (2.0 * h3 * h),
                    (12.0 * d - 6.0 * (v1 + v0) * h + (a1 - a0) * h2) / (2.0 * h3 * h2),
                ]
            }
            _ => [
                p0,
                v0,
                (3.0 * d - (2.0 * v0 + v1) * h) / (h * h),
                (-2.0 * d + (v0 + v1) * h) / (h * h * h),
                0.0,
                0.0,
            ],
        };
        Some(Self { t0, c })
    }

    /// The position at `t`.
    fn position(&self, t: f64) -> f64 {
        let s = t - self.t0;
        self.c.iter().rev().fold(0.0, |acc, &k| acc * s + k)
    }

    /// The acceleration at `t`.
    fn acceleration(&self, t: f64) -> f64 {
        let s = t - self.t0;
        let c = &self.c;
        2.0 * c[2] + s * (6.0 * c[3] + s * (12.0 * c[4] + s * 20.0 * c[5]))
    }
}

/// A knot of the motion: its time from the start (s), positions, velocities and
/// accelerations (degrees, degrees a second, degrees a second²; where given).
type Knot<'a> = (f64, &'a [f64], Option<&'a [f64]>, Option<&'a [f64]>);

/// The times of `t`'s points, s (for the library's own trajectories made of another's
/// points: a blend's).
pub(crate) fn times(t: &Trajectory) -> Vec<f64> {
    t.times.iter().map(|x| x.0).collect()
}

/// The trajectory file of `rows` (time, joint degrees) of `joints`.
pub(crate) fn csv_of(joints: &[String], rows: &[(f64, Vec<f64>)]) -> String {
    use std::fmt::Write as _;
    let mut csv = String::from("time_s");
    for j in joints {
        csv.push(',');
        csv.push_str(j);
    }
    csv.push('\n');
    for (t, p) in rows {
        let _ = write!(csv, "{t}");
        for x in p {
            let _ = write!(csv, ",{x}");
        }
        csv.push('\n');
    }
    csv
}

/// Checks the first stretch, from `from_deg` to `first_deg` (point `skipped`) in
/// `t_first` seconds, against each joint's `max_velocity`.
fn check_first_stretch(
    checked: &Checked,
    robot: &RobotConfig,
    from_deg: &[f64],
    first_deg: &[f64],
    t_first: f64,
    skipped: usize,
) -> Result<(), Refused> {
    for (c, (&a, &b)) in from_deg.iter().zip(first_deg).enumerate() {
        let j = &robot.joints[checked.index[c]];
        let d = (b - a).abs();
        let vmax = j.max_velocity.to_degrees();
        let at_once = t_first <= 1e-9;
        if at_once && d > AT_ONCE_DEG {
            return Err(invalid(format!(
                "point {skipped}: due at once, and {} is {d:.3}° from it (at {a:.3}°): more \
                 than the {AT_ONCE_DEG}° a point due at once may be",
                checked.joints[c]
            )));
        }
        if !at_once && d > vmax * t_first * (1.0 + 1e-9) {
            return Err(invalid(format!(
                "point {skipped}: {} is at {a:.3}° and would move {d:.3}° in {t_first:.3} s \
                 ({:.1}°/s), faster than its max_velocity {vmax:.1}°/s ({} rad/s)",
                checked.joints[c],
                d / t_first.max(1e-9),
                j.max_velocity
            )));
        }
    }
    Ok(())
}

/// Where the motion starts from, per joint of the trajectory (in its order): the
/// position, velocity and acceleration commanded at the start (degrees, a second, a
/// second²). Still joints ([`Start::still`]) for a trajectory that starts from rest; the
/// state the one playing commands at the instant it is replaced for a replacement, as
/// `joint_trajectory_controller` starts a new trajectory from its current command.
#[derive(Debug, Clone, PartialEq)]
pub struct Start {
    /// Degrees.
    pub position_deg: Vec<f64>,
    /// Degrees a second.
    pub velocity_deg_s: Vec<f64>,
    /// Degrees a second².
    pub acceleration_deg_s2: Vec<f64>,
}

impl Start {
    /// Joints still at `position_deg`.
    #[must_use]
    pub fn still(position_deg: &[f64]) -> Self {
        Self {
            position_deg: position_deg.to_vec(),
            velocity_deg_s: vec![0.0; position_deg.len()],
            acceleration_deg_s2: vec![0.0; position_deg.len()],
        }
    }
}

/// Plans `checked` to start now: `late_s` seconds after its stamp's start (0 for a zero
/// stamp or a start reached by waiting), from `from_deg` (where each of its joints is,
/// degrees, in its order; held still). [`plan_from`] with [`Start::still`].
///
/// # Errors
///
/// As [`plan_from`].
pub fn plan(
    checked: &Checked,
    robot: &RobotConfig,
    from_deg: &[f64],
    late_s: f64,
) -> Result<Planned, Refused> {
    plan_from(checked, robot, &Start::still(from_deg), late_s)
}

/// Plans `checked` to start now, `late_s` seconds after its stamp's start, from `start`
/// (each joint's commanded state, in the trajectory's order). The points already due
/// are skipped, and the joints go from the start to the first point due in the time
/// left to it: on the quintic through the start's position, velocity and acceleration
/// and the point's where the point gives velocities and accelerations, on the cubic
/// where it gives velocities, linearly otherwise (as `joint_trajectory_controller`
/// interpolates from its current command); then from point to point the same way.
///
/// # Errors
///
/// [`Refused`] (`INVALID_GOAL`) for a first stretch faster than a joint's
/// `max_velocity` (or a first point due at once and more than [`AT_ONCE_DEG`] away), or
/// a curve that leaves a joint's soft limits, exceeds its `max_velocity` or (a quintic)
/// its `max_acceleration` between its points; `OLD_HEADER_TIMESTAMP` when every point is
/// already due.
pub fn plan_from(
    checked: &Checked,
    robot: &RobotConfig,
    start: &Start,
    late_s: f64,
) -> Result<Planned, Refused> {
    let late_s = late_s.max(0.0);
    let n = checked.joints.len();
    let from_deg = start.position_deg.as_slice();
    if [from_deg, &start.velocity_deg_s, &start.acceleration_deg_s2]
        .iter()
        .any(|v| v.len() != n || v.iter().any(|x| !x.is_finite()))
    {
        return Err(invalid(format!(
            "a start of {} positions, {} velocities and {} accelerations for {n} joints",
            from_deg.len(),
            start.velocity_deg_s.len(),
            start.acceleration_deg_s2.len()
        )));
    }
    let skipped = checked
        .points
        .iter()
        .take_while(|p| late_s > 0.0 && p.0 <= late_s)
        .count();
    let rest = &checked.points[skipped..];
    let Some(first) = rest.first() else {
        return Err(Refused {
            code: result_code::OLD_HEADER_TIMESTAMP,
            message: format!(
                "joint_trajectory: it started {late_s:.3} s ago: every point is already due"
            ),
        });
    };
    let t_first = first.0 - late_s;
    check_first_stretch(checked, robot, from_deg, &first.1, t_first, skipped)?;
    // Knots: (time from now, positions, velocities, accelerations); the start first.
    let mut knots: Vec<Knot<'_>> = Vec::with_capacity(rest.len() + 1);
    if t_first > 1e-9 {
        knots.push((
            0.0,
            from_deg,
            Some(&start.velocity_deg_s),
            Some(&start.acceleration_deg_s2),
        ));
    }
    for (t, p, v, a) in rest {
        knots.push((t - late_s, p.as_slice(), v.as_deref(), a.as_deref()));
    }
    let duration = knots.last().map_or(0.0, |k| k.0);
    let step = SPLINE_STEP_S.max(duration / (super::MAX_POINTS as f64 / 2.0));
    let mut rows: Vec<(f64, Vec<f64>)> = Vec::new();
    for (k, &(t, p, v, a)) in knots.iter().enumerate() {
        if let Some(&(t0, p0, v0, a0)) = k.checked_sub(1).and_then(|i| knots.get(i))
            && v0.is_some()
            && v.is_some()
        {
            let end = |x: Option<&[f64]>, c: usize| x.and_then(|x| x.get(c).copied());
            let curves: Vec<Spline> = (0..n)
                .filter_map(|c| {
                    Spline::between(
                        (t0, p0[c], end(v0, c), end(a0, c)),
                        (t, p[c], end(v, c), end(a, c)),
                    )
                })
                .collect();
            #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)] // bounded
            let m = ((t - t0) / step).ceil().max(1.0) as usize;
            let quintic = a0.is_some() && a.is_some();
            for s in 1..m {
                #[allow(clippy::cast_precision_loss)]
                let ts = t0 + (t - t0) * s as f64 / m as f64;
                if quintic {
                    check_acceleration(checked, robot, &curves, ts)?;
                }
                rows.push((ts, curves.iter().map(|q| q.position(ts)).collect()));
            }
        }
        rows.push((t, p.to_vec()));
    }
    let csv = csv_of(&checked.joints, &rows);
    let trajectory = Trajectory::parse(&csv).map_err(|e| invalid(e.0))?;
    // Between the points: the spline's own limits and speeds (the points' are checked).
    trajectory.check(robot).map_err(|e| {
        let at =
            e.0.strip_prefix("trajectory line ")
                .and_then(|r| r.split_once(": "))
                .and_then(|(line, what)| {
                    let row = line.parse::<usize>().ok()?.checked_sub(2)?;
                    Some(format!(
                        "at {:.3} s from the start: {what}",
                        rows.get(row)?.0
                    ))
                })
                .unwrap_or(e.0);
        invalid(format!("on the curve its velocities make, {at}"))
    })?;
    Ok(Planned {
        csv,
        trajectory,
        skipped,
        late_s,
    })
}

/// Refuses a quintic whose acceleration at `t` (s from the start) is more than a joint's
/// `max_acceleration`.
fn check_acceleration(
    checked: &Checked,
    robot: &RobotConfig,
    curves: &[Spline],
    t: f64,
) -> Result<(), Refused> {
    for (c, q) in curves.iter().enumerate() {
        let j = &robot.joints[checked.index[c]];
        let acc = q.acceleration(t);
        let amax = j.max_acceleration.to_degrees();
        if acc.abs() > amax * (1.0 + 1e-9) {
            return Err(invalid(format!(
                "on the curve its velocities and accelerations make, at {t:.3} s from the \
                 start: {} accelerates at {acc:.1}°/s², more than its max_acceleration \
                 {amax:.1}°/s² ({} rad/s²)",
                checked.joints[c], j.max_acceleration
            )));
        }
    }
    Ok(())
}

/// How a played trajectory ended, per joint: how far from its last point.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct JointEnd {
    /// The joint.
    pub joint: String,
    /// Its last point, degrees.
    pub goal_deg: f64,
    /// Where it was read at the end, degrees (`None`: it did not answer).
    pub position_deg: Option<f64>,
    /// The distance, degrees.
    pub error_deg: Option<f64>,
}

/// The end of a played trajectory: each joint against its last point, and whether all
/// are within [`GOAL_TOLERANCE_DEG`]: `(code, the joints)`, the code
/// `SUCCESSFUL` or `GOAL_TOLERANCE_VIOLATED` (a joint outside, or one that did not
/// answer).
#[must_use]
pub fn outcome(checked: &Checked, positions_deg: &[Option<f64>]) -> (i32, Vec<JointEnd>) {
    let ends: Vec<JointEnd> = checked
        .joints
        .iter()
        .zip(checked.goal_deg())
        .enumerate()
        .map(|(c, (j, &g))| {
            let at = positions_deg.get(c).copied().flatten();
            JointEnd {
                joint: j.clone(),
                goal_deg: g,
                position_deg: at,
                error_deg: at.map(|p| (p - g).abs()),
            }
        })
        .collect();
    let ok = ends
        .iter()
        .all(|e| e.error_deg.is_some_and(|d| d <= GOAL_TOLERANCE_DEG));
    (
        if ok {
            result_code::SUCCESSFUL
        } else {
            result_code::GOAL_TOLERANCE_VIOLATED
        },
        ends,
    )
}

#[cfg(test)]
mod tests;
