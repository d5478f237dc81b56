//! `robobus sim wck`: simulated wCK servos behind a pseudo-terminal.
//!
//! Prints the path clients open (the `--link` symlink if given, else the pty slave) as the
//! only line on stdout, then serves until SIGINT / SIGTERM, and removes the symlink.

use std::io::Write as _;
use std::os::fd::AsFd as _;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use anyhow::{Context as _, bail};
use robobus_link::{FaultConfig, FaultyByteLink, PtyOptions, PtyPair};
use robobus_sim::wck::{Bus, BusConfig, Eeprom, Endpoint, Model, Timing};
use robobus_wck::{BaudRate, ExtServoId};

/// Options of `robobus sim wck`.
#[derive(Debug, clap::Args)]
pub(crate) struct Args {
    /// Servo IDs on the bus: a list of IDs and ranges, e.g. `0-5`, `0,2,4-6`. A repeated
    /// ID puts two modules with the same ID on the bus (their replies collide).
    #[arg(long, default_value = "0")]
    servos: String,
    /// wCK model of every servo: 1108, 1111 or 1413.
    #[arg(long, default_value = "1108")]
    model: String,
    /// Baud rate the servos are set to (4800, 9600, 38400, 57600, 115200, 230400, 460800,
    /// 921600). A client at another rate gets garbage, as on a real bus.
    #[arg(long, default_value_t = 115_200)]
    baud: u32,
    /// Also make this symlink to the pty (removed on exit).
    #[arg(long)]
    link: Option<PathBuf>,
    /// Seed for the turnaround spread between modules and for injected faults.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Module turnaround in microseconds (default 1006.6, from the manual); 0 for
    /// benchmarks of the wire alone.
    #[arg(long)]
    turnaround_us: Option<f64>,
    /// EEPROM write time in milliseconds (default 121).
    #[arg(long)]
    eeprom_ms: Option<f64>,
    /// Load the modules' EEPROM from this file if it exists, and save it there on exit.
    #[arg(long)]
    eeprom_file: Option<PathBuf>,
    /// Probability that a byte (either direction) is lost on the wire.
    #[arg(long, default_value_t = 0.0)]
    drop: f64,
    /// Probability that a byte (either direction) has a bit flipped on the wire.
    #[arg(long, default_value_t = 0.0)]
    flip: f64,
}

/// Parses `0-5,7,9-10` into IDs, in order (repeats kept).
fn parse_ids(spec: &str) -> anyhow::Result<Vec<u8>> {
    let mut ids = Vec::new();
    for part in spec.split(',').map(str::trim).filter(|p| !p.is_empty()) {
        let (lo, hi) = match part.split_once('-') {
            Some((a, b)) => (a.trim(), b.trim()),
            None => (part, part),
        };
        let parse = |s: &str| -> anyhow::Result<u8> {
            let v: u8 = s
                .parse()
                .with_context(|| format!("--servos: `{s}` is not an ID (0..=253)"))?;
            ExtServoId::new(v).map_err(|e| anyhow::anyhow!("--servos: {e}"))?;
            Ok(v)
        };
        let (lo, hi) = (parse(lo)?, parse(hi)?);
        if lo > hi {
            bail!("--servos: range {lo}-{hi} runs backwards");
        }
        ids.extend(lo..=hi);
    }
    if ids.is_empty() {
        bail!("--servos: no IDs given (e.g. `--servos 0-5`)");
    }
    Ok(ids)
}

fn probability(name: &str, p: f64) -> anyhow::Result<f64> {
    if (0.0..=1.0).contains(&p) {
        Ok(p)
    } else {
        bail!("--{name} {p} is out of range 0..=1")
    }
}

fn duration_of(name: &str, value: f64, unit: f64) -> anyhow::Result<Duration> {
    Duration::try_from_secs_f64(value * unit)
        .map_err(|_| anyhow::anyhow!("--{name} {value} must be a non-negative number"))
}

/// Serves the simulated bus until interrupted.
pub(crate) fn run(args: &Args) -> anyhow::Result<()> {
    let ids = parse_ids(&args.servos)?;
    let model: Model = args.model.parse()?;
    let baud =
        BaudRate::from_bits_per_second(args.baud).map_err(|e| anyhow::anyhow!("--baud: {e}"))?;
    let mut timing = Timing::MANUAL;
    if let Some(us) = args.turnaround_us {
        timing.turnaround = duration_of("turnaround-us", us, 1e-6)?;
    }
    if let Some(ms) = args.eeprom_ms {
        timing.eeprom_write = duration_of("eeprom-ms", ms, 1e-3)?;
    }
    let (lose, flip) = (
        probability("drop", args.drop)?,
        probability("flip", args.flip)?,
    );
    let config = BusConfig {
        host_baud: baud,
        timing,
        seed: args.seed,
        ..Default::default()
    };
    let mut bus = Bus::with_servos(config, model, ids.iter().copied());
    if let Some(path) = &args.eeprom_file
        && path.exists()
    {
        bus.load_eeproms(path)?;
    }

    let pair = PtyPair::open(&PtyOptions {
        baud: args.baud,
        symlink: args.link.clone(),
    })
    .context("creating the pseudo-terminal")?;
    let shown = args.link.clone().unwrap_or_else(|| pair.slave_path.clone());
    // The endpoint keeps its own slave descriptor; clients open the path.
    drop(pair.slave);
    let endpoint = if lose > 0.0 || flip > 0.0 {
        // Wire faults through the link layer's seeded fault injector, both directions.
        let termios = pair.master.as_fd().try_clone_to_owned()?;
        let faults = FaultConfig {
            drop: lose,
            corrupt: flip,
            ..FaultConfig::seeded(args.seed)
        };
        let link = FaultyByteLink::new(pair.master, faults);
        Endpoint::spawn_link(bus, link, Some(termios), shown.clone())
    } else {
        Endpoint::spawn(bus, pair.master, shown.clone())
    }
    .context("starting the simulator thread")?;

    let stop = Arc::new(AtomicBool::new(false));
    let flag = Arc::clone(&stop);
    ctrlc::set_handler(move || flag.store(true, Ordering::Relaxed))
        .context("installing the SIGINT/SIGTERM handler")?;

    let mut out = std::io::stdout().lock();
    writeln!(out, "{}", shown.display())?;
    out.flush()?;
    drop(out);
    eprintln!(
        "robobus sim wck: {} x {model} (IDs {}) at {} bit/s on {} (pty {}); Ctrl-C stops",
        ids.len(),
        args.servos,
        args.baud,
        shown.display(),
        pair.slave_path.display(),
    );

    while !stop.load(Ordering::Relaxed) && endpoint.is_running() {
        std::thread::sleep(Duration::from_millis(50));
    }
    let eeproms: Option<Vec<Eeprom>> = endpoint.with_bus(|bus| bus.eeproms());
    let stats = endpoint.stop()?;
    if let (Some(path), Some(eeproms)) = (&args.eeprom_file, eeproms) {
        Eeprom::save(&eeproms, path)?;
    }
    let mean_late = u32::try_from(stats.bytes_out)
        .ok()
        .filter(|n| *n > 0)
        .map_or(Duration::ZERO, |n| stats.late_total / n);
    eprintln!(
        "robobus sim wck: served {:.1} s, {} bytes in, {} bytes out, CPU {:.3} s ({:.2} %), \
         reply bytes late by {:?} on average, {:?} at most",
        stats.wall.as_secs_f64(),
        stats.bytes_in,
        stats.bytes_out,
        stats.cpu.as_secs_f64(),
        100.0 * stats.cpu.as_secs_f64() / stats.wall.as_secs_f64().max(1e-9),
        mean_late,
        stats.late_max,
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn id_lists() {
        assert_eq!(parse_ids("0-5").unwrap(), [0, 1, 2, 3, 4, 5]);
        assert_eq!(parse_ids("0, 2,4-5,4").unwrap(), [0, 2, 4, 5, 4]);
        assert!(
            parse_ids("5-3")
                .unwrap_err()
                .to_string()
                .contains("backwards")
        );
        assert!(parse_ids("254").unwrap_err().to_string().contains("254"));
        assert!(parse_ids("x").is_err());
        assert!(parse_ids("").is_err());
    }
}
