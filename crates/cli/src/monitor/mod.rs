//! `robobus monitor`: a live terminal dashboard of a WHJ bus or a wCK port.
//!
//! Sources ([`Source`]):
//!
//! - `--bus BUS --joints 1-7`: WHJ joints, read-only: the monitor is one subscriber of the
//!   station's one sampling of the bus ([`Station::telemetry`]) of the request
//!   `whj.sample` on a station holding that bus: each sample is a status query (position,
//!   current, enable, error bits) and a speed register read per joint; with `--broadcast`,
//!   one broadcast status frame (0x7F) for all joints (1..=7).
//! - `--port PORT --servos 0-15`: wCK servos (a serial device, `COMn` or
//!   `socket://HOST:PORT`), read-only, the stream of `wck.sample`: a status read
//!   (position, load) per servo; the speed is the position's derivative.
//! - `--robot FILE.toml`: every joint of a robot file, by name, in the file's order, as
//!   joint angles (the file's `offset`, `direction` and wCK `centre` applied) in degrees
//!   and deg/s: the stream of `robot.sample` on a station opened from the file. The
//!   file's buses are only read, without a [`robobus::robot::Robot`]: nothing is enabled,
//!   and ending the monitor neither disables an arm nor releases a servo.
//! - `--sim`: the built-in simulated WHJ arm (joints 1..=7, in-process), which the monitor
//!   itself drives along a slow sine through the cyclic loop, so there is something to
//!   watch without hardware; the values are the loop's feedback.
//!
//! A stream keeps its own rate: a dashboard that falls behind loses its oldest samples
//! (shown as "not shown", and as `lost` in JSON lines), never slows the bus. A sample's
//! time is when its read completed.
//!
//! On a terminal it draws a table (position, speed, current / load, enable, errors) and a
//! scrolling plot of the positions with ratatui; `q`, `Esc` or Ctrl-C quit and the terminal
//! is restored. Without a terminal it prints one line per second instead; with `--json`,
//! one JSON object per sample (JSON lines, never the dashboard). `--record FILE` writes
//! every sample as CSV (the format `robobus plot` reads), JSON lines or MCAP (with
//! `sensor_msgs/msg/JointState`); `--duration` ends the run by itself. The rows, their staleness and both formats are the library's
//! [`robobus::record`]; this module only waits, draws and prints.

use robobus::catalogue::telemetry::RecvError;
use robobus::catalogue::telemetry::Subscription;
use robobus::catalogue::{self, Delivery, Request};
use robobus::ops::{IdList, ListId};
use robobus::station::{self, Station, StationConfig};
use std::io::IsTerminal as _;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::Context as _;
use robobus::record::{RecordFormat, Recorder, SampleTable};
use robobus::station::sampler::{bus_description, monitored_joints};
use robobus::whj::JointBusConfig;
use robobus_wck::{BaudRate, ServoId};
use robobus_whj::JointId;

use crate::Global;
use crate::exit::{Interrupted, usage};

/// Seconds of history in the scrolling plot.
const WINDOW_S: f64 = 10.0;

/// Options of `robobus monitor`.
#[derive(Debug, clap::Args)]
#[command(after_help = crate::plot::FORMAT_HELP)]
pub(crate) struct Args {
    /// A WHJ bus: `udp`, `udp:GROUP:PORT`, a SocketCAN interface, `slcan:PORT` or
    /// `fdcanusb:PORT` (with --joints).
    #[arg(long, value_name = "BUS", conflicts_with_all = ["port", "sim", "robot"])]
    bus: Option<String>,
    /// WHJ joint IDs to watch, e.g. `1-7` or `1,3`.
    #[arg(long, default_value = "1-7", value_parser = parse_ids_1_30)]
    joints: Ids,
    /// With --bus: sample joints 1..=7 with one broadcast status frame (0x7F) instead of
    /// two requests per joint.
    #[arg(long, requires = "bus")]
    broadcast: bool,
    /// A wCK port (with --servos): a serial device, `COMn`, or `socket://HOST:PORT`.
    #[arg(
        long,
        value_name = "PORT",
        value_parser = crate::wck::parse_port::<PathBuf>,
        conflicts_with_all = ["sim", "robot"]
    )]
    port: Option<PathBuf>,
    /// wCK servo IDs to watch, e.g. `0-15`.
    #[arg(long, default_value = "0-15", value_parser = parse_ids_0_30)]
    servos: Ids,
    /// wCK baud rate (bit/s).
    #[arg(long, default_value_t = 115_200)]
    baud: u32,
    /// Extra time to wait for each wCK reply beyond its modelled wire time, in ms
    /// (default 10, plus a USB adapter's latency timer when it can be read).
    #[arg(long, value_name = "MS", value_parser = crate::wck::parse_margin)]
    reply_margin: Option<Duration>,
    /// Every joint of a robot file (the TOML `robobus::robot` reads), as joint angles;
    /// its buses are only read: nothing is enabled or released.
    #[arg(long, value_name = "FILE.toml", conflicts_with = "sim")]
    robot: Option<PathBuf>,
    /// Watch the built-in simulated WHJ arm (7 joints, in-process), moved along a slow
    /// sine by the monitor itself.
    #[arg(long)]
    sim: bool,
    /// Samples per second, 1..=200.
    #[arg(long, default_value_t = 20.0, value_parser = parse_rate)]
    rate_hz: f64,
    /// Stop after this many seconds (default: until q / Ctrl-C).
    #[arg(long, value_parser = parse_duration)]
    duration: Option<f64>,
    /// Write every sample to FILE, in the format its name ends with: .csv (the format
    /// `robobus plot` reads), .jsonl (one JSON object per sample, as --json prints) or
    /// .mcap (the samples and `sensor_msgs/msg/JointState` on one time base, for Foxglove
    /// and the ROS 2 tools; `robobus plot` reads it too).
    #[arg(long, value_name = "FILE")]
    record: Option<PathBuf>,
    /// With --bus or --port: record every frame / byte on the bus to FILE (a candump log
    /// for WHJ, a timestamped hex log for wCK); `robobus replay FILE` decodes it. An
    /// existing FILE is not overwritten.
    #[arg(long, value_name = "FILE", conflicts_with_all = ["sim", "robot"])]
    capture: Option<PathBuf>,
}

/// A list of IDs.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct Ids(Vec<u8>);

/// The IDs of an ID list, ascending ([`IdList`]: the one ID-list parser).
fn raw_ids<T: ListId>(s: &str) -> Result<Ids, String> {
    let ids: IdList<T> = s.parse()?;
    let mut raw: Vec<u8> = ids
        .as_slice()
        .iter()
        .filter_map(|id| u8::try_from(id.raw()).ok())
        .collect();
    raw.sort_unstable();
    Ok(Ids(raw))
}
fn parse_ids_1_30(s: &str) -> Result<Ids, String> {
    raw_ids::<robobus_whj::JointId>(s)
}
fn parse_ids_0_30(s: &str) -> Result<Ids, String> {
    raw_ids::<robobus_wck::ServoId>(s)
}
fn parse_number(s: &str, what: &str, lo: f64, hi: f64) -> Result<f64, String> {
    let v: f64 = s
        .trim()
        .parse()
        .map_err(|_| format!("`{s}` is not a number"))?;
    if v.is_finite() && (lo..=hi).contains(&v) {
        Ok(v)
    } else {
        Err(format!("{what} {s} is out of range {lo}..={hi}"))
    }
}
fn parse_rate(s: &str) -> Result<f64, String> {
    parse_number(s, "rate (Hz)", 1.0, 200.0)
}
fn parse_duration(s: &str) -> Result<f64, String> {
    parse_number(s, "duration (s)", 0.1, 86_400.0)
}

/// Where samples come from: a station's telemetry stream (WHJ `whj.sample`, wCK
/// `wck.sample`, a robot file's `robot.sample`), or the simulated arm the monitor drives
/// and samples itself on its own clock.
enum Source {
    Stream(Stream),
    Sim(robobus::robot::simulated::SimArm),
}

/// The monitor as a subscriber of the station's sampling of the bus
/// ([`Station::telemetry`], as every reader of a bus is) on a station that holds only the
/// watched buses: each delivery fills the library's sample table ([`SampleTable::take`]).
struct Stream {
    sub: Subscription,
    station: Option<Arc<Station>>,
}

/// Samples a subscriber may fall behind by before it loses the oldest (the dashboard
/// draws far faster than the bus samples, so only a stalled terminal loses any).
const QUEUE: usize = 256;

impl Stream {
    /// A subscription to the sampling of `request` on `station` (it starts at once; the
    /// samples taken before the dashboard draws wait in its queue).
    fn new(station: Station, request: Request, rate_hz: f64) -> anyhow::Result<Self> {
        let station = Arc::new(station);
        let sub = station.telemetry(request, rate_hz, QUEUE)?;
        Ok(Self {
            sub,
            station: Some(station),
        })
    }
}

impl Drop for Stream {
    fn drop(&mut self) {
        // Stops the sampling (its read under way completes: the last subscriber's close
        // joins it), then closes the station leaving every device as it was: the monitor
        // only reads.
        self.sub.close();
        if let Some(station) = self.station.take().and_then(|s| Arc::try_unwrap(s).ok()) {
            station.leave();
        }
    }
}

/// What waiting for a stream's next sample gave.
enum Waited {
    Sample(Delivery),
    /// A quit key, the terminal hung up, the duration is over, the run was stopped or
    /// the stream ended.
    End,
}

/// How often a wait for a stream's sample looks at the keys.
const KEY_SLICE: Duration = Duration::from_millis(50);

/// Takes the next sample into `d` (a stream's: waiting for it, reading keys meanwhile);
/// `false` when the run ends instead (a quit key, the duration, a stop), the link's error
/// when the bus itself failed.
fn take_sample(
    src: &mut Source,
    d: &mut Dashboard,
    start: Instant,
    stop: &robobus::ops::StopToken,
    keys: Option<&std::sync::mpsc::Receiver<ratatui::crossterm::event::KeyEvent>>,
    end: Option<Instant>,
) -> Result<bool, String> {
    match src {
        Source::Stream(s) => {
            let Waited::Sample(delivery) = wait_stream(s, stop, keys, end) else {
                return Ok(false);
            };
            // The time its read completed, not the time it is shown.
            let t = start.elapsed().saturating_sub(delivery.sample.age());
            d.table.take(&delivery, t.as_secs_f64())?;
        }
        Source::Sim(arm) => {
            let t = start.elapsed().as_secs_f64();
            d.table.take_cycle(arm.sample().as_ref(), t);
        }
    }
    Ok(true)
}

/// Waits until `next`, the next sample's slot, reading keys meanwhile (at least once per
/// sample); whether the user quit.
fn wait_slot(
    next: Instant,
    stop: &robobus::ops::StopToken,
    keys: Option<&std::sync::mpsc::Receiver<ratatui::crossterm::event::KeyEvent>>,
) -> bool {
    loop {
        let now = Instant::now();
        if keys.is_some() {
            // A closed terminal (a killed tmux, a dropped SSH session) reads as end of
            // file forever (crossterm then spins inside its reader thread): stop as if the
            // user had quit (the hang-up signal also sets `stop`).
            if stop.is_stopped() || terminal_gone() {
                return true;
            }
            let wait = next.saturating_duration_since(now).min(KEY_SLICE);
            if quit_key(keys, wait) {
                return true;
            }
        } else if now < next {
            std::thread::sleep(next - now);
        }
        if Instant::now() >= next {
            return false;
        }
    }
}

/// Waits for `stream`'s next sample, reading keys meanwhile, until `end`.
fn wait_stream(
    stream: &Stream,
    stop: &robobus::ops::StopToken,
    keys: Option<&std::sync::mpsc::Receiver<ratatui::crossterm::event::KeyEvent>>,
    end: Option<Instant>,
) -> Waited {
    loop {
        if stop.is_stopped() {
            return Waited::End;
        }
        if keys.is_some() && (terminal_gone() || quit_key(keys, Duration::ZERO)) {
            return Waited::End;
        }
        let now = Instant::now();
        if end.is_some_and(|e| now >= e) {
            return Waited::End;
        }
        let wait = end.map_or(KEY_SLICE, |e| (e - now).min(KEY_SLICE));
        match stream.sub.recv_timeout(wait) {
            Ok(d) => return Waited::Sample(d),
            Err(RecvError::Timeout) => {}
            Err(RecvError::Ended) => return Waited::End,
        }
    }
}

/// Restores the terminal when dropped (also on errors and panics in the loop).
struct TerminalGuard;

impl Drop for TerminalGuard {
    fn drop(&mut self) {
        ratatui::restore();
    }
}

/// Runs `robobus monitor`.
pub(crate) fn run(g: Global, args: &Args) -> anyhow::Result<()> {
    if g.dry_run {
        return Err(usage(
            "robobus monitor: --dry-run has nothing to print (it only reads)",
        ));
    }
    if let Some(r) = &args.record
        && RecordFormat::of_path(r).is_none()
    {
        return Err(usage(format!(
            "--record {}: the file name must end in .csv, .jsonl, .ndjson or .mcap",
            r.display()
        )));
    }
    let baud = BaudRate::from_bits_per_second(args.baud)
        .map_err(|e| usage(format!("--baud {}: {e}", args.baud)))?;
    let out = Output { json: g.json };
    if args.sim {
        return run_sim(args, out);
    }
    if let Some(path) = &args.robot {
        return run_robot(path, args, g.wait, out);
    }
    if let Some(bus) = &args.bus {
        let joints: Vec<JointId> = args
            .joints
            .0
            .iter()
            .filter_map(|&j| JointId::new(j).ok())
            .collect();
        if args.broadcast {
            robobus::ops::whj::reply_mask(&joints)
                .map_err(|e| usage(format!("--broadcast --joints: {e}")))?;
        }
        let jb = station::open_whj_with(bus, args.capture.as_deref(), whj_config(g.wait))?;
        let ids: Vec<u8> = joints.iter().map(|j| j.get()).collect();
        let d = dashboard(
            format!("WHJ bus {bus}"),
            "current mA",
            SampleTable::whj(&ids),
            args,
        );
        let mut station = Station::new();
        station.add_whj_at(bus.as_str(), jb);
        let request = Request::WhjSample(catalogue::whj::Sample {
            bus: None,
            joints: id_list(&ids),
            broadcast: args.broadcast,
        });
        let src = Stream::new(station, request, args.rate_hz)?;
        return watch(&mut Source::Stream(src), d, args, out);
    }
    if let Some(port) = &args.port {
        let name = port.display().to_string();
        let mut bus = station::open_wck_port(&name, baud, args.capture.as_deref())
            .with_context(|| format!("opening {name}"))?;
        if let Some(margin) = args.reply_margin {
            bus.config_mut().margin = margin;
        }
        bus.config_mut().wait = g.wait;
        let ids: Vec<ServoId> = args
            .servos
            .0
            .iter()
            .filter_map(|&s| ServoId::new(s).ok())
            .collect();
        let ids: Vec<u8> = ids.iter().map(|s| s.get()).collect();
        let d = dashboard(
            format!("wCK port {name} at {} bit/s", args.baud),
            "load",
            SampleTable::wck(&ids),
            args,
        );
        let mut station = Station::new();
        station.add_wck(name, bus);
        let request = Request::WckSample(catalogue::wck::Sample {
            bus: None,
            ids: id_list(&ids),
        });
        let src = Stream::new(station, request, args.rate_hz)?;
        return watch(&mut Source::Stream(src), d, args, out);
    }
    Err(usage(
        "robobus monitor: give --bus BUS (WHJ), --port PORT (wCK), --robot FILE.toml or \
         --sim (the built-in simulated arm)",
    ))
}

/// How samples are printed when there is no dashboard.
#[derive(Debug, Clone, Copy)]
struct Output {
    /// One JSON object per sample (and never the dashboard).
    json: bool,
}

/// The monitor's WHJ connect timeout: short, so a silent joint does not hold up the start
/// (it shows as `timeout`).
const WHJ_CONNECT_TIMEOUT: Duration = Duration::from_millis(300);

/// The WHJ client settings of the monitor (see [`WHJ_CONNECT_TIMEOUT`]).
fn whj_config(wait: robobus::WaitMode) -> JointBusConfig {
    JointBusConfig {
        wait,
        connect_timeout: WHJ_CONNECT_TIMEOUT,
        ..JointBusConfig::default()
    }
}

/// `monitor --robot FILE`: every joint of the file, read through the file's buses: one
/// subscriber of the `robot.sample` stream on a station opened from the file.
fn run_robot(
    path: &std::path::Path,
    args: &Args,
    wait: robobus::WaitMode,
    out: Output,
) -> anyhow::Result<()> {
    let station = Station::open(&StationConfig {
        robot: Some(path.to_path_buf()),
        wck_reply_margin: args.reply_margin,
        whj_connect_timeout: Some(WHJ_CONNECT_TIMEOUT),
        wait,
        ..StationConfig::default()
    })?;
    let config = station
        .robot()
        .context("the station opened from the robot file has no robot")?;
    let joints = monitored_joints(config);
    let buses: Vec<String> = config
        .buses
        .iter()
        .map(|(name, bus)| bus_description(name, bus))
        .collect();
    let effort_name = match (joints.iter().any(|j| !j.wck), joints.iter().any(|j| j.wck)) {
        (true, true) => "mA / load",
        (false, true) => "load",
        _ => "current mA",
    };
    let d = dashboard(
        format!(
            "{}: {} joints ({})",
            path.display(),
            joints.len(),
            buses.join("; ")
        ),
        effort_name,
        SampleTable::robot(joints.iter().map(|j| (j.name.as_str(), j.wck))),
        args,
    );
    let d = Dashboard {
        named_joints: true,
        ..d
    };
    let request = Request::RobotSample(catalogue::robot::Sample {});
    let src = Stream::new(station, request, args.rate_hz)?;
    watch(&mut Source::Stream(src), d, args, out)
}

fn dashboard(
    title: String,
    effort_name: &'static str,
    table: SampleTable,
    args: &Args,
) -> Dashboard {
    Dashboard {
        recording: args.record.as_ref().map(|p| p.display().to_string()),
        ..Dashboard::new(title, effort_name, table)
    }
}

fn run_sim(args: &Args, out: Output) -> anyhow::Result<()> {
    let joints: Vec<u8> = args.joints.0.clone();
    let ids: Vec<JointId> = joints
        .iter()
        .filter_map(|&j| JointId::new(j).ok())
        .collect();
    let arm = robobus::robot::simulated::SimArm::start(&ids)?;
    let d = dashboard(
        format!("simulated WHJ30 arm, joints {}", ids_text(&joints)),
        "current mA",
        SampleTable::whj(&joints).with_torque_constants(&arm.torque_constants()),
        args,
    );
    // Dropping the arm disables its joints and stops the simulator.
    watch(&mut Source::Sim(arm), d, args, out)
}

fn ids_text(ids: &[u8]) -> String {
    match (ids.first(), ids.last()) {
        (Some(a), Some(b)) if ids.len() > 1 && usize::from(b - a) + 1 == ids.len() => {
            format!("{a}-{b}")
        }
        _ => ids.iter().map(u8::to_string).collect::<Vec<_>>().join(","),
    }
}

/// Device IDs as a request's ID list.
fn id_list(ids: &[u8]) -> catalogue::args::Ids {
    catalogue::args::Ids::List(ids.iter().map(|&i| u32::from(i)).collect())
}

/// Whether the terminal on stdin has hung up (reads would only return end of file).
#[cfg(unix)]
fn terminal_gone() -> bool {
    use nix::poll::{PollFd, PollFlags, PollTimeout, poll};
    use std::os::fd::AsFd as _;
    let stdin = std::io::stdin();
    let mut fds = [PollFd::new(stdin.as_fd(), PollFlags::POLLIN)];
    matches!(poll(&mut fds, PollTimeout::ZERO), Ok(n) if n > 0)
        && fds[0].revents().is_some_and(|r| {
            r.intersects(PollFlags::POLLHUP | PollFlags::POLLERR | PollFlags::POLLNVAL)
        })
}

/// Whether the console on stdin has gone: never seen here, since Windows ends the
/// programs of a console that closes (after their Ctrl-C handler, which stops the monitor).
#[cfg(not(unix))]
const fn terminal_gone() -> bool {
    false
}

/// Key presses, read on their own thread: crossterm's reader can spin forever on a
/// terminal that hung up, and the sampling loop must keep its duration and its exits.
fn key_reader() -> std::sync::mpsc::Receiver<ratatui::crossterm::event::KeyEvent> {
    use ratatui::crossterm::event::{self, Event, KeyEventKind};
    let (tx, rx) = std::sync::mpsc::channel();
    let _ = std::thread::Builder::new()
        .name("monitor-keys".into())
        .spawn(move || {
            while let Ok(ev) = event::read() {
                if let Event::Key(k) = ev
                    && k.kind == KeyEventKind::Press
                    && tx.send(k).is_err()
                {
                    break;
                }
            }
        });
    rx
}

/// Waits up to `wait` for a key; whether it was one that quits (q, Esc, Ctrl-C).
fn quit_key(
    keys: Option<&std::sync::mpsc::Receiver<ratatui::crossterm::event::KeyEvent>>,
    wait: Duration,
) -> bool {
    use ratatui::crossterm::event::{KeyCode, KeyModifiers};
    use std::sync::mpsc::RecvTimeoutError;
    match keys.map(|k| k.recv_timeout(wait)) {
        Some(Ok(k)) => {
            let ctrl_c =
                k.code == KeyCode::Char('c') && k.modifiers.contains(KeyModifiers::CONTROL);
            matches!(k.code, KeyCode::Char('q') | KeyCode::Esc) || ctrl_c
        }
        Some(Err(RecvTimeoutError::Timeout)) => false,
        // The reader stopped (its terminal failed): just wait.
        Some(Err(RecvTimeoutError::Disconnected)) | None => {
            std::thread::sleep(wait);
            false
        }
    }
}

fn watch(src: &mut Source, mut d: Dashboard, args: &Args, out: Output) -> anyhow::Result<()> {
    let mut recorder = match &args.record {
        Some(p) => Some(Recorder::create(p, &d.title, &d.table)?),
        None => None,
    };
    let stop = crate::interrupt::stop_token();
    let tui = !out.json && std::io::stdout().is_terminal();
    let mut terminal = if tui {
        Some(ratatui::try_init().context("setting up the terminal")?)
    } else {
        None
    };
    let guard = if tui { Some(TerminalGuard) } else { None };
    let keys = tui.then(key_reader);
    let period = Duration::from_secs_f64(1.0 / args.rate_hz);
    let start = Instant::now();
    let end = args.duration.map(|s| start + Duration::from_secs_f64(s));
    let mut next = start;
    let mut last_line = -1.0f64;
    loop {
        if stop.is_stopped() || end.is_some_and(|e| Instant::now() >= e) {
            break;
        }
        match take_sample(src, &mut d, start, &stop, keys.as_ref(), end) {
            Ok(true) => {}
            Ok(false) => break,
            Err(e) => {
                return Err(anyhow::anyhow!(
                    "monitor stopped after {} sample(s): {e}",
                    d.table.samples.saturating_sub(1)
                ));
            }
        }
        d.push_history();
        if let Some(r) = &mut recorder {
            r.record(&d.table)?;
        }
        if let Some(term) = &mut terminal {
            term.draw(|f| render(f, &d))?;
        } else if out.json {
            crate::output::print(&format!("{}\n", d.table.json_line()))?;
        } else if d.table.t_s - last_line >= 1.0 {
            last_line = d.table.t_s;
            crate::output::print(&format!("{}\n", d.plain_line()))?;
        }
        if matches!(src, Source::Stream(_)) {
            // The stream keeps its own rate; the next wait reads the keys.
            continue;
        }
        next += period;
        if wait_slot(next, &stop, keys.as_ref()) {
            break;
        }
        if Instant::now() > next + period * 10 {
            next = Instant::now();
        }
    }
    drop(terminal);
    drop(guard);
    if let Some(r) = recorder {
        r.finish()?;
    }
    if let Some(p) = &args.record {
        eprintln!(
            "robobus monitor: {} samples recorded to {}",
            d.table.samples,
            p.display()
        );
    }
    if stop.is_stopped() {
        return Err(anyhow::Error::new(Interrupted));
    }
    silent(&d)
}

/// Exit code 3 when a device stayed silent: it never answered, or its last sample was
/// missing (its values shown last were stale).
fn silent(d: &Dashboard) -> anyhow::Result<()> {
    let gone = d.table.silent();
    if gone.is_empty() {
        return Ok(());
    }
    Err(anyhow::Error::new(crate::exit::Timeout(format!(
        "silent at the end: {}",
        gone.join(", ")
    ))))
}

mod dashboard;

pub(crate) use dashboard::{Dashboard, render};

#[cfg(test)]
mod tests;
