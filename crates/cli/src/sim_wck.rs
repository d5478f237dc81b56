//! `robobus sim wck`: simulated wCK servos behind a pseudo-terminal, or over TCP
//! (`--listen`, pyserial's `socket://HOST:PORT`, on every OS).
//!
//! Prints what clients open (the `--link` symlink if given, else the pty slave; with
//! `--listen`, `socket://HOST:PORT` with the port chosen) as the only line on stdout once
//! the simulated servos listen (past the manual's 65 ms of deafness after power-up, unless
//! `--power-up-on-open`), then serves until SIGINT / SIGTERM, and removes the symlink if it
//! still points to its own pty.

use std::io::Write as _;
use std::net::SocketAddr;
#[cfg(unix)]
use std::os::fd::AsFd as _;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use std::ops::RangeInclusive;

use anyhow::Context as _;
use robobus::ops::capture::{Overwrite, capture_device_byte_link};
use robobus_link::{ByteLink, FaultConfig, FaultyByteLink, PortSpec, TcpServer, WaitMode};
#[cfg(unix)]
use robobus_link::{LinkError, PtyLink, PtyOptions, PtyPair, PtySymlink};
use robobus_sim::faults::{DeviceFault, DeviceFaultKind, FaultSchedule};
use robobus_sim::wck::{Bus, BusConfig, Eeprom, Endpoint, Model, Timing};
use robobus_wck::{BaudRate, ExtServoId};

use crate::exit::usage;
use crate::hand::Hand;

/// What `robobus sim wck --help` adds after the options.
const AFTER_LONG_HELP: &str = "\
Readiness: the path is printed (and the --link symlink made) only once the simulated servos
listen, as on real hardware, where the modules were powered long before the host connects.
--power-up-on-open instead powers them up the moment the path appears: a command sent in
the first 65 ms is then lost, as the manual says.

The link is a pseudo-terminal (pty). Programs that open it like a serial port through
termios work: pyserial (serial.Serial(PATH, 115200)), minicom, picocom, screen, the
robobus client, anything that sets the baud rate with tcsetattr (the simulator follows
it). A pty has no modem lines: the TIOCMGET / TIOCMSET / TIOCMBIS / TIOCMBIC ioctls fail
with ENOTTY (\"Inappropriate ioctl for device\"). pyserial opens it (it ignores ENOTTY
when it sets DTR / RTS on open), but setting ser.dtr or ser.rts later, or reading
ser.cts / ser.dsr, raises OSError. Programs that insist on the modem lines when opening
cannot use it: .NET / mono System.IO.Ports (SerialPort.Open sets DTR and RTS) fails.
Such programs need a real serial port (a USB-serial adapter wired to the servos).

--listen IP:PORT serves the bus over TCP instead (every OS; the only way where there are
no ptys, as on Windows): clients name it socket://IP:PORT (robobus --port, pyserial's
serial.serial_for_url). Port 0 picks a free port; the line printed says which. Exactly
the address given is listened on: 127.0.0.1 keeps it on this machine, anything else lets
other machines drive the simulated servos. One client is served at a time, as one
program has a serial port open; a connection made while one is served is closed at once,
and the next is served once the client leaves (a port closed and opened again). A TCP
stream has no line rate: the wire runs at --baud, with the same timing as on the pty.

Faults: --drop / --flip / --duplicate / --truncate / --delay / --disconnect-after act on
the wire (both directions) through the link layer's seeded fault injector: the same
--fault-seed and the same traffic give the same faults. --fault-silent and
--fault-power-cycle act on one servo at a time after the path appears (repeat them for
more).";

/// Options of `robobus sim wck`.
#[derive(Debug, clap::Args)]
#[command(after_long_help = AFTER_LONG_HELP)]
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
    /// Also make this symlink to the pty (removed on exit if it still points to it). Only
    /// a stale link of a simulator is replaced; a file or another live simulator's link
    /// there is an error (exit 2).
    #[arg(long, conflicts_with = "listen")]
    link: Option<PathBuf>,
    /// Serve over TCP on this address instead of a pty, e.g. `127.0.0.1:5600` (port 0
    /// picks a free one; the printed `socket://` line names it). Only the address given is
    /// listened on.
    #[arg(long, value_name = "IP:PORT")]
    listen: Option<String>,
    /// Record every byte the simulated servos receive and send to FILE (a timestamped hex
    /// log from the servos' side; `robobus replay FILE` decodes it). An existing FILE is
    /// not overwritten.
    #[arg(long, value_name = "FILE")]
    capture: Option<PathBuf>,
    /// Power the servos up when the path appears (they ignore the bus for the manual's
    /// 65 ms), instead of before.
    #[arg(long)]
    power_up_on_open: bool,
    /// Seed for the turnaround spread between modules (and the faults' default seed).
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
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    drop: f64,
    /// Probability that a byte (either direction) has a bit flipped on the wire.
    #[arg(
        long,
        visible_alias = "corrupt",
        default_value_t = 0.0,
        allow_negative_numbers = true
    )]
    flip: f64,
    #[command(flatten)]
    faults: LinkFaultArgs,
    /// A hand turns servo ID's shaft back and forth between FROM and TO degrees (from the
    /// centre, step 127) once every PERIOD seconds, as someone calibrating a robot does:
    /// `ID:FROM:TO:PERIOD`, e.g. `0:-40:50:1`. A servo that holds its position fights it
    /// (make it passive). Repeatable.
    #[arg(long, value_name = "ID:FROM:TO:PERIOD", allow_negative_numbers = true)]
    hand: Vec<String>,
    /// Servo ID stops answering (powered off) SECONDS after the path appears: `ID@SECONDS`,
    /// e.g. `3@2.5`. Repeatable.
    #[arg(long, value_name = "ID@SECONDS")]
    fault_silent: Vec<String>,
    /// Servo ID browns out (power-cycled: runtime state lost, deaf for 65 ms) SECONDS after
    /// the path appears: `ID@SECONDS`. Repeatable.
    #[arg(long, value_name = "ID@SECONDS")]
    fault_power_cycle: Vec<String>,
}

/// Link faults shared by both simulators (besides `--drop` and the corruption option).
#[derive(Debug, Clone, clap::Args)]
pub(crate) struct LinkFaultArgs {
    /// Probability that a byte / frame (either direction) is sent twice.
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    pub(crate) duplicate: f64,
    /// Probability that a write / frame is cut short.
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    pub(crate) truncate: f64,
    /// Probability that a write / read / frame is held back by --delay-ms.
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    pub(crate) delay: f64,
    /// How long a delayed operation waits, ms (0..=10000).
    #[arg(long, default_value_t = 1.0, allow_negative_numbers = true)]
    pub(crate) delay_ms: f64,
    /// The link closes (the simulator stops) after this many reads + writes.
    #[arg(long, value_name = "N")]
    pub(crate) disconnect_after: Option<u64>,
    /// Seed of the link faults (default: --seed): the same seed and traffic give the same
    /// faults.
    #[arg(long, value_name = "N")]
    pub(crate) fault_seed: Option<u64>,
}

impl LinkFaultArgs {
    /// The fault injector's configuration, validated; `None` when no fault is asked for.
    pub(crate) fn config(
        &self,
        seed: u64,
        drop: (&str, f64),
        corrupt: (&str, f64),
    ) -> anyhow::Result<Option<FaultConfig>> {
        if !(0.0..=10_000.0).contains(&self.delay_ms) {
            return Err(usage(format!(
                "--delay-ms {} out of range (allowed: 0..=10000)",
                self.delay_ms
            )));
        }
        let delay_by = duration_of("delay-ms", self.delay_ms, 1e-3)?;
        let cfg = FaultConfig {
            drop: probability(drop.0, drop.1)?,
            corrupt: probability(corrupt.0, corrupt.1)?,
            duplicate: probability("duplicate", self.duplicate)?,
            truncate: probability("truncate", self.truncate)?,
            delay: probability("delay", self.delay)?,
            delay_by,
            disconnect_after: self.disconnect_after,
            ..FaultConfig::seeded(self.fault_seed.unwrap_or(seed))
        };
        let any = [
            cfg.drop,
            cfg.corrupt,
            cfg.duplicate,
            cfg.truncate,
            cfg.delay,
        ]
        .iter()
        .any(|p| *p > 0.0)
            || cfg.disconnect_after.is_some();
        Ok(any.then_some(cfg))
    }
}

/// Parses every `--fault-silent` / `--fault-power-cycle` (and, for WHJ, `--fault-error`)
/// value; every ID must be on the simulated bus.
pub(crate) fn device_faults(
    groups: &[(&str, DeviceFaultKind, &[String])],
    ids: RangeInclusive<u8>,
    present: &[u8],
) -> anyhow::Result<Vec<DeviceFault>> {
    let mut out = Vec::new();
    for (option, kind, values) in groups {
        for v in *values {
            let f = DeviceFault::parse(v, *kind, ids.clone(), option)
                .map_err(|e| usage(e.to_string()))?;
            if !present.contains(&f.id) {
                return Err(usage(format!(
                    "{option} {v:?}: no device with ID {} is simulated (IDs on the bus: {present:?})",
                    f.id
                )));
            }
            out.push(f);
        }
    }
    Ok(out)
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
                .map_err(|_| usage(format!("--servos: `{s}` is not an ID (allowed: 0..=253)")))?;
            ExtServoId::new(v).map_err(|e| usage(format!("--servos: {e}")))?;
            Ok(v)
        };
        let (lo, hi) = (parse(lo)?, parse(hi)?);
        if lo > hi {
            return Err(usage(format!(
                "--servos: range {lo}-{hi} runs backwards (write the lower ID first)"
            )));
        }
        ids.extend(lo..=hi);
    }
    if ids.is_empty() {
        return Err(usage("--servos: no IDs given (e.g. `--servos 0-5`)"));
    }
    Ok(ids)
}

pub(crate) fn probability(name: &str, p: f64) -> anyhow::Result<f64> {
    if (0.0..=1.0).contains(&p) {
        Ok(p)
    } else {
        Err(usage(format!("--{name} {p} out of range (allowed: 0..=1)")))
    }
}

fn duration_of(name: &str, value: f64, unit: f64) -> anyhow::Result<Duration> {
    Duration::try_from_secs_f64(value * unit).map_err(|_| {
        usage(format!(
            "--{name} {value} out of range (allowed: a non-negative number)"
        ))
    })
}

/// What a dry run prints: the bus it would serve; nothing is opened.
fn print_dry_run(args: &Args, ids: &[u8], listen: Option<SocketAddr>) -> anyhow::Result<()> {
    // A dry run opens nothing: no pty, no socket, no link, no EEPROM file written.
    let ids: Vec<String> = ids.iter().map(u8::to_string).collect();
    let on = listen.map_or_else(
        || {
            format!(
                "a new pty{}",
                args.link
                    .as_ref()
                    .map(|l| format!(" linked from {}", l.display()))
                    .unwrap_or_default()
            )
        },
        |addr| format!("TCP {addr}"),
    );
    crate::output::print(&format!(
        "# would serve {} simulated wCK {} servo(s) [{}] at {} bit/s on {on}; \
         nothing opened\n",
        ids.len(),
        args.model,
        ids.join(","),
        args.baud,
    ))
}

/// Reads `--listen`: `IP:PORT` (or `socket://IP:PORT`), an IPv6 address in brackets.
fn parse_listen(value: &str) -> anyhow::Result<SocketAddr> {
    let text = value
        .strip_prefix("socket://")
        .or_else(|| value.strip_prefix("SOCKET://"))
        .unwrap_or(value);
    text.parse().map_err(|_| {
        usage(format!(
            "--listen {:?}: expected IP:PORT, e.g. 127.0.0.1:5600 (an IPv6 address in \
             brackets, [::1]:5600; port 0..=65535, 0 picks a free port)",
            crate::exit::cut_long(value)
        ))
    })
}

/// Wraps `link` in the wire faults and the capture when asked for.
fn wrap_link(
    link: Box<dyn ByteLink + Send>,
    wire_faults: Option<FaultConfig>,
    capture: Option<&std::path::Path>,
) -> anyhow::Result<Box<dyn ByteLink + Send>> {
    let mut link = link;
    if let Some(faults) = wire_faults {
        link = Box::new(FaultyByteLink::new(link, faults));
    }
    if let Some(path) = capture {
        link = Box::new(capture_device_byte_link(link, path, Overwrite::No)?);
    }
    Ok(link)
}

/// Starts the thread that serves `bus` over TCP, through the wire faults and the capture
/// when asked for.
fn spawn_tcp_endpoint(
    bus: Bus,
    server: TcpServer,
    wire_faults: Option<FaultConfig>,
    capture: Option<&std::path::Path>,
) -> anyhow::Result<Endpoint> {
    if wire_faults.is_none() && capture.is_none() {
        return Ok(Endpoint::spawn_tcp(bus, server, WaitMode::Sleep)?);
    }
    let port = server.port_spec();
    let link = wrap_link(Box::new(server), wire_faults, capture)?;
    Ok(Endpoint::spawn_at(bus, link, None, port, WaitMode::Sleep)?)
}

/// Starts the thread that serves `bus` on the pty master, through the wire faults and the
/// capture when asked for.
#[cfg(unix)]
fn spawn_endpoint(
    bus: Bus,
    master: PtyLink,
    slave_path: &std::path::Path,
    wire_faults: Option<FaultConfig>,
    capture: Option<&std::path::Path>,
) -> anyhow::Result<Endpoint> {
    Ok(match (wire_faults, capture) {
        (None, None) => Endpoint::spawn(bus, master, slave_path.to_path_buf())?,
        (faults, capture) => {
            // Wire faults through the link layer's seeded fault injector, both directions;
            // the capture sees what the simulated servos received and sent.
            let termios = master.as_fd().try_clone_to_owned()?;
            let link = wrap_link(Box::new(master), faults, capture)?;
            Endpoint::spawn_link(bus, link, Some(termios), slave_path.to_path_buf())?
        }
    })
}

/// The manual's timing with the turnaround and EEPROM write time asked for.
fn timing_of(args: &Args) -> anyhow::Result<Timing> {
    let mut timing = Timing::MANUAL;
    if let Some(us) = args.turnaround_us {
        timing.turnaround = duration_of("turnaround-us", us, 1e-6)?;
    }
    if let Some(ms) = args.eeprom_ms {
        timing.eeprom_write = duration_of("eeprom-ms", ms, 1e-3)?;
    }
    Ok(timing)
}

/// Serves the simulated bus until interrupted.
pub(crate) fn run(args: &Args, dry_run: bool) -> anyhow::Result<()> {
    let ids = parse_ids(&args.servos)?;
    let model: Model = args
        .model
        .parse()
        .map_err(|e| usage(format!("--model: {e}")))?;
    let baud =
        BaudRate::from_bits_per_second(args.baud).map_err(|e| usage(format!("--baud: {e}")))?;
    let timing = timing_of(args)?;
    let (wire_faults, device) = faults_of(args, &ids)?;
    let hands = args
        .hand
        .iter()
        .map(|h| Hand::parse(h, &ids, 135.0))
        .collect::<anyhow::Result<Vec<_>>>()?;
    let listen = args.listen.as_deref().map(parse_listen).transpose()?;
    if let Some(link) = &args.link {
        check_link_path(link)?;
    }
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
    if !args.power_up_on_open {
        // Powered long before anyone connects, as real modules are: past the manual's
        // 65 ms of deafness before the path appears.
        bus.advance(timing.power_up_deaf);
    }
    let opened_at = bus.now();
    let schedule = FaultSchedule::new(device).shifted(opened_at);

    if dry_run {
        return print_dry_run(args, &ids, listen);
    }
    let served = Served {
        ids: &ids,
        model,
        opened_at,
    };
    match listen {
        Some(addr) => serve_tcp(args, bus, addr, (wire_faults, schedule, &hands), &served),
        None => serve_pty(args, bus, (wire_faults, schedule, &hands), &served),
    }
}

/// What both ways of serving print and need.
struct Served<'a> {
    ids: &'a [u8],
    model: Model,
    opened_at: Duration,
}

/// The wire faults, the device-fault schedule and the hands.
type Extras<'a> = (Option<FaultConfig>, FaultSchedule, &'a [Hand]);

/// Serves over TCP on `addr` until interrupted.
fn serve_tcp(
    args: &Args,
    bus: Bus,
    addr: SocketAddr,
    (wire_faults, mut schedule, hands): Extras<'_>,
    served: &Served<'_>,
) -> anyhow::Result<()> {
    let listener = TcpServer::bind(addr, args.baud).map_err(|e| match &e {
        robobus_link::LinkError::Io { source, .. }
            if matches!(
                source.kind(),
                std::io::ErrorKind::AddrInUse | std::io::ErrorKind::AddrNotAvailable
            ) =>
        {
            usage(format!(
                "--listen {addr}: {source} (pick another port, 0 for a free one, or an \
                 address of this machine such as 127.0.0.1)"
            ))
        }
        _ => anyhow::Error::new(e),
    })?;
    let port: PortSpec = listener.port_spec();
    let endpoint = spawn_tcp_endpoint(bus, listener, wire_faults, args.capture.as_deref())
        .context("starting the simulator thread")?;
    let token = crate::interrupt::stop_token();
    let stop = token.flag();
    let mut out = std::io::stdout().lock();
    writeln!(out, "{port}")?;
    out.flush()?;
    drop(out);
    let reach = if addr.ip().is_loopback() {
        ""
    } else {
        " (not loopback: other machines can reach it)"
    };
    eprintln!(
        "robobus sim wck: {} x {} (IDs {}) at {} bit/s on {port}{reach}, one client at a \
         time; Ctrl-C stops",
        served.ids.len(),
        served.model,
        args.servos,
        args.baud,
    );
    serve_until_stopped(&endpoint, &mut schedule, hands, served.opened_at, stop);
    finish(args, endpoint, || {})
}

/// Serves on a new pty until interrupted.
#[cfg(not(unix))]
fn serve_pty(
    _args: &Args,
    _bus: Bus,
    _extras: Extras<'_>,
    _served: &Served<'_>,
) -> anyhow::Result<()> {
    Err(anyhow::Error::new(crate::exit::NotAvailable(
        "this system has no pseudo-terminals: serve over TCP with --listen 127.0.0.1:5600 \
         and name the port socket://127.0.0.1:5600"
            .into(),
    )))
}

/// Serves on a new pty until interrupted.
#[cfg(unix)]
fn serve_pty(
    args: &Args,
    bus: Bus,
    (wire_faults, mut schedule, hands): Extras<'_>,
    served: &Served<'_>,
) -> anyhow::Result<()> {
    let (ids, model, opened_at) = (served.ids, served.model, served.opened_at);
    let pair = PtyPair::open(&PtyOptions {
        baud: args.baud,
        symlink: None,
    })
    .context("creating the pseudo-terminal")?;
    let slave_path = pair.slave_path.clone();
    // The endpoint keeps its own slave descriptor; clients open the path.
    drop(pair.slave);
    let endpoint = spawn_endpoint(
        bus,
        pair.master,
        &slave_path,
        wire_faults,
        args.capture.as_deref(),
    )
    .context("starting the simulator thread")?;
    // Before the path appears: a client (or a test) may signal us as soon as it sees it.
    // The command's one Ctrl-C / SIGTERM handler (`interrupt`), installed now.
    let token = crate::interrupt::stop_token();
    let stop = token.flag();
    // The servos listen now: only now does the stable path appear.
    let symlink = match &args.link {
        Some(link) => Some(PtySymlink::create(link, &slave_path).map_err(|e| match e {
            LinkError::PathInUse { .. } => usage(format!("--link: {e}")),
            e => anyhow::Error::new(e),
        })?),
        None => None,
    };
    let shown = symlink
        .as_ref()
        .map_or_else(|| slave_path.clone(), |l| l.path().to_path_buf());

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
        slave_path.display(),
    );

    serve_until_stopped(&endpoint, &mut schedule, hands, opened_at, stop);
    // After the pty is closed; removed only if it still points to our pty.
    finish(args, endpoint, move || drop(symlink))
}

/// Stops the endpoint, saves the EEPROM file and reports; `after_close` runs once the
/// link is closed.
fn finish(args: &Args, endpoint: Endpoint, after_close: impl FnOnce()) -> anyhow::Result<()> {
    // The serving thread may be inside an injected delay (--delay-ms up to 10 s): Ctrl-C
    // is answered within STOP_WAIT all the same; the process then ends without it.
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let eeproms: Option<Vec<Eeprom>> = endpoint.with_bus(|bus| bus.eeproms());
        let _ = tx.send((eeproms, endpoint.stop()));
    });
    let stopped = rx.recv_timeout(STOP_WAIT);
    after_close();
    let Ok((eeproms, stats)) = stopped else {
        eprintln!(
            "robobus sim wck: stopped while an injected delay was pending (after {} ms); \
             statistics and the EEPROM file were not written",
            STOP_WAIT.as_millis()
        );
        return Ok(());
    };
    let stats = stats?;
    if let (Some(path), Some(eeproms)) = (&args.eeprom_file, eeproms) {
        Eeprom::save(&eeproms, path)?;
    }
    report(&stats);
    Ok(())
}

/// How long a stop waits for the serving thread before the process ends without it.
const STOP_WAIT: Duration = Duration::from_millis(500);

/// The wire faults (if any) and the device faults, validated.
fn faults_of(args: &Args, ids: &[u8]) -> anyhow::Result<(Option<FaultConfig>, Vec<DeviceFault>)> {
    let wire_faults = args
        .faults
        .config(args.seed, ("drop", args.drop), ("flip", args.flip))?;
    let device = device_faults(
        &[
            (
                "--fault-silent",
                DeviceFaultKind::Silent,
                &args.fault_silent,
            ),
            (
                "--fault-power-cycle",
                DeviceFaultKind::PowerCycle,
                &args.fault_power_cycle,
            ),
        ],
        0..=253,
        ids,
    )?;
    Ok((wire_faults, device))
}

/// The shaft angle (degrees, step 0 = 0°) of a servo at `deg` from the centre.
fn shaft_angle(deg: f64) -> f64 {
    127.0 * robobus_sim::wck::mechanics::DEG_PER_STEP8 + deg
}

/// Applies the device faults at their times, and turns the `--hand` servos, until Ctrl-C
/// or the endpoint stops.
fn serve_until_stopped(
    endpoint: &Endpoint,
    schedule: &mut FaultSchedule,
    hands: &[Hand],
    opened_at: Duration,
    stop: &AtomicBool,
) {
    let t0 = std::time::Instant::now();
    while !stop.load(Ordering::Relaxed) && endpoint.is_running() {
        let now = opened_at + t0.elapsed();
        if !hands.is_empty() {
            let t = t0.elapsed().as_secs_f64();
            let turns: Vec<(u8, f64)> = hands.iter().map(|h| (h.id, h.angle(t))).collect();
            endpoint.with_bus(move |bus| {
                for (id, deg) in turns {
                    if let Some(s) = bus.slot_of(id).and_then(|i| bus.servo_mut(i)) {
                        s.set_angle(shaft_angle(deg));
                    }
                }
            });
        }
        if schedule.next_due().is_some_and(|t| t <= now) {
            let due: Vec<DeviceFault> = schedule.take_due(now).to_vec();
            endpoint.with_bus(move |bus| {
                for f in &due {
                    let hit = bus.apply_fault(f);
                    eprintln!("robobus sim wck: fault: servo {f} ({hit} module(s))");
                }
            });
        }
        let tick = if hands.is_empty() {
            Duration::from_millis(50)
        } else {
            Duration::from_millis(10)
        };
        let nap = schedule
            .next_due()
            .map_or(tick, |t| t.saturating_sub(now).min(tick));
        std::thread::sleep(nap);
    }
}

fn report(stats: &robobus_sim::wck::EndpointStats) {
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
}

/// Refuses a `--link` path that is plainly not ours before anything is opened: a regular
/// file, a directory, a device (the full check, against live simulators too, is
/// `PtySymlink::create`).
fn check_link_path(link: &std::path::Path) -> anyhow::Result<()> {
    match std::fs::symlink_metadata(link) {
        Ok(meta) if !meta.file_type().is_symlink() => {
            let kind = if meta.is_dir() {
                "a directory"
            } else if meta.is_file() {
                "a regular file"
            } else {
                "a file that is not a symlink"
            };
            Err(usage(format!(
                "--link {}: {kind} is there (left untouched); remove it or pick another path",
                link.display()
            )))
        }
        _ => Ok(()),
    }
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
