//! Trajectories: named joints of a robot file over time, in a documented CSV form, checked
//! against the file before anything moves and sampled by linear interpolation.
//!
//! # The file
//!
//! ```text
//! # a wave of the right arm (lines starting with # are comments)
//! time_s,shoulder,elbow,wrist
//! 0.0,0,0,0
//! 1.0,30,-20,10
//! 2.5,0,0,0
//! ```
//!
//! - The header: `time_s`, then one column per joint, named as in the robot file (a joint
//!   at most once; the file's other joints are not moved).
//! - Each row: the time in seconds from the start (finite, the first ≥ 0, each later than
//!   the one before), then each joint's angle in degrees, in the robot file's joint frame
//!   (its `offset`, `direction` and wCK `centre` applied: what `robobus monitor --robot`
//!   shows). Blank lines and `#` comments are skipped; spaces around a cell are allowed.
//! - Bounds: at most [`MAX_POINTS`] rows, [`MAX_JOINTS`] joints, [`MAX_LINE`] characters
//!   a line, [`MAX_DURATION_S`] seconds.
//!
//! Between rows a joint moves linearly. [`Trajectory::check`] refuses, naming the joint and
//! the row, an angle outside the joint's soft limits (`limits`) and a segment faster than
//! its `max_velocity`.

use std::fmt;

pub mod ros;

use super::RobotConfig;

/// The most rows (points) of a trajectory.
pub const MAX_POINTS: usize = 100_000;
/// The most joints (columns after `time_s`).
pub const MAX_JOINTS: usize = 64;
/// The longest line, characters.
pub const MAX_LINE: usize = 4096;
/// The longest trajectory, seconds.
pub const MAX_DURATION_S: f64 = 3600.0;
/// The longest joint name.
pub const MAX_NAME: usize = 64;

/// A trajectory that does not parse or does not fit its robot file; the message names the
/// line (1-based), the joint and the value.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TrajectoryError(pub String);

impl fmt::Display for TrajectoryError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for TrajectoryError {}

fn bad(line: usize, what: impl fmt::Display) -> TrajectoryError {
    TrajectoryError(format!("trajectory line {line}: {what}"))
}

/// A parsed trajectory (see the [module docs](self)).
#[derive(Debug, Clone, PartialEq)]
pub struct Trajectory {
    joints: Vec<String>,
    /// Each point: its time (s) and the line it came from.
    times: Vec<(f64, usize)>,
    /// Each point's angles, degrees, in the order of `joints`.
    angles: Vec<Vec<f64>>,
}

impl Trajectory {
    /// Parses the CSV text.
    ///
    /// # Errors
    ///
    /// [`TrajectoryError`] naming the line for a missing or bad header, a cell that is not
    /// a finite number, a row with another cell count, times not increasing, and each
    /// bound.
    pub fn parse(text: &str) -> Result<Self, TrajectoryError> {
        let mut lines = text
            .lines()
            .enumerate()
            .map(|(i, l)| (i + 1, l))
            .filter(|(_, l)| !l.trim().is_empty() && !l.trim_start().starts_with('#'));
        let (hline, header) = lines
            .next()
            .ok_or_else(|| TrajectoryError("trajectory: no header (time_s,JOINT,...)".into()))?;
        if header.chars().count() > MAX_LINE {
            return Err(bad(hline, format!("longer than {MAX_LINE} characters")));
        }
        let mut cells = header.split(',').map(str::trim);
        if cells.next() != Some("time_s") {
            return Err(bad(
                hline,
                "the header must start with time_s, then one column per joint",
            ));
        }
        let joints: Vec<String> = cells.map(str::to_owned).collect();
        if joints.is_empty() || joints.len() > MAX_JOINTS {
            return Err(bad(
                hline,
                format!("{} joint columns; 1..={MAX_JOINTS} allowed", joints.len()),
            ));
        }
        for (i, j) in joints.iter().enumerate() {
            if j.is_empty() || j.chars().count() > MAX_NAME {
                return Err(bad(
                    hline,
                    format!("joint column {j:?}: a name of 1..={MAX_NAME} characters"),
                ));
            }
            if joints[..i].contains(j) {
                return Err(bad(hline, format!("joint {j} appears twice")));
            }
        }
        let mut times = Vec::new();
        let mut angles = Vec::new();
        for (n, line) in lines {
            if line.chars().count() > MAX_LINE {
                return Err(bad(n, format!("longer than {MAX_LINE} characters")));
            }
            if times.len() == MAX_POINTS {
                return Err(bad(n, format!("more than {MAX_POINTS} points")));
            }
            let cells: Vec<&str> = line.split(',').map(str::trim).collect();
            if cells.len() != joints.len() + 1 {
                return Err(bad(
                    n,
                    format!(
                        "{} cells; the header has {} (time_s and {} joints)",
                        cells.len(),
                        joints.len() + 1,
                        joints.len()
                    ),
                ));
            }
            let number = |c: &str, what: &str| -> Result<f64, TrajectoryError> {
                c.parse::<f64>()
                    .ok()
                    .filter(|v| v.is_finite())
                    .ok_or_else(|| bad(n, format!("{what} {c:?} is not a finite number")))
            };
            let t = number(cells.first().copied().unwrap_or(""), "time_s")?;
            if !(0.0..=MAX_DURATION_S).contains(&t) {
                return Err(bad(
                    n,
                    format!("time_s {t} out of range 0..={MAX_DURATION_S}"),
                ));
            }
            if let Some(&(before, _)) = times.last()
                && t <= before
            {
                return Err(bad(
                    n,
                    format!("time_s {t} is not later than the row before ({before})"),
                ));
            }
            let row = joints
                .iter()
                .zip(cells.iter().skip(1))
                .map(|(j, c)| number(c, j))
                .collect::<Result<Vec<f64>, _>>()?;
            times.push((t, n));
            angles.push(row);
        }
        if times.is_empty() {
            return Err(TrajectoryError(
                "trajectory: no points after the header".into(),
            ));
        }
        Ok(Self {
            joints,
            times,
            angles,
        })
    }

    /// The joints, in the order of every sample.
    #[must_use]
    pub fn joints(&self) -> &[String] {
        &self.joints
    }

    /// The number of points.
    #[must_use]
    pub fn len(&self) -> usize {
        self.times.len()
    }

    /// Whether it has no points (never, once parsed).
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.times.is_empty()
    }

    /// The time of the last point, s (the first may be later than 0: the joints are
    /// held at the first point until then).
    #[must_use]
    pub fn duration_s(&self) -> f64 {
        self.times.last().map_or(0.0, |t| t.0)
    }

    /// The first point's angles, degrees.
    #[must_use]
    pub fn first(&self) -> &[f64] {
        self.angles.first().map_or(&[], Vec::as_slice)
    }

    /// Each joint's angle at `t_s` seconds, degrees (linear between points; the first
    /// point before it, the last after it).
    #[must_use]
    pub fn at(&self, t_s: f64) -> Vec<f64> {
        let k = self.times.partition_point(|&(t, _)| t <= t_s);
        let (Some(&(t1, _)), Some(a1)) = (self.times.get(k), self.angles.get(k)) else {
            return self.angles.last().cloned().unwrap_or_default();
        };
        if k == 0 {
            return a1.clone();
        }
        let (t0, a0) = (self.times[k - 1].0, &self.angles[k - 1]);
        let f = (t_s - t0) / (t1 - t0);
        a0.iter().zip(a1).map(|(x, y)| x + (y - x) * f).collect()
    }

    /// The fastest any segment moves column `column`'s joint, degrees per second.
    #[must_use]
    pub fn max_speed(&self, column: usize) -> f64 {
        self.times
            .windows(2)
            .zip(self.angles.windows(2))
            .filter_map(|(t, a)| {
                let d = (a[1].get(column)? - a[0].get(column)?).abs();
                Some(d / (t[1].0 - t[0].0))
            })
            .fold(0.0, f64::max)
    }

    /// Checks the trajectory against `robot`: each joint is in the file, every angle
    /// within its soft limits, every segment no faster than its `max_velocity`. Returns
    /// each column's index among the file's joints.
    ///
    /// # Errors
    ///
    /// [`TrajectoryError`] naming the joint, the line and the value against what the file
    /// allows.
    pub fn check(&self, robot: &RobotConfig) -> Result<Vec<usize>, TrajectoryError> {
        let mut index = Vec::with_capacity(self.joints.len());
        for (c, name) in self.joints.iter().enumerate() {
            let Some(i) = robot.joints.iter().position(|j| &j.name == name) else {
                return Err(TrajectoryError(format!(
                    "trajectory: joint {name} is not in the robot file (its joints: {})",
                    robot.joint_names()
                )));
            };
            let j = &robot.joints[i];
            let [lo, hi] =
                [j.limits[0].min(j.limits[1]), j.limits[0].max(j.limits[1])].map(f64::to_degrees);
            let vmax = j.max_velocity.to_degrees();
            for (k, ((t, line), row)) in self.times.iter().zip(&self.angles).enumerate() {
                let a = row[c];
                // A hair of slack: limits in radians, angles in degrees.
                if a < lo - 1e-9 || a > hi + 1e-9 {
                    return Err(bad(
                        *line,
                        format!(
                            "{name} = {a}° is outside its soft limits {lo:.3}..={hi:.3}° (the \
                             robot file's limits)"
                        ),
                    ));
                }
                if k > 0 {
                    let (t0, before) = (self.times[k - 1].0, self.angles[k - 1][c]);
                    let v = (a - before).abs() / (t - t0);
                    if v > vmax * (1.0 + 1e-9) {
                        return Err(bad(
                            *line,
                            format!(
                                "{name} moves {:.3}° in {:.3} s ({v:.1}°/s), faster than its \
                                 max_velocity {vmax:.1}°/s ({} rad/s)",
                                a - before,
                                t - t0,
                                j.max_velocity
                            ),
                        ));
                    }
                }
            }
            index.push(i);
        }
        Ok(index)
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::float_cmp)] // exact interpolation values

    use super::*;

    const ROBOT: &str = r#"
        [buses.a]
        kind = "wck-external"
        [[joints]]
        name = "elbow"
        bus = "a"
        id = 0
        limits = [-1.0, 1.0]
        max_velocity = 1.0
        max_acceleration = 10.0
        [[joints]]
        name = "wrist"
        bus = "a"
        id = 1
        limits = [-0.5, 0.5]
        max_velocity = 2.0
        max_acceleration = 10.0
    "#;

    #[test]
    fn parsed_and_interpolated_linearly() {
        let t = Trajectory::parse(
            "# a comment\n\ntime_s, wrist ,elbow\n0.5,0,0\n1.5, 10, -20\n# more\n2.5,0,0\n",
        )
        .unwrap();
        assert_eq!(t.joints(), ["wrist", "elbow"]);
        assert_eq!(t.len(), 3);
        assert_eq!(t.duration_s(), 2.5);
        assert_eq!(t.at(0.0), [0.0, 0.0]);
        assert_eq!(t.at(1.0), [5.0, -10.0]);
        assert_eq!(t.at(1.5), [10.0, -20.0]);
        assert_eq!(t.at(2.0), [5.0, -10.0]);
        assert_eq!(t.at(9.0), [0.0, 0.0]);
        let robot = RobotConfig::from_toml_str(ROBOT).unwrap();
        assert_eq!(t.check(&robot).unwrap(), [1, 0]);
    }

    #[test]
    fn bad_files_name_the_line() {
        for (text, says) in [
            ("", "no header"),
            (
                "t,elbow\n0,0\n",
                "line 1: the header must start with time_s",
            ),
            ("time_s\n0\n", "line 1: 0 joint columns"),
            ("time_s,elbow,elbow\n", "line 1: joint elbow appears twice"),
            ("time_s,elbow\n", "no points"),
            ("time_s,elbow\n0,1,2\n", "line 2: 3 cells; the header has 2"),
            (
                "time_s,elbow\n0,x\n",
                "line 2: elbow \"x\" is not a finite number",
            ),
            ("time_s,elbow\n0,NaN\n", "is not a finite number"),
            (
                "time_s,elbow\n-1,0\n",
                "line 2: time_s -1 out of range 0..=3600",
            ),
            (
                "time_s,elbow\n1,0\n\n1,0\n",
                "line 4: time_s 1 is not later",
            ),
        ] {
            let e = Trajectory::parse(text).unwrap_err().to_string();
            assert!(e.contains(says), "{text:?}: {e}");
        }
        let long = format!("time_s,{}\n", "a".repeat(MAX_LINE));
        assert!(
            Trajectory::parse(&long)
                .unwrap_err()
                .to_string()
                .contains("longer than 4096")
        );
    }

    #[test]
    fn checked_against_the_robot_file() {
        let robot = RobotConfig::from_toml_str(ROBOT).unwrap();
        for (text, says) in [
            (
                "time_s,knee\n0,0\n",
                "joint knee is not in the robot file (its joints: elbow, wrist)",
            ),
            (
                "time_s,wrist\n0,0\n1,30\n",
                "line 3: wrist = 30° is outside its soft limits -28.648..=28.648°",
            ),
            // 1 rad/s is 57.3°/s: 40° in 0.5 s is 80°/s.
            (
                "time_s,elbow\n0,0\n0.5,40\n",
                "line 3: elbow moves 40.000° in 0.500 s (80.0°/s), faster than its max_velocity 57.3°/s (1 rad/s)",
            ),
        ] {
            let e = Trajectory::parse(text)
                .unwrap()
                .check(&robot)
                .unwrap_err()
                .to_string();
            assert!(e.contains(says), "{text:?}: {e}");
        }
    }
}
