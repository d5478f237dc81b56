//! `robobus`: drive and simulate wCK servos and WHJ joints from the command line.
//!
//! One module per subcommand; this file only parses, sets up logging and dispatches.
//!
//! | module | subcommand |
//! | --- | --- |
//! | [`wck`] | `robobus wck --port PORT ...` (wCK servos on a serial bus, or a simulator over TCP) |
//! | [`whj`] | `robobus whj --bus BUS ...` (WHJ joints on CAN FD) |
//! | [`demo`] | `robobus demo` (the built-in simulated robot) |
//! | [`monitor`] | `robobus monitor` (live dashboard) |
//! | [`plot`] | `robobus plot FILE.csv -o FILE.png\|svg` |
//! | [`replay`] | `robobus replay FILE` (decode a capture file) |
//! | [`doctor`] | `robobus doctor` (setup checks) |
//! | [`run`] | `robobus run FILE.json`, `robobus schema` (the catalogue's requests) |
//! | [`generate`] | `robobus completions SHELL`, `robobus man` |
//! | [`sim_wck`], [`sim_whj`] | `robobus sim wck`, `robobus sim whj` |
//!
//! Cross-cutting pieces: [`exit`] (exit codes and the error kinds that select them),
//! [`output`] (how `--dry-run` prints packets and frames), [`report`] (the one place a
//! subcommand's request meets the station: its confirmation, its run and its report).
//!
//! # Exit codes
//!
//! See [`exit::Exit`]: 0 success, 1 device / runtime error, 2 usage or validation error
//! (nothing was opened or sent), 3 timeout or no device answered, 4 not available in this
//! build, 5 `doctor` found a problem, 130 interrupted (Ctrl-C).

use std::io::IsTerminal as _;
use std::process::ExitCode;

use clap::{CommandFactory as _, FromArgMatches as _, Parser, Subcommand};

#[cfg(feature = "bridge")]
mod bridge;
mod demo;
mod doctor;
mod exit;
mod generate;
mod hand;
mod interrupt;
mod monitor;
mod output;
mod plot;
mod ports;
mod replay;
mod report;
mod robot;
mod run;
mod sim_wck;
mod sim_whj;
mod studio;
mod wck;
mod whj;

use exit::Exit;

/// Text shown after the top-level `--help`: exit codes and where to start.
const AFTER_HELP: &str = "\
Exit codes:
  0    success
  1    device or runtime error (I/O, a device reported an error, a malformed reply)
  2    usage or validation error: a value is out of range or malformed; nothing was
       opened or sent
  3    timeout: no device answered
  4    not available: the command needs something this build or machine lacks (such
       as SocketCAN in the kernel)
  5    `robobus doctor` found at least one problem
  130  interrupted (Ctrl-C); devices were brought to their safe state first

Every value is checked before anything is opened; `--dry-run` prints the exact bytes
(wCK) or CAN FD frames (WHJ) a command would send, one per line, without opening anything.

Examples:
  robobus demo                                              # the simulated robot, no setup
  robobus wck --port /dev/ttyUSB0 --dry-run move 3 127      # prints FF 03 7F 7C
  robobus whj --bus can0 --dry-run enable 1                 # prints 001##1020A01
  robobus sim wck --servos 0-5 --link /tmp/wck              # a simulated wCK bus
  robobus doctor --port /dev/ttyUSB0 --can can0";

/// Drive and simulate RoboBuilder wCK servos and RealMan WHJ joints.
#[derive(Debug, Parser)]
#[command(
    name = "robobus",
    version,
    propagate_version = true,
    after_help = AFTER_HELP
)]
pub(crate) struct Cli {
    /// Options every subcommand accepts.
    #[command(flatten)]
    global: Global,
    /// What to do.
    #[command(subcommand)]
    command: Command,
}

/// Options every subcommand accepts (written before or after the subcommand).
#[derive(Debug, Clone, Copy, Default, clap::Args)]
pub(crate) struct Global {
    /// Machine-readable output: one JSON document on stdout.
    #[arg(long, global = true)]
    pub(crate) json: bool,
    /// Print the exact bytes / CAN FD frames the command would send, one per line, and
    /// exit without opening any port or bus.
    #[arg(long, global = true)]
    pub(crate) dry_run: bool,
    /// More log output on stderr (-v info, -vv debug, -vvv trace). `RUST_LOG` overrides.
    #[arg(short, long, global = true, action = clap::ArgAction::Count)]
    pub(crate) verbose: u8,
    /// Answer "yes" to confirmations. Commands that rewrite a device's EEPROM / flash
    /// (wck set-id, set-baud, set (not --runtime), program upload; whj set-id, save) ask
    /// first on a terminal, and without a terminal need --yes.
    #[arg(short = 'y', long, global = true)]
    pub(crate) yes: bool,
    /// How the client waits for replies on the buses it opens: sleep (in the kernel, the
    /// default), or spin (poll from shortly before each reply is due: lower latency, one
    /// core busy while a reply is awaited; spin:US starts US µs before).
    #[arg(long, global = true, value_name = "MODE", default_value = "sleep", value_parser = parse_wait)]
    pub(crate) wait: robobus::WaitMode,
}

/// `--wait`: sleep, spin or spin:US.
fn parse_wait(s: &str) -> Result<robobus::WaitMode, String> {
    s.parse().map_err(|e: robobus::WaitModeError| e.to_string())
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Run the built-in simulated robot through a short showcase: start here.
    ///
    /// A wCK humanoid of 16 servos and a 7-joint WHJ arm, simulated in-process: scan,
    /// synchronized wCK keyframes, a 500 Hz WHJ sine trajectory; then a summary of what
    /// moved, how well it tracked, and the bus figures.
    Demo(demo::Args),
    /// Drive wCK servos on a serial (UART) bus.
    Wck(wck::Args),
    /// Drive WHJ joints on a CAN FD bus (SocketCAN or the python-can UDP bus).
    Whj(whj::Args),
    /// Live terminal dashboard of a WHJ bus, a wCK port or a robot file; records to CSV.
    ///
    /// Positions, speeds, currents (wCK: load), enable state and errors, with a scrolling
    /// plot of the positions; `q`, `Esc` or Ctrl-C quit. Only reads: nothing is enabled,
    /// moved or released. With --json (or without a terminal) it prints samples instead:
    /// one JSON object per sample, or one text line per second.
    Monitor(monitor::Args),
    /// Plot a recording (CSV, or MCAP from `monitor --record`) to a PNG or SVG file.
    Plot(plot::Args),
    /// A robot file as one robot: calibrate its joints' limits and zero by hand.
    Robot(robot::Args),
    /// Print what every frame or packet of a capture file means (candump or hex log).
    ///
    /// WHJ frames with joint, command, registers by name in units, error bits by name;
    /// wCK commands and each reply decoded against its command; malformed entries marked.
    Replay(replay::Args),
    /// Check the machine's setup: serial ports, USB latency, SocketCAN, the UDP bus.
    Doctor(doctor::Args),
    /// List the machine's serial ports: USB IDs, the adapter, what it is for, latency advice.
    ///
    /// COM ports on Windows, /dev/cu.* on macOS, /dev/ttyUSB* and /dev/ttyACM* on Linux,
    /// as the OS knows them; adapters robobus recognises are named with the option that
    /// uses them (a wCK bus: --port PORT; a CAN FD adapter: --bus slcan:PORT or
    /// --bus fdcanusb:PORT). Nothing is opened or sent.
    Ports(ports::Args),
    /// Print a shell completion script (bash, zsh, fish, elvish, powershell).
    Completions(generate::CompletionArgs),
    /// Write the man pages (robobus.1 and one per subcommand).
    Man(generate::ManArgs),
    /// Run a simulated bus that other programs can talk to like real hardware.
    #[command(subcommand)]
    Sim(SimCommand),
    /// Run requests given as JSON (one, or an array) and print their reports as JSON.
    ///
    /// Each request names an operation (`wck.status`, `whj.move`, ...) and its arguments,
    /// as the subcommands take them: `{"op": "whj.move", "joint": 1, "degrees": 30}`
    /// (docs/catalogue.md; `robobus schema request`). Without --wck-port, --whj-bus and
    /// --robot they run on the built-in simulated robot. Writes to EEPROM / flash / IDs
    /// need `"confirm": true` in the request.
    Run(run::Args),
    /// Print the JSON Schema of requests, reports, plans, or the host bounds table.
    Schema(run::SchemaArgs),
    /// Serve the web studio: scan, jog, tune, plot, waveforms, programs and poses in a
    /// browser.
    ///
    /// Without --wck-port, --whj-bus and --robot it serves the built-in simulated robot.
    /// The first line printed is `studio: http://127.0.0.1:PORT/`. It listens on
    /// 127.0.0.1 only unless --listen (with --token-file) says otherwise; motion needs the
    /// page's Arm and its heartbeat (docs/studio.md).
    Studio(studio::Args),
    /// Put the robot on Zenoh, in the message types ROS 2 reads: joint states and
    /// commands in CDR, the request catalogue as a queryable, health and liveliness.
    ///
    /// Without --wck-port, --whj-bus and --robot it serves the built-in simulated robot.
    /// The first line printed starts `bridge: `. It listens on tcp/127.0.0.1:7447 only,
    /// with scouting off, unless --listen / --connect say otherwise; commands move
    /// nothing until armed, and a command stream quiet for --command-timeout holds the
    /// joints (docs/bridge.md).
    #[cfg(feature = "bridge")]
    Bridge(bridge::Args),
}

#[derive(Debug, Subcommand)]
enum SimCommand {
    /// Simulated wCK servos behind a pseudo-terminal (a serial port any program can open).
    Wck(sim_wck::Args),
    /// Simulated WHJ joints on a virtual CAN FD bus (python-can UDP multicast or SocketCAN).
    Whj(sim_whj::Args),
}

/// Logs go to stderr, coloured only when stderr is a terminal (a pipe or a file gets plain
/// text); a non-empty `NO_COLOR` also turns colour off.
fn init_logging(verbose: u8) {
    let default = match verbose {
        0 => "warn",
        1 => "info",
        2 => "debug",
        _ => "trace",
    };
    let colour = std::io::stderr().is_terminal()
        && std::env::var_os("NO_COLOR").is_none_or(|v| v.is_empty());
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                // Zenoh warns at every start of a peer with gossip off, which is the
                // bridge's safe default (docs/bridge.md): not a problem to report.
                .unwrap_or_else(|_| {
                    tracing_subscriber::EnvFilter::new(format!(
                        "{default},zenoh::net::routing::hat::peer=error"
                    ))
                }),
        )
        .with_writer(std::io::stderr)
        .with_ansi(colour)
        .init();
    tracing::debug!(
        version = env!("CARGO_PKG_VERSION"),
        colour,
        "robobus logging"
    );
}

/// Every argument that takes a value takes a negative number too (`move 3 -1`,
/// `--offset -5`), so that the command's own range check names the value, the allowed
/// range and the option, instead of clap taking `-1` for an unknown flag.
fn negative_numbers(cmd: clap::Command) -> clap::Command {
    cmd.mut_args(|a| {
        if a.get_action().takes_values() {
            a.allow_negative_numbers(true)
        } else {
            a
        }
    })
    .mut_subcommands(negative_numbers)
}

/// A command line clap refused (exit 2; help and version exit 0). Under `--json` the
/// error is JSON with its kind, as every other error is.
fn usage_error(e: &clap::Error) -> ExitCode {
    use clap::error::ErrorKind as K;
    let json = std::env::args_os().any(|a| a == "--json");
    if json && !matches!(e.kind(), K::DisplayHelp | K::DisplayVersion) {
        let text = exit::cut_long(&e.to_string());
        let message = text
            .lines()
            .next()
            .unwrap_or_default()
            .trim_start_matches("error: ");
        let v = serde_json::json!({
            "error": { "kind": "bad-input", "message": message, "exit_code": 2 }
        });
        eprintln!("{v}");
        return ExitCode::from(Exit::Usage as u8);
    }
    if matches!(e.kind(), K::DisplayHelp | K::DisplayVersion)
        || e.kind() == K::DisplayHelpOnMissingArgumentOrSubcommand
    {
        e.exit()
    }
    // clap's own message, with any absurdly long value cut.
    eprint!("{}", exit::cut_long(&e.render().to_string()));
    ExitCode::from(Exit::Usage as u8)
}

fn main() -> ExitCode {
    let parsed = negative_numbers(Cli::command())
        .try_get_matches()
        .and_then(|m| Cli::from_arg_matches(&m));
    let cli = match parsed {
        Ok(cli) => cli,
        Err(e) => return usage_error(&e),
    };
    init_logging(cli.global.verbose);
    let g = cli.global;
    let json = g.json;
    let result = match cli.command {
        Command::Demo(args) => demo::run(g, &args),
        Command::Wck(args) => wck::run(g, &args),
        Command::Whj(args) => whj::run(g, &args),
        Command::Monitor(args) => monitor::run(g, &args),
        Command::Plot(args) => plot::run(g, &args),
        Command::Robot(args) => robot::run(g, &args),
        Command::Replay(args) => replay::run(g, &args),
        Command::Doctor(args) => doctor::run(g, &args),
        Command::Ports(args) => ports::run(g, &args),
        Command::Completions(args) => generate::completions(&args),
        Command::Man(args) => generate::man(&args),
        Command::Sim(SimCommand::Wck(args)) => sim_wck::run(&args, g.dry_run),
        Command::Sim(SimCommand::Whj(args)) => sim_whj::run(&args, g.dry_run),
        Command::Run(args) => run::run(g, &args),
        Command::Schema(args) => run::schema(&args),
        Command::Studio(args) => studio::run(g, &args),
        #[cfg(feature = "bridge")]
        Command::Bridge(args) => bridge::run(g, &args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        // Our own output went to a reader that stopped reading (`robobus replay | head`):
        // the program ends quietly, as a pipeline expects.
        Err(err)
            if err
                .downcast_ref::<std::io::Error>()
                .is_some_and(|e| e.kind() == std::io::ErrorKind::BrokenPipe) =>
        {
            ExitCode::SUCCESS
        }
        Err(err) => {
            let code = Exit::of(&err);
            if json {
                // Under --json the error is JSON too, with its kind (on stderr, as the
                // text form; stdout keeps only reports).
                let v = serde_json::json!({
                    "error": {
                        "kind": exit::kind_name(&err),
                        "message": exit::cut_long(&exit::message(&err)),
                        "exit_code": code as u8,
                    }
                });
                eprintln!("{v}");
            } else {
                eprintln!("robobus: error: {}", exit::cut_long(&exit::message(&err)));
            }
            ExitCode::from(code as u8)
        }
    }
}
