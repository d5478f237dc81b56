//! `robobus robot ...`: a robot file as one robot. `calibrate` runs the catalogue's
//! `robot.calibrate` on a station opened from the file, prints each joint's range and new
//! offset and limits, and with `--write` (or `-o FILE`) writes them into the file, keeping
//! its comments and order (the old file is kept as `FILE.bak`).

use std::path::{Path, PathBuf};

use anyhow::Context as _;
use clap::Subcommand;
use robobus::catalogue::robot::{Calibrate, ZeroPose};
use robobus::catalogue::{self, Request, Station, StationConfig};
use robobus::ops::read_bounded;
use robobus::robot::calibration::{JointCalibration, apply_to_toml};
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
    } = &args.command;
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
        let plan = catalogue::plan(&request)?;
        return if g.json {
            crate::output::print_json(&serde_json::to_value(&plan)?)
        } else {
            crate::output::print(plan.to_text())
        };
    }
    // The file must read before any servo goes passive.
    let text = read_bounded(robot, 1 << 20)?;
    let target = match (write, output) {
        (true, _) => Some(robot.clone()),
        (false, Some(o)) => Some(o.clone()),
        (false, None) => None,
    };
    let station = Station::open(&StationConfig {
        robot: Some(robot.clone()),
        wck_reply_margin: *reply_margin,
        wait: g.wait,
        ..StationConfig::default()
    })?;
    let result = report::run(&station, &request);
    let failures = station.close();
    for f in &failures {
        eprintln!("robobus: safe stop: {f}");
    }
    let report = result?;
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
    let printed = report::print(&report, g.json, &TABLE);
    if report
        .summary
        .as_ref()
        .is_some_and(|s| s["interrupted"] == true)
    {
        return Err(anyhow::Error::new(crate::exit::Interrupted)
            .context("the reading was ended early; what was read is above"));
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
