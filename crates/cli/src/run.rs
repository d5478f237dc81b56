//! `robobus run FILE.json` and `robobus schema`: the catalogue's requests from JSON.
//!
//! `run` parses one request or an array of them ([`robobus::catalogue::Request`]), opens a
//! station from `--wck-port`, `--whj-bus` and `--robot` (with none of them: the built-in
//! simulated robot, [`Station::simulated`]) and runs them in order through the library's
//! dispatcher; it prints each report ([`robobus::catalogue::Report`]) as JSON (one object,
//! or an array for an array). `--dry-run` prints the plans instead (text: the lines the
//! subcommand's `--dry-run` prints; `--json`: the plan views every front end shows,
//! `robobus::frontend::PlanView`). The first request that fails as a whole ends the run
//! (later ones are not sent); the exit code is the worst failure, a device's included.
//! Confirmation is part of the request (`confirm: true`).

use std::io::Read as _;
use std::path::PathBuf;

use robobus::catalogue::{self, Request};
use robobus::ops::{Control, OpError, read_bounded};
use robobus::station::{Station, StationConfig};
use robobus_wck::BaudRate;
use serde_json::Value;

use crate::Global;
use crate::exit::Timeout;
use crate::output;

/// The largest request file read.
const REQUEST_LIMIT: u64 = 4 << 20;

/// Options of `robobus run`.
#[derive(Debug, clap::Args)]
pub(crate) struct Args {
    /// The request file: one JSON request (`{"op": "wck.status", "ids": "0-2"}`) or an
    /// array of them; `-` reads standard input.
    file: PathBuf,
    #[command(flatten)]
    station: StationArgs,
}

/// The buses a front end on the catalogue opens (`run`, `studio`): with none of them, the
/// built-in simulated robot.
#[derive(Debug, clap::Args)]
pub(crate) struct StationArgs {
    /// A wCK serial port to open (repeatable; requests name it under `bus`).
    #[arg(long, value_name = "PATH")]
    wck_port: Vec<String>,
    /// The baud rate of the wCK ports.
    #[arg(long, default_value = "115200", value_parser = crate::wck::parse_baud)]
    wck_baud: BaudRate,
    /// A WHJ bus to open: udp, udp:GROUP:PORT, a SocketCAN interface, slcan:PORT or
    /// fdcanusb:PORT (repeatable).
    #[arg(long, value_name = "BUS")]
    whj_bus: Vec<String>,
    /// A robot file whose buses are opened too (named as in the file).
    #[arg(long, value_name = "FILE")]
    robot: Option<PathBuf>,
}

impl StationArgs {
    /// No bus named: the built-in simulated robot.
    pub(crate) fn simulated(&self) -> bool {
        self.wck_port.is_empty() && self.whj_bus.is_empty() && self.robot.is_none()
    }

    /// The station's configuration.
    pub(crate) fn config(&self) -> StationConfig {
        StationConfig {
            wck_ports: self.wck_port.clone(),
            wck_baud: Some(self.wck_baud),
            whj_buses: self.whj_bus.clone(),
            robot: self.robot.clone(),
            ..StationConfig::default()
        }
    }
}

/// Which schema `robobus schema` prints.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub(crate) enum Which {
    /// Requests.
    Request,
    /// Reports.
    Report,
    /// Plans (--dry-run).
    Plan,
    /// The host bounds table.
    Bounds,
}

/// Options of `robobus schema`.
#[derive(Debug, clap::Args)]
pub(crate) struct SchemaArgs {
    /// Which schema (all of them, in one object, without it).
    #[arg(value_enum)]
    which: Option<Which>,
}

fn read_requests(args: &Args) -> anyhow::Result<(Vec<Request>, bool)> {
    let text = if args.file.as_os_str() == "-" {
        let mut s = String::new();
        std::io::stdin()
            .take(REQUEST_LIMIT + 1)
            .read_to_string(&mut s)?;
        if s.len() as u64 > REQUEST_LIMIT {
            return Err(OpError::invalid("FILE", "-", "larger than the limit of 4 MiB").into());
        }
        s
    } else {
        read_bounded(&args.file, REQUEST_LIMIT)?
    };
    let many = text.trim_start().starts_with('[');
    Ok((Request::parse_many(&text)?, many))
}

/// Runs `robobus run`.
pub(crate) fn run(g: Global, args: &Args) -> anyhow::Result<()> {
    let (requests, many) = read_requests(args)?;
    let numbered = |n: usize, e: OpError| -> anyhow::Error {
        if many {
            anyhow::Error::new(e).context(format!("request {}", n + 1))
        } else {
            e.into()
        }
    };
    if g.dry_run {
        let plans = requests
            .iter()
            .enumerate()
            .map(|(n, r)| robobus::frontend::PlanView::of(r).map_err(|e| numbered(n, e)))
            .collect::<anyhow::Result<Vec<_>>>()?;
        if g.json {
            let v = serde_json::to_value(&plans)?;
            return output::print_json(&if many { v } else { first(v) });
        }
        let text: String = plans.iter().map(|p| p.text.as_str()).collect();
        return output::print(&text);
    }
    // Every request is checked before any is sent: bad input anywhere in a list sends
    // nothing at all.
    for (n, r) in requests.iter().enumerate() {
        catalogue::validate(r).map_err(|e| numbered(n, e))?;
    }
    let station = if args.station.simulated() {
        Station::simulated()?
    } else {
        Station::open(&StationConfig {
            wait: g.wait,
            ..args.station.config()
        })?
    };
    let stop = crate::interrupt::stop_token();
    let mut reports = Vec::new();
    let mut outcome: anyhow::Result<()> = Ok(());
    for r in &requests {
        match catalogue::run(&station, r, &mut Control::new(&stop)) {
            Ok(report) => {
                if outcome.is_ok()
                    && let Some(kind) = report.failed_kind()
                {
                    let message = report.error.clone().unwrap_or_default();
                    outcome = Err(match kind {
                        robobus::ErrorKind::NoDevice => anyhow::Error::new(Timeout(message)),
                        robobus::ErrorKind::BadInput | robobus::ErrorKind::Refused => {
                            crate::exit::usage(message)
                        }
                        robobus::ErrorKind::Interrupted => {
                            anyhow::Error::new(crate::exit::Interrupted).context(message)
                        }
                        _ => anyhow::Error::new(OpError::Device(message)),
                    });
                }
                reports.push(serde_json::to_value(&report)?);
            }
            Err(e) => {
                outcome = Err(e.into());
                break;
            }
        }
    }
    // Every device is left as its requests left it, as the `wck` and `whj` subcommands
    // leave theirs: a robot operation ends in its file's `safe_state` itself, and an
    // interrupted request has brought its devices to its own stop state.
    station.leave();
    // A list prints the reports of the requests that ran; a single request that failed
    // as a whole prints none.
    if many || !reports.is_empty() {
        let v = Value::Array(reports);
        output::print_json(&if many { v } else { first(v) })?;
    }
    outcome
}

fn first(v: Value) -> Value {
    match v {
        Value::Array(mut a) if !a.is_empty() => a.swap_remove(0),
        other => other,
    }
}

/// Runs `robobus schema`.
pub(crate) fn schema(args: &SchemaArgs) -> anyhow::Result<()> {
    let v = match args.which {
        Some(Which::Request) => catalogue::request_schema(),
        Some(Which::Report) => catalogue::report_schema(),
        Some(Which::Plan) => catalogue::plan_schema(),
        Some(Which::Bounds) => catalogue::bounds_json(),
        None => catalogue::schemas(),
    };
    output::print_json(&v)
}
