//! `robobus bridge`: the station's robot on Zenoh (crate `robobus-bridge`), on the given
//! buses or the built-in simulated robot; prints `bridge: ...` first and serves until
//! Ctrl-C.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Duration;

use robobus::robot::simulated::{JOINTS, SERVOS};
use robobus::robot::{BusConfig, RobotConfig};
use robobus::station::{Station, StationConfig};
use robobus_bridge::{Bridge, BridgeConfig, DEFAULT_LISTEN, Keys, ZenohMode};

use crate::Global;

/// Options of `robobus bridge`.
#[derive(Debug, clap::Args)]
#[allow(clippy::struct_excessive_bools)] // each one of the command line's flags
pub(crate) struct Args {
    /// The key prefix of every key (`bot1`, `site/arm`; a ROS 2 namespace `/bot1` works
    /// as is). Default: none.
    #[arg(long, value_name = "NS")]
    namespace: Option<String>,
    /// Joint states per second on `NS/joint_states` (0.1..=1000).
    #[arg(long, default_value_t = 50.0, value_name = "HZ")]
    rate: f64,
    /// How the bridge joins Zenoh: `peer`, or `client` of the routers given with
    /// --connect (behind a site's router, bridges and consumers are clients).
    #[arg(long, value_enum, default_value_t = Mode::Peer)]
    mode: Mode,
    /// A Zenoh endpoint to listen on (repeatable). Default: tcp/127.0.0.1:7447 only in
    /// peer mode, none in client mode.
    #[arg(long, value_name = "ENDPOINT", conflicts_with = "no_listen")]
    listen: Vec<String>,
    /// Listen on no endpoint (a peer that only connects; a client never listens).
    #[arg(long)]
    no_listen: bool,
    /// A Zenoh endpoint to connect to, such as a router's tcp/10.0.0.1:7447 (repeatable).
    #[arg(long, value_name = "ENDPOINT")]
    connect: Vec<String>,
    /// A Zenoh configuration file (JSON5) for TLS, access control or credentials; the
    /// endpoints above and scouting off are set on top of it.
    #[arg(long, value_name = "FILE")]
    zenoh_config: Option<PathBuf>,
    /// Armed from the start: joint commands and motion requests move the robot.
    #[arg(long, conflicts_with = "read_only")]
    armed: bool,
    /// Serve reads only: joint states, health and read-only requests; no request that
    /// changes a device, no joint command, no arming.
    #[arg(long)]
    read_only: bool,
    /// A command stream quiet for this long holds the joints it moved, ms (20..=5000).
    #[arg(long, default_value_t = 200, value_name = "MS",
          value_parser = clap::value_parser!(u64).range(20..=5000))]
    command_timeout: u64,
    /// Serve the built-in simulated robot (as without --wck-port, --whj-bus and
    /// --robot); with --robot, through that robot file: its buses are the simulators'
    /// `sim-wck` (kind = "wck-external", servos 0..=15) and `sim-whj` (kind =
    /// "whj-external", joints 1..=7), its joints any of them with their own limits and
    /// command interfaces (docs/bridge.md).
    #[arg(long, conflicts_with_all = ["wck_port", "whj_bus"])]
    simulated: bool,
    #[command(flatten)]
    station: crate::run::StationArgs,
}

/// `--mode`.
#[derive(Debug, Clone, Copy, clap::ValueEnum)]
enum Mode {
    Peer,
    Client,
}

impl Args {
    fn config(&self) -> BridgeConfig {
        let mode = match self.mode {
            Mode::Peer => ZenohMode::Peer,
            Mode::Client => ZenohMode::Client,
        };
        BridgeConfig {
            namespace: self.namespace.clone(),
            rate_hz: self.rate,
            listen: if self.no_listen || (mode == ZenohMode::Client && self.listen.is_empty()) {
                Vec::new()
            } else if self.listen.is_empty() {
                vec![DEFAULT_LISTEN.to_owned()]
            } else {
                self.listen.clone()
            },
            connect: self.connect.clone(),
            mode,
            zenoh_config: self.zenoh_config.clone(),
            armed: self.armed,
            read_only: self.read_only,
            command_timeout: Duration::from_millis(self.command_timeout),
            ..BridgeConfig::default()
        }
    }
}

/// The keys, one per line, for the first lines printed.
fn describe(
    keys: &Keys,
    config: &BridgeConfig,
    joints: &[String],
    sim: bool,
    source: &str,
) -> String {
    let endpoints = if config.mode == ZenohMode::Client {
        format!("a client of {}", config.connect.join(", "))
    } else {
        format!(
            "listening on {}{}",
            if config.listen.is_empty() {
                "no endpoint".to_owned()
            } else {
                config.listen.join(", ")
            },
            if config.connect.is_empty() {
                String::new()
            } else {
                format!(", connecting to {}", config.connect.join(", "))
            }
        )
    };
    let mut t = format!(
        "{endpoints}; {}; {} joints{}; {}\n",
        source,
        joints.len(),
        if joints.is_empty() {
            String::new()
        } else {
            format!(" ({})", joints.join(" "))
        },
        if config.read_only {
            "read-only"
        } else if config.armed {
            "ARMED"
        } else {
            "not armed"
        },
    );
    let rows = [
        (
            &keys.joint_states,
            format!("sensor_msgs/msg/JointState, {} Hz", config.rate_hz),
        ),
        (
            &keys.joint_commands,
            "std_msgs/msg/Float64MultiArray, rad".to_owned(),
        ),
        (
            &keys.diagnostics,
            "diagnostic_msgs/msg/DiagnosticArray, every second".to_owned(),
        ),
        (
            &keys.run,
            "queryable: a catalogue request in JSON, its report".to_owned(),
        ),
        (&keys.plan, "queryable: a request's dry run".to_owned()),
        (&keys.arm, "queryable: true / false / nothing".to_owned()),
        (&keys.health, "JSON, every second".to_owned()),
        (&keys.alive, "liveliness token".to_owned()),
    ];
    for (k, what) in rows {
        let _ = writeln!(t, "  {k:<28} {what}");
    }
    if !config.read_only {
        let prefix = keys.joint_states.strip_suffix("joint_states").unwrap_or("");
        let tk = robobus_bridge::TrajectoryKeys::under(prefix);
        for (k, what) in [
            (tk.trajectory, "trajectory_msgs/msg/JointTrajectory, played"),
            (
                tk.state,
                "control_msgs/msg/JointTrajectoryControllerState, each tick",
            ),
            (tk.result, "JSON, each trajectory's end"),
        ] {
            let _ = writeln!(t, "  {k:<28} {what}");
        }
        let ck = robobus_bridge::CommandKeys::under(prefix);
        for (k, what) in [
            (ck.velocity, "std_msgs/msg/Float64MultiArray, rad/s"),
            (ck.effort, "std_msgs/msg/Float64MultiArray, N·m"),
            (
                ck.interface,
                "queryable: the joints' interfaces, read or switched",
            ),
        ] {
            let _ = writeln!(t, "  {k:<28} {what}");
        }
    }
    if sim {
        let _ = writeln!(t, "  {:<28} queryable: the simulators' state", keys.sim);
    }
    t
}

/// `--simulated --robot FILE`: the file read and checked for the built-in simulators
/// before anything starts: each bus is `sim-wck` (kind `wck-external`) or `sim-whj` (kind
/// `whj-external`), each joint's ID one of that simulator's (servos `0..SERVOS`, joints
/// `1..=JOINTS`). Anything else is bad input (exit 2) naming the file, the value and what
/// is allowed.
fn sim_robot(path: &Path) -> anyhow::Result<RobotConfig> {
    let bad = |what: &dyn std::fmt::Display| {
        crate::exit::usage(format!(
            "--robot {} with --simulated: {what}",
            path.display()
        ))
    };
    let text = robobus::ops::read_bounded(path, RobotConfig::MAX_FILE_BYTES as u64)
        .map_err(|e| bad(&e))?;
    let robot = RobotConfig::from_toml_str(&text).map_err(|e| bad(&e))?;
    for (name, bus) in &robot.buses {
        let (wanted, kind) = if bus.is_wck() {
            ("sim-wck", "wck-external")
        } else {
            ("sim-whj", "whj-external")
        };
        if name != wanted || bus.kind() != kind {
            return Err(bad(&format!(
                "bus {name} (kind = \"{}\") is not a bus of the built-in simulated robot; \
                 expected [buses.sim-wck] with kind = \"wck-external\" or [buses.sim-whj] \
                 with kind = \"whj-external\"",
                bus.kind()
            )));
        }
    }
    for j in &robot.joints {
        let wck = robot.buses.get(&j.bus).is_some_and(BusConfig::is_wck);
        let (ok, ids) = if wck {
            (j.id < SERVOS, format!("0..={}", SERVOS - 1))
        } else {
            ((1..=JOINTS).contains(&j.id), format!("1..={JOINTS}"))
        };
        if !ok {
            return Err(bad(&format!(
                "joint {}: id = {} is not on the simulated bus {}; expected {ids}",
                j.name, j.id, j.bus
            )));
        }
    }
    Ok(robot)
}

/// The built-in simulated station with the robot file of `--simulated --robot` in place
/// of its own.
fn with_robot(mut station: Station, robot: Option<&RobotConfig>) -> anyhow::Result<Station> {
    if let Some(robot) = robot {
        station
            .set_robot(robot.clone())
            .map_err(|e| match e.kind() {
                robobus::ErrorKind::BadInput => crate::exit::usage(e.to_string()),
                _ => anyhow::Error::new(e),
            })?;
    }
    Ok(station)
}

/// Runs `robobus bridge`.
pub(crate) fn run(g: Global, args: &Args) -> anyhow::Result<()> {
    let config = args.config();
    let sim = args.simulated || args.station.simulated();
    let file = args.station.config().robot;
    let robot = match (sim, &file) {
        (true, Some(path)) => Some(sim_robot(path)?),
        _ => None,
    };
    let source = match (sim, &file) {
        (true, Some(path)) => format!("the built-in simulated robot through {}", path.display()),
        (true, None) => "the built-in simulated robot".to_owned(),
        (false, _) => "the given buses".to_owned(),
    };
    if g.dry_run {
        // Checked as the real run checks them; nothing is opened.
        let keys = config.check().map_err(|e| match e.kind() {
            robobus::ErrorKind::BadInput => crate::exit::usage(e.to_string()),
            _ => anyhow::Error::new(e),
        })?;
        let joints = if sim {
            robot.as_ref().map_or_else(
                || {
                    Station::simulated()
                        .ok()
                        .and_then(|s| robobus::station::follow::Follower::new(&s).ok())
                        .map(|f| f.joints().iter().map(|j| j.name.clone()).collect())
                        .unwrap_or_default()
                },
                |r| r.joints.iter().map(|j| j.name.clone()).collect(),
            )
        } else {
            Vec::new()
        };
        return crate::output::print(&format!(
            "bridge: would serve, opening no socket: {}",
            describe(&keys, &config, &joints, sim, &source)
        ));
    }
    let (station, live) = if sim {
        let (station, live) = Station::simulated_live(None)?;
        (with_robot(station, robot.as_ref())?, Some(live))
    } else {
        (
            Station::open(&StationConfig {
                wait: g.wait,
                ..args.station.config()
            })?,
            None,
        )
    };
    // The Ctrl-C handler is in place before the line that says the bridge serves: a
    // signal sent as soon as that line is read stops it cleanly, never kills it.
    let stop = crate::interrupt::stop_token();
    let bridge = Bridge::start(station, live, config.clone()).map_err(exit_error)?;
    crate::output::print(&format!(
        "bridge: zenoh {} {}",
        bridge.zid(),
        describe(bridge.keys(), &config, &bridge.joint_names(), sim, &source)
    ))?;
    bridge.run(&stop).map_err(exit_error)?;
    Ok(())
}

/// A bridge's error with its exit code: 2 for a bad option, 4 for a namespace another
/// bridge serves (not available here), else 1.
fn exit_error(e: robobus_bridge::BridgeError) -> anyhow::Error {
    if matches!(e, robobus_bridge::BridgeError::InUse { .. }) {
        return anyhow::Error::new(crate::exit::NotAvailable(e.to_string()));
    }
    match e.kind() {
        robobus::ErrorKind::BadInput => crate::exit::usage(e.to_string()),
        _ => anyhow::Error::new(e),
    }
}
