//! `robobus studio`: the web studio (crate `robobus-studio`) on a station of the given
//! buses, or on the built-in simulated robot; prints `studio: http://ADDR/` first and
//! serves until Ctrl-C.

use std::net::{IpAddr, Ipv4Addr, SocketAddr};
use std::path::PathBuf;

use anyhow::Context as _;
use robobus::frontend::guard::GuardConfig;
use robobus::ops::{OpError, read_bounded};
use robobus::station::{Station, StationConfig};
use robobus_studio::{CaptureDir, Studio, StudioConfig};

use crate::Global;

/// Options of `robobus studio`.
#[derive(Debug, clap::Args)]
pub(crate) struct Args {
    /// The port on 127.0.0.1 (0: any free port; the first line printed names it).
    #[arg(long, default_value_t = 7480)]
    port: u16,
    /// Listen on another address (`0.0.0.0:8080`); any address but loopback needs
    /// --token-file.
    #[arg(long, value_name = "ADDR")]
    listen: Option<SocketAddr>,
    /// A file holding the token every request must carry (one word of 16 characters or
    /// more; needed off loopback).
    #[arg(long, value_name = "FILE")]
    token_file: Option<PathBuf>,
    /// Serve monitoring only: nothing that changes a device is served.
    #[arg(long)]
    read_only: bool,
    #[command(flatten)]
    station: crate::run::StationArgs,
    /// Heartbeat timeout of an armed page, ms (50..=5000): past it, the devices it moved
    /// are brought to their safe state. The page beats every 100 ms; on a machine loaded
    /// beyond its cores its beats arrive more than 500 ms apart now and then, hence 1000
    /// (docs/studio.md).
    #[arg(long, default_value_t = 1000, value_parser = clap::value_parser!(u64).range(50..=5000))]
    heartbeat_timeout_ms: u64,
}

/// The largest token file read.
const TOKEN_LIMIT: u64 = 4096;

fn token(args: &Args) -> anyhow::Result<Option<String>> {
    let Some(path) = &args.token_file else {
        return Ok(None);
    };
    let text = read_bounded(path, TOKEN_LIMIT)?;
    let t = text.trim();
    if t.len() < 16 || t.chars().any(char::is_whitespace) {
        return Err(OpError::invalid(
            "--token-file",
            path.display(),
            "the token must be one word of at least 16 characters",
        )
        .into());
    }
    Ok(Some(t.to_owned()))
}

/// Runs `robobus studio`.
pub(crate) fn run(g: Global, args: &Args) -> anyhow::Result<()> {
    let listen = args
        .listen
        .unwrap_or(SocketAddr::new(IpAddr::V4(Ipv4Addr::LOCALHOST), args.port));
    let token = token(args)?;
    if g.dry_run {
        return crate::output::print(&format!(
            "studio: would serve http://{listen}/ ({}), opening nothing\n",
            if args.station.simulated() {
                "the built-in simulated robot"
            } else {
                "the given buses"
            }
        ));
    }
    // The session's traffic is captured in a folder of its own (served by the page's
    // Capture panel): made fresh with mode 0700 under an unpredictable name, and its
    // capture files removed when the studio stops, whatever way it stops; anything else
    // found in it is left, and said.
    let tmp = std::env::temp_dir();
    let capture_dir = CaptureDir::create(&tmp)
        .with_context(|| format!("creating the capture folder in {}", tmp.display()))?;
    let mut made = Vec::new();
    let served = serve_in(args, g.wait, listen, token, capture_dir.path(), &mut made);
    for left in capture_dir.remove(&made) {
        tracing::warn!(
            "left in place (not made by this studio): {}",
            left.display()
        );
    }
    served
}

fn serve_in(
    args: &Args,
    wait: robobus::WaitMode,
    listen: SocketAddr,
    token: Option<String>,
    capture_dir: &std::path::Path,
    made: &mut Vec<PathBuf>,
) -> anyhow::Result<()> {
    let (station, sim) = if args.station.simulated() {
        let (station, sim) = Station::simulated_live(Some(capture_dir))?;
        (station, Some(sim))
    } else {
        let station = Station::open(&StationConfig {
            capture_dir: Some(capture_dir.to_path_buf()),
            wait,
            ..args.station.config()
        })?;
        (station, None)
    };
    made.extend(station.captures().iter().map(|(_, path)| path.clone()));
    let studio = Studio::bind(
        station,
        sim,
        StudioConfig {
            listen,
            token,
            read_only: args.read_only,
            guard: GuardConfig {
                heartbeat_timeout: std::time::Duration::from_millis(args.heartbeat_timeout_ms),
                ..GuardConfig::default()
            },
        },
    )
    .map_err(|e| match e.kind() {
        robobus::ErrorKind::BadInput => crate::exit::usage(e.to_string()),
        _ => anyhow::Error::new(e),
    })?;
    // The Ctrl-C handler is in place before the address is printed: a signal sent as soon
    // as that line is read stops the studio cleanly, never kills it.
    let stop = crate::interrupt::stop_token();
    crate::output::print(&format!("studio: http://{}/\n", studio.addr()))?;
    studio.serve(&stop)?;
    Ok(())
}
