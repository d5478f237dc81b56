//! `robobus robot ...`: a robot file as one robot. `calibrate` runs the catalogue's
//! `robot.calibrate` on a station opened from the file, prints each joint's range and new
//! offset and limits, and with `--write` (or `-o FILE`) writes them into the file, keeping
//! its comments and order (the old file is kept as `FILE.bak`). `teleop` runs
//! `robot.teleop`: some of the file's joints, moved by hand, drive others.

use std::path::{Path, PathBuf};

use anyhow::Context as _;
use clap::Subcommand;
use robobus::catalogue::robot::{Calibrate, Pair, Play, PlayTick, Teach, Teleop, ZeroPose};
use robobus::catalogue::{self, Request};
use robobus::catalogue::{Interaction, NoInteraction};
use robobus::ops::read_bounded;
use robobus::ops::{ErrorKind, OpError};
use robobus::record::{Recorder, SampleTable};
use robobus::robot::RobotConfig;
use robobus::robot::calibration::{JointCalibration, apply_to_toml};
use robobus::robot::trajectory::Trajectory;
use robobus::station::{Station, StationConfig};
use serde_json::Value;

use crate::Global;
use crate::report;

/// Options of `robobus robot`.
#[derive(Debug, clap::Args)]
pub(crate) struct Args {
    #[command(subcommand)]
    command: RobotCommand,
}

#[derive(Debug, Subcommand)]
enum RobotCommand {
    /// Calibrate a robot file by hand: move each joint through its whole range, then
    /// leave the robot in its zero pose.
    ///
    /// The file's wCK servos are made passive (torque off) and every joint is read for
    /// --seconds while you move them. Each joint's range becomes its `limits` (--margin-deg
    /// inside at each end) and, with --zero end, the pose at the end its zero (`offset`).
    /// WHJ joints are read as they are: a disabled WHJ joint holds its brake. Without
    /// --write or -o nothing is written. Ctrl-C ends the reading early: what was read is
    /// calibrated (and written), and the exit code is 130.
    Calibrate {
        /// The robot file: its buses are opened, its joints read.
        #[arg(long, value_name = "FILE")]
        robot: PathBuf,
        /// How long the joints are read, seconds (0.1..=600).
        #[arg(long, default_value_t = 20.0)]
        seconds: f64,
        /// Readings a second (1..=100).
        #[arg(long, default_value_t = 20.0)]
        rate_hz: f64,
        /// Which pose becomes the zero: the one at the end, or keep the file's offsets.
        #[arg(long, value_enum, default_value = "end")]
        zero: ZeroArg,
        /// How far inside the recorded range the limits stay, degrees (0..=30).
        #[arg(long, default_value_t = 2.0)]
        margin_deg: f64,
        /// Leave the wCK servos' torque as it is.
        #[arg(long)]
        no_passive: bool,
        /// Extra time to wait for each wCK reply beyond its modelled wire time, in ms.
        #[arg(long, value_name = "MS", value_parser = crate::wck::parse_margin)]
        reply_margin: Option<std::time::Duration>,
        /// Write the calibrated joints into the robot file (the old one kept as FILE.bak).
        #[arg(long, conflicts_with = "output")]
        write: bool,
        /// Write the calibrated robot file here instead.
        #[arg(short = 'o', long, value_name = "FILE")]
        output: Option<PathBuf>,
    },
    /// Play a trajectory on the robot file's joints, across its buses and both families.
    ///
    /// The trajectory is a CSV file: a header `time_s,JOINT,JOINT,...` (joints named as
    /// in the robot file), then a row per point: the time in seconds and each joint's
    /// angle in degrees (the file's joint frame, as `monitor --robot` shows it). It is
    /// checked whole before anything moves (names, soft limits, maximum speeds); every
    /// joint is read, and a silent one or one outside its limits refuses the run. The
    /// joints go from where they are to the first point no faster than their
    /// maximum speed, then follow the trajectory (linear between points), every bus
    /// commanded at the same instant each tick. WHJ joints must be enabled in position
    /// mode first. --record writes targets and positions on one time base (.csv, .jsonl
    /// or .mcap: ROS 2 joint states of the positions and of the targets). Ctrl-C
    /// stops it where it is (exit 130).
    Play {
        /// The trajectory (CSV; at most 4 MiB).
        #[arg(value_name = "TRAJECTORY.csv")]
        trajectory: PathBuf,
        /// The robot file: its buses are opened, its joints named in the trajectory.
        #[arg(long, value_name = "FILE")]
        robot: PathBuf,
        /// Ticks a second (1..=500).
        #[arg(long, default_value_t = 50.0)]
        rate_hz: f64,
        /// The wCK servos' torque level (0 strongest ..= 4 weakest).
        #[arg(long, default_value_t = 2)]
        torque: u8,
        /// Record every tick's targets and positions (.csv, .jsonl / .ndjson or .mcap).
        #[arg(long, value_name = "FILE")]
        record: Option<PathBuf>,
        /// Extra time to wait for each wCK reply beyond its modelled wire time, in ms.
        #[arg(long, value_name = "MS", value_parser = crate::wck::parse_margin)]
        reply_margin: Option<std::time::Duration>,
        /// A play of positions runs first on WHJ simulators seeded with its WHJ joints
        /// (by default when the trajectory lasts at most 60 s) and is refused before its
        /// first tick if a simulated joint would lag, fault or be derated.
        #[command(flatten)]
        preflight: robobus::catalogue::whj::PreflightArg,
    },
    /// Record a trajectory by hand: move the robot file's joints while they are read, then
    /// play it back with `robot play`.
    ///
    /// The wCK servos go passive and the WHJ joints into current mode at --hold-ma (0:
    /// limp): an arm falls unless you hold it, so this asks for confirmation (--yes). Every
    /// joint is read --rate-hz times a second for --seconds; a reading in which a joint
    /// did not answer is left out (and counted). At the end the WHJ joints are back in
    /// position mode and each bus is left in the robot file's `safe_state` (by default WHJ
    /// joints hold where they are, wCK servos passive). The trajectory (CSV) goes to -o
    /// FILE. Ctrl-C ends the reading early: what was
    /// read is written, and the exit code is 130.
    Teach {
        /// The robot file: its buses are opened, its joints read.
        #[arg(long, value_name = "FILE")]
        robot: PathBuf,
        /// How long the joints are read, seconds (0.1..=3600).
        #[arg(long, default_value_t = 10.0)]
        seconds: f64,
        /// Readings (trajectory points) a second (1..=100).
        #[arg(long, default_value_t = 20.0)]
        rate_hz: f64,
        /// The joints to record, by name (comma-separated; default: every joint).
        #[arg(long, value_delimiter = ',', value_name = "NAME,...")]
        joints: Vec<String>,
        /// The current a WHJ joint is held at while moved by hand, mA (-2000..=2000).
        #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
        hold_ma: f64,
        /// The trajectory file to write (CSV).
        #[arg(short = 'o', long, value_name = "FILE.csv")]
        output: PathBuf,
        /// Extra time to wait for each wCK reply beyond its modelled wire time, in ms.
        #[arg(long, value_name = "MS", value_parser = crate::wck::parse_margin)]
        reply_margin: Option<std::time::Duration>,
    },
    /// Leader-follower teleoperation: joints of the robot file moved by hand (the leader)
    /// drive others (the follower), live.
    ///
    /// Every cycle reads each leader joint and steps its follower toward the leader's
    /// angle × SCALE + OFFSET (in degrees; the joint angles of the file, its offsets and
    /// directions applied), at most 2° (WHJ) or 8 steps (wCK) a cycle, within the follower's soft
    /// limits and its --limit. A WHJ follower must be enabled in position mode first: a
    /// silent follower, one outside its soft limits or a WHJ one not ready refuses the run
    /// before anything is sent. A cycle without every leader reading sends nothing: the
    /// follower holds. After --leader-timeout-ms without one, the run ends (exit 3).
    /// Without --seconds it runs until Ctrl-C. At the end each bus is left in the robot
    /// file's `safe_state`.
    Teleop {
        /// The robot file: its buses are opened, its joints named in --map.
        #[arg(long, value_name = "FILE")]
        robot: PathBuf,
        /// A leader joint driving a follower joint (repeat for each follower; a leader
        /// may drive several). SCALE: -10..=10 (default 1; negative mirrors);
        /// OFFSET: -360..=360 (default 0).
        #[arg(long = "map", value_name = "LEADER:FOLLOWER[:SCALE[:OFFSET]]", required = true, value_parser = parse_pair)]
        map: Vec<Pair>,
        /// The follower's range in degrees (repeat; the robot file's limits apply too).
        #[arg(long = "limit", value_name = "FOLLOWER:MIN_DEG:MAX_DEG", value_parser = parse_limit)]
        limit: Vec<(String, [f64; 2])>,
        /// Cycles a second (1..=200).
        #[arg(long, default_value_t = 50.0)]
        rate_hz: f64,
        /// How long, seconds (0.1..=86400); without it, until Ctrl-C.
        #[arg(long)]
        seconds: Option<f64>,
        /// End the run when the leader gives no complete reading for this long, ms
        /// (10..=10000).
        #[arg(long, value_name = "MS", default_value_t = 500)]
        leader_timeout_ms: u64,
        /// Leave the leader's wCK servos' torque as it is (they are made passive, to be
        /// moved by hand).
        #[arg(long)]
        no_passive: bool,
        /// Extra time to wait for each wCK reply beyond its modelled wire time, in ms.
        #[arg(long, value_name = "MS", value_parser = crate::wck::parse_margin)]
        reply_margin: Option<std::time::Duration>,
    },
}

/// `LEADER:FOLLOWER[:SCALE[:OFFSET]]`.
fn parse_pair(s: &str) -> Result<Pair, String> {
    let parts: Vec<&str> = s.split(':').collect();
    let number = |i: usize, what: &str, default: f64| -> Result<f64, String> {
        parts.get(i).map_or(Ok(default), |v| {
            v.trim().parse::<f64>().map_err(|_| {
                format!("{what} {v:?} is not a number (LEADER:FOLLOWER[:SCALE[:OFFSET]])")
            })
        })
    };
    match parts.as_slice() {
        [leader, follower, ..]
            if parts.len() <= 4 && !leader.is_empty() && !follower.is_empty() =>
        {
            Ok(Pair {
                leader: (*leader).to_owned(),
                follower: (*follower).to_owned(),
                scale: number(2, "SCALE", 1.0)?,
                offset_deg: number(3, "OFFSET", 0.0)?,
                limits_deg: None,
            })
        }
        _ => Err(format!("{s:?}: expected LEADER:FOLLOWER[:SCALE[:OFFSET]]")),
    }
}

/// `FOLLOWER:MIN_DEG:MAX_DEG`.
fn parse_limit(s: &str) -> Result<(String, [f64; 2]), String> {
    let bad = || format!("{s:?}: expected FOLLOWER:MIN_DEG:MAX_DEG");
    match s.split(':').collect::<Vec<_>>().as_slice() {
        [name, lo, hi] if !name.is_empty() => {
            let lo: f64 = lo.trim().parse().map_err(|_| bad())?;
            let hi: f64 = hi.trim().parse().map_err(|_| bad())?;
            Ok(((*name).to_owned(), [lo, hi]))
        }
        _ => Err(bad()),
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum ZeroArg {
    /// The pose at the end becomes each joint's zero.
    End,
    /// The file's offsets stay.
    Keep,
}

/// How calibration tables look: the `JOINT` column, three decimals.
const TABLE: report::Style = report::Style {
    id_header: "joint",
    decimals: 3,
};

/// Runs `robobus robot`.
pub(crate) fn run(g: Global, args: &Args) -> anyhow::Result<()> {
    match &args.command {
        RobotCommand::Calibrate { .. } => calibrate(g, &args.command),
        RobotCommand::Teach { .. } => teach(g, &args.command),
        RobotCommand::Play { .. } => play(g, &args.command),
        RobotCommand::Teleop { .. } => teleop(g, &args.command),
    }
}

/// `robobus robot teach`.
fn teach(g: Global, command: &RobotCommand) -> anyhow::Result<()> {
    let RobotCommand::Teach {
        robot,
        seconds,
        rate_hz,
        joints,
        hold_ma,
        output,
        reply_margin,
    } = command
    else {
        return Ok(());
    };
    let request = Request::RobotTeach(Teach {
        seconds: *seconds,
        rate_hz: *rate_hz,
        joints: (!joints.is_empty()).then(|| joints.clone()),
        hold_ma: *hold_ma,
        confirm: false,
    });
    catalogue::validate(&request)?;
    crate::output::check_output_path(output, "--output")?;
    if g.dry_run {
        return print_plan(g, &request);
    }
    let request = report::confirm(request, g.yes)?;
    let report = run_on(g, robot, *reply_margin, &request)?;
    if let Some(text) = report
        .summary
        .as_ref()
        .and_then(|s| s["trajectory"].as_str())
    {
        std::fs::write(output, text)
            .with_context(|| format!("cannot write {}", output.display()))?;
        eprintln!(
            "robobus: {} points written to {}",
            report
                .summary
                .as_ref()
                .map_or(0, |s| s["points"].as_u64().unwrap_or(0)),
            output.display()
        );
    }
    print(
        g,
        &report,
        "the reading was ended early; what was read is written",
    )
}

/// `robobus robot play`.
fn play(g: Global, command: &RobotCommand) -> anyhow::Result<()> {
    let RobotCommand::Play {
        trajectory,
        robot,
        rate_hz,
        torque,
        record,
        reply_margin,
        preflight,
    } = command
    else {
        return Ok(());
    };
    let request = Request::RobotPlay(Play {
        trajectory: read_bounded(trajectory, MAX_TRAJECTORY_BYTES)?,
        rate_hz: *rate_hz,
        torque: *torque,
        preflight: *preflight,
    });
    let mut parsed = request_trajectory(&request)?;
    // The file's joints, limits and speeds are checked before anything opens.
    let config = RobotConfig::from_toml_str(&read_bounded(robot, 1 << 20)?)
        .map_err(|e| crate::exit::usage(format!("--robot {}: {e}", robot.display())))?;
    let Request::RobotPlay(play) = &request else {
        return Ok(());
    };
    if play.interface()? == robobus::robot::Interface::Position {
        parsed
            .check(&config)
            .map_err(|e| crate::exit::usage(format!("{}: {e}", trajectory.display())))?;
    } else {
        // Velocities or efforts, as the header names them.
        parsed = play
            .check_against(&config)
            .map_err(|e| crate::exit::usage(format!("{}: {e}", trajectory.display())))?;
        if record.is_some() {
            return Err(crate::exit::usage(
                "--record records a play of positions; a play of velocities or efforts \
                 gives its front end no ticks",
            ));
        }
    }
    if g.dry_run {
        return print_plan(g, &request);
    }
    let mut recording = match record {
        Some(path) => {
            let table = SampleTable::played(&config, parsed.joints());
            let heading = format!("{} on {}", trajectory.display(), robot.display());
            Some(Recording {
                recorder: Recorder::create(path, &heading, &table)?,
                table,
                path: path.clone(),
            })
        }
        None => None,
    };
    let report = match &mut recording {
        Some(r) => run_on_with(g, robot, *reply_margin, &request, r)?,
        None => run_on(g, robot, *reply_margin, &request)?,
    };
    if let Some(r) = recording {
        let n = r.recorder.written();
        r.recorder
            .finish()
            .with_context(|| format!("cannot write {}", r.path.display()))?;
        eprintln!("robobus: {n} ticks recorded to {}", r.path.display());
    }
    print(
        g,
        &report,
        "stopped before the trajectory ended; what was done is above",
    )
}

/// `robobus robot teleop`.
fn teleop(g: Global, command: &RobotCommand) -> anyhow::Result<()> {
    let RobotCommand::Teleop {
        robot,
        map,
        limit,
        rate_hz,
        seconds,
        leader_timeout_ms,
        no_passive,
        reply_margin,
    } = command
    else {
        return Ok(());
    };
    let mut map = map.clone();
    for (name, range) in limit {
        let pair = map
            .iter_mut()
            .find(|p| p.follower == *name)
            .ok_or_else(|| {
                crate::exit::usage(format!(
                    "--limit {name}:{}:{}: no --map has the follower {name}",
                    range[0], range[1]
                ))
            })?;
        pair.limits_deg = Some(*range);
    }
    let request = Request::RobotTeleop(Teleop {
        map,
        rate_hz: *rate_hz,
        seconds: *seconds,
        leader_timeout_ms: *leader_timeout_ms,
        passive_leader: !no_passive,
    });
    catalogue::validate(&request)?;
    if g.dry_run {
        return print_plan(g, &request);
    }
    let report = run_on(g, robot, *reply_margin, &request)?;
    print(
        g,
        &report,
        "stopped before --seconds ended; what was done is above",
    )
}

/// The largest trajectory file read.
const MAX_TRAJECTORY_BYTES: u64 = 4 << 20;

/// The trajectory of a `robot.play` request, parsed (bad input: exit 2).
fn request_trajectory(request: &Request) -> anyhow::Result<Trajectory> {
    match request {
        Request::RobotPlay(p) => Ok(p.check()?),
        _ => Err(crate::exit::usage("not a trajectory")),
    }
}

/// A played trajectory's recording: each tick into the table, the table into the file.
struct Recording {
    table: SampleTable,
    recorder: Recorder<std::io::BufWriter<std::fs::File>>,
    path: PathBuf,
}

impl Interaction for Recording {
    fn play_tick(&mut self, tick: &PlayTick<'_>) -> Result<(), OpError> {
        self.table.take_tick(tick);
        self.recorder
            .record(&self.table)
            .map_err(|e| OpError::File {
                path: self.path.clone(),
                reason: format!("cannot write: {e}"),
                kind: ErrorKind::Link,
            })
    }
}

/// Runs `request` on a station opened from the robot file `robot`. A robot operation ends
/// with each bus it moved in the file's `safe_state` itself (a refused one moved nothing),
/// so the station is left as the operation left it: not braked and disabled on top.
fn run_on(
    g: Global,
    robot: &Path,
    reply_margin: Option<std::time::Duration>,
    request: &Request,
) -> anyhow::Result<robobus::catalogue::Report> {
    run_on_with(g, robot, reply_margin, request, &mut NoInteraction)
}

/// [`run_on`] with a front end's side of the run.
fn run_on_with(
    g: Global,
    robot: &Path,
    reply_margin: Option<std::time::Duration>,
    request: &Request,
    interaction: &mut dyn Interaction,
) -> anyhow::Result<robobus::catalogue::Report> {
    let station = Station::open(&StationConfig {
        robot: Some(robot.to_path_buf()),
        wck_reply_margin: reply_margin,
        wait: g.wait,
        ..StationConfig::default()
    })?;
    let result = report::run_with(&station, request, interaction);
    station.leave();
    result
}

/// Prints the plan of `request` (`--dry-run`): nothing is opened.
fn print_plan(g: Global, request: &Request) -> anyhow::Result<()> {
    crate::report::print_plan(g, &robobus::frontend::PlanView::of(request)?)
}

/// `robobus robot calibrate`.
fn calibrate(g: Global, command: &RobotCommand) -> anyhow::Result<()> {
    let RobotCommand::Calibrate {
        robot,
        seconds,
        rate_hz,
        zero,
        margin_deg,
        no_passive,
        reply_margin,
        write,
        output,
    } = command
    else {
        return Ok(());
    };
    let request = Request::RobotCalibrate(Calibrate {
        seconds: *seconds,
        rate_hz: *rate_hz,
        zero: match zero {
            ZeroArg::End => ZeroPose::End,
            ZeroArg::Keep => ZeroPose::Keep,
        },
        margin_deg: *margin_deg,
        passive: !no_passive,
    });
    catalogue::validate(&request)?;
    if g.dry_run {
        return print_plan(g, &request);
    }
    // The file must read before any servo goes passive.
    let text = read_bounded(robot, 1 << 20)?;
    let target = match (write, output) {
        (true, _) => Some(robot.clone()),
        (false, Some(o)) => Some(o.clone()),
        (false, None) => None,
    };
    let report = run_on(g, robot, *reply_margin, &request)?;
    if let Some(target) = &target {
        let done = calibrated(&report.results);
        if done.is_empty() {
            eprintln!(
                "robobus: no joint was calibrated; {} not written",
                target.display()
            );
        } else {
            let out = apply_to_toml(&text, &done)?;
            write_file(robot, target, *write, &out)?;
            let names: Vec<&str> = done.iter().map(|(n, _)| n.as_str()).collect();
            eprintln!(
                "robobus: {} written with the calibration of {}",
                target.display(),
                names.join(", ")
            );
        }
    }
    print(
        g,
        &report,
        "the reading was ended early; what was read is above",
    )
}

/// Prints `report`; a run the stop token ended early (`summary.interrupted`) is exit code
/// 130 with `why`, otherwise the report's own outcome.
fn print(g: Global, report: &robobus::catalogue::Report, why: &'static str) -> anyhow::Result<()> {
    let printed = report::print(report, g.json, &TABLE);
    if report
        .summary
        .as_ref()
        .is_some_and(|s| s["interrupted"] == true)
    {
        return Err(anyhow::Error::new(crate::exit::Interrupted).context(why));
    }
    printed
}

/// The joints of the report that were calibrated (the failed rows are left out).
fn calibrated(rows: &[Value]) -> Vec<(String, JointCalibration)> {
    rows.iter()
        .filter(|r| r.get("kind").is_none())
        .filter_map(|r| {
            let name = r["id"].as_str()?.to_owned();
            let c: JointCalibration = serde_json::from_value(r.clone()).ok()?;
            Some((name, c))
        })
        .collect()
}

/// Writes `text` to `target`; over the robot file itself, the old one is kept as
/// `FILE.bak` first.
fn write_file(robot: &Path, target: &Path, in_place: bool, text: &str) -> anyhow::Result<()> {
    if in_place {
        let mut bak = robot.as_os_str().to_owned();
        bak.push(".bak");
        std::fs::copy(robot, &bak)
            .with_context(|| format!("cannot keep a copy of {}", robot.display()))?;
    }
    std::fs::write(target, text).with_context(|| format!("cannot write {}", target.display()))
}
