//! `robobus demo`: the built-in simulated robot, driven through the client library.
//!
//! Starts, in this process and on the wall clock:
//!
//! - a wCK humanoid: 16 simulated wCK-1108 servos (IDs 0..=15) on a 115200 bit/s bus, the
//!   bus `robobus sim wck` serves, reached through an in-process `SimLink` (its replies do
//!   not depend on how loaded the machine is);
//! - a 7-joint WHJ30 arm (IDs 1..=7) on an in-process CAN FD bus, served on its own thread.
//!
//! Then it does what a first session with real hardware does, through [`robobus::wck`]
//! and [`robobus::whj`] (the same code paths as `robobus wck` / `robobus whj`): scans the
//! wCK bus, plays three keyframes as synchronized moves while polling every servo, connects
//! the WHJ joints (IAP release, identify), enables them in position mode and streams a
//! 500 Hz sine trajectory through the cyclic loop. It ends with a summary: what moved, how
//! well it tracked, and the bus figures (cycles, deadline misses, latency percentiles,
//! wire utilisation against the limit the protocol timing models give).

use std::f64::consts::TAU;
use std::fmt::Write as _;
use std::io::IsTerminal as _;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use anyhow::{Context as _, anyhow};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use robobus::wck::{ScanOptions, WckBus};
use robobus::whj::{CyclicConfig, CyclicStats, JointBus, MotionLimits, Percentiles};
use robobus_link::{ByteLink, MemoryBus};
use robobus_wck::{BaudRate, Position as WckPosition, ServoId, TorqueLevel};
use robobus_whj::timing::{BitRates, frame_duration};
use robobus_whj::units::Position;
use robobus_whj::{JointId, Reply, Request, WorkMode};
use serde_json::json;

use crate::Global;
use crate::exit::{Interrupted, usage};
use crate::plot::Recording;

/// wCK servos of the humanoid (IDs 0..SERVOS).
const SERVOS: u8 = 16;
/// WHJ joints of the arm (IDs 1..=JOINTS).
const JOINTS: u8 = 7;
/// The cyclic loop's period: 500 Hz.
const PERIOD: Duration = Duration::from_millis(2);
/// Sine amplitude (degrees) and frequency (Hz) of the arm trajectory.
const AMPLITUDE_DEG: f64 = 20.0;
const FREQUENCY_HZ: f64 = 0.5;
/// Degrees per wCK position step.
const WCK_DEG_PER_STEP: f64 = 1.055;

/// The keyframes: name and one position (0..=254) per servo.
const KEYFRAMES: [(&str, [u8; SERVOS as usize]); 3] = [
    ("stand", [127; SERVOS as usize]),
    (
        "arms up",
        [
            200, 54, 190, 64, 127, 127, 127, 127, 127, 127, 127, 127, 127, 127, 127, 127,
        ],
    ),
    (
        "crouch",
        [
            127, 127, 127, 127, 90, 164, 80, 174, 100, 154, 110, 144, 127, 127, 127, 127,
        ],
    ),
];

/// Options of `robobus demo`.
#[derive(Debug, clap::Args)]
pub(crate) struct Args {
    /// How long the WHJ arm follows its sine trajectory, seconds (0.5..=60).
    #[arg(long, default_value_t = 4.0, value_parser = parse_seconds)]
    seconds: f64,
    /// Also plot the run (wCK servo angles and WHJ joint angles over time) to this file;
    /// the format follows the extension: .png or .svg.
    #[arg(long, value_name = "FILE")]
    plot: Option<PathBuf>,
}

fn parse_seconds(s: &str) -> Result<f64, String> {
    let v: f64 = s
        .trim()
        .parse()
        .map_err(|_| format!("`{s}` is not a number"))?;
    if v.is_finite() && (0.5..=60.0).contains(&v) {
        Ok(v)
    } else {
        Err(format!("--seconds {s} is out of range 0.5..=60"))
    }
}

/// Progress output: indicatif bars on a terminal, plain lines on stderr otherwise.
struct Progress {
    fancy: bool,
}

impl Progress {
    fn new() -> Self {
        Self {
            fancy: std::io::stderr().is_terminal(),
        }
    }

    fn bar(&self, len: u64, what: &str) -> ProgressBar {
        if !self.fancy {
            eprintln!("demo: {what}");
            return ProgressBar::hidden();
        }
        let pb = ProgressBar::with_draw_target(Some(len), ProgressDrawTarget::stderr());
        if let Ok(style) = ProgressStyle::with_template("{prefix:>10} [{bar:30}] {pos}/{len} {msg}")
        {
            pb.set_style(style.progress_chars("=> "));
        }
        pb.set_prefix(what.to_owned());
        pb
    }

    fn line(&self, text: &str) {
        if !self.fancy {
            eprintln!("demo: {text}");
        }
    }
}

/// One keyframe's outcome.
struct Pose {
    name: &'static str,
    settled: Option<Duration>,
    worst_steps: u8,
}

/// What the wCK part did.
struct WckSummary {
    found: Vec<u8>,
    scan: Duration,
    poses: Vec<Pose>,
    polls: u64,
    stats: robobus::wck::WckStats,
    bytes_out: u64,
    bytes_in: u64,
    elapsed: Duration,
}

/// One joint's tracking.
struct Tracking {
    id: u8,
    model: String,
    firmware: String,
    rms_deg: f64,
    max_deg: f64,
    samples: u64,
    final_error: String,
    /// No error bit latched at the end.
    error_free: bool,
}

/// What the WHJ part did.
struct WhjSummary {
    joints: Vec<Tracking>,
    stats: CyclicStats,
    seconds: f64,
    cycle_wire: Duration,
    sim_received: u64,
    sim_sent: u64,
}

/// Samples for `--plot`: (time since the demo's start, column, value).
#[derive(Default)]
struct Samples(Vec<(f64, usize, f64)>);

/// Runs `robobus demo`.
pub(crate) fn run(g: Global, args: &Args) -> anyhow::Result<()> {
    if let Some(p) = &args.plot {
        let ext = p
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase);
        if !matches!(ext.as_deref(), Some("png" | "svg")) {
            return Err(usage(format!(
                "--plot {}: the file name must end in .png or .svg",
                p.display()
            )));
        }
    }
    if g.dry_run {
        return Err(usage(
            "robobus demo: --dry-run has nothing to print (the demo talks to its own \
             in-process simulators)",
        ));
    }
    let stop = Arc::new(AtomicBool::new(false));
    let flag = Arc::clone(&stop);
    // Another handler may exist already (tests in one process); then Ctrl-C kills the demo.
    let _ = ctrlc::set_handler(move || flag.store(true, Ordering::Relaxed));

    let wall = Instant::now();
    let progress = Progress::new();
    let mut samples = Samples::default();
    let wck = humanoid(&progress, &stop, wall, &mut samples)?;
    let whj = arm(&progress, &stop, args.seconds, wall, &mut samples)?;
    let elapsed = wall.elapsed();

    if let Some(path) = &args.plot {
        let rec = samples.recording();
        crate::plot::write_image(&rec, path, "robobus demo: simulated robot")?;
        progress.line(&format!("wrote {}", path.display()));
    }
    if g.json {
        crate::output::print_json(&summary_json(&wck, &whj, elapsed, args.plot.as_ref()))
    } else {
        crate::output::print(&summary_text(&wck, &whj, elapsed, args.plot.as_ref()))
    }
}

fn check_stop(stop: &AtomicBool) -> anyhow::Result<()> {
    if stop.load(Ordering::Relaxed) {
        Err(anyhow::Error::new(Interrupted))
    } else {
        Ok(())
    }
}

fn humanoid(
    progress: &Progress,
    stop: &AtomicBool,
    wall: Instant,
    samples: &mut Samples,
) -> anyhow::Result<WckSummary> {
    use robobus_sim::wck::{Bus, BusConfig, Model, SimLink};

    let (link, sim) = SimLink::new(Bus::with_servos(
        BusConfig::default(),
        Model::W1108,
        0..SERVOS,
    ));
    // The modules are deaf for 65 ms after power-up.
    std::thread::sleep(
        (robobus_wck::timing::POWER_UP_DEAF + Duration::from_millis(5)).saturating_sub(sim.now()),
    );
    let mut bus =
        WckBus::new(link, BaudRate::B115200)?.with_device_name("simulated humanoid (in-process)");
    let started = Instant::now();
    let result = humanoid_run(&mut bus, progress, stop, wall, samples);
    let served = sim.with_bus(|b| b.stats());
    let (found, scan, poses, polls) = result?;
    Ok(WckSummary {
        found,
        scan,
        poses,
        polls,
        stats: bus.stats(),
        bytes_out: served.host_bytes,
        bytes_in: served.received_bytes,
        elapsed: started.elapsed(),
    })
}

type HumanoidRun = (Vec<u8>, Duration, Vec<Pose>, u64);

fn humanoid_run<L: ByteLink>(
    bus: &mut WckBus<L>,
    progress: &Progress,
    stop: &AtomicBool,
    wall: Instant,
    samples: &mut Samples,
) -> anyhow::Result<HumanoidRun> {
    let options = ScanOptions {
        check_duplicates: false,
        probes: 3,
        ..ScanOptions::at(BaudRate::B115200)
    };
    let pb = progress.bar(31, "wCK scan");
    let t0 = Instant::now();
    let report = bus.scan(&options, |p| {
        pb.set_position(p.done as u64);
        pb.set_message(format!("{} found", p.found));
    })?;
    pb.finish_and_clear();
    let scan = t0.elapsed();
    let mut found: Vec<u8> = report.found.iter().map(|f| f.id.get()).collect();
    // A second look at any missing ID (with the client's retries), as a user rescans: on
    // a busy machine a module's answer can miss the scan's short deadline.
    for raw in 0..SERVOS {
        if !found.contains(&raw) && bus.servo(ServoId::new(raw)?).status().is_ok() {
            found.push(raw);
        }
    }
    found.sort_unstable();
    progress.line(&format!(
        "wCK scan found {} servos in {:.0} ms",
        found.len(),
        scan.as_secs_f64() * 1e3
    ));
    if found.len() != usize::from(SERVOS) {
        return Err(anyhow!(
            "the wCK scan found {} servos ({found:?}); the simulated humanoid has {SERVOS}",
            found.len()
        ));
    }
    check_stop(stop)?;

    let torque = TorqueLevel::new(0)?;
    let mut poses = Vec::new();
    let mut polls = 0u64;
    let pb = progress.bar(KEYFRAMES.len() as u64, "keyframes");
    for (name, pose) in KEYFRAMES {
        pb.set_message(name);
        progress.line(&format!("wCK keyframe `{name}`"));
        let positions = pose
            .iter()
            .map(|&p| WckPosition::new(p))
            .collect::<Result<Vec<_>, _>>()?;
        bus.sync_move(torque, &positions)?;
        let start = Instant::now();
        let mut settled = None;
        let mut worst = u8::MAX;
        // Poll every servo until all stand within one step, for at most 1.2 s.
        while start.elapsed() < Duration::from_millis(1200) {
            check_stop(stop)?;
            worst = 0;
            let t = wall.elapsed().as_secs_f64();
            for (raw, target) in (0..SERVOS).zip(pose) {
                let at = bus.servo(ServoId::new(raw)?).status()?.position.get();
                polls += 1;
                worst = worst.max(at.abs_diff(target));
                if let Some(col) = wck_column(raw) {
                    samples.push(t, col, (f64::from(at) - 127.0) * WCK_DEG_PER_STEP);
                }
            }
            if worst <= 1 {
                settled = Some(start.elapsed());
                break;
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        poses.push(Pose {
            name,
            settled,
            worst_steps: worst,
        });
        pb.inc(1);
    }
    pb.finish_and_clear();
    Ok((found, scan, poses, polls))
}

/// The plotted wCK servos (the ones the keyframes move most) and their columns.
const WCK_PLOTTED: [u8; 4] = [0, 2, 4, 6];

fn wck_column(id: u8) -> Option<usize> {
    WCK_PLOTTED.iter().position(|&p| p == id)
}

fn sine_target(i: usize, t: f64) -> f64 {
    #[allow(clippy::cast_precision_loss)] // i < 7
    let phase = i as f64 * 0.4;
    AMPLITUDE_DEG * (TAU * FREQUENCY_HZ * t + phase).sin() - AMPLITUDE_DEG * phase.sin()
}

fn arm(
    progress: &Progress,
    stop: &Arc<AtomicBool>,
    seconds: f64,
    wall: Instant,
    samples: &mut Samples,
) -> anyhow::Result<WhjSummary> {
    use robobus_sim::whj::{WhjBus, WhjModel};

    let wire = MemoryBus::new();
    let mut sim_end = wire.endpoint();
    let sim_stop = Arc::new(AtomicBool::new(false));
    let flag = Arc::clone(&sim_stop);
    let sim = std::thread::Builder::new()
        .name("demo-whj-sim".into())
        .spawn(move || {
            let mut sim = WhjBus::chain(1..=JOINTS, WhjModel::Whj30, 7);
            robobus_sim::whj::serve(&mut sim, &mut sim_end, &flag)
        })
        .context("starting the simulated WHJ arm")?;
    let bus = JointBus::open_with(wire.endpoint(), robobus::whj::JointBusConfig::simulated())?;
    let result = arm_run(&bus, progress, stop, seconds, wall, samples);
    // Safe state whatever happened: every joint disabled.
    for id in 1..=JOINTS {
        if let Ok(j) = JointId::new(id) {
            let _ = bus.joint_unchecked(j).disable();
        }
    }
    drop(bus);
    sim_stop.store(true, Ordering::Relaxed);
    let served = sim
        .join()
        .map_err(|_| anyhow!("the simulated WHJ arm's thread panicked"))?
        .context("the simulated WHJ arm")?;
    let mut summary = result?;
    summary.sim_received = served.received;
    summary.sim_sent = served.sent;
    Ok(summary)
}

#[allow(clippy::too_many_lines)] // one straight sequence: connect, loop, figures
fn arm_run(
    bus: &JointBus,
    progress: &Progress,
    stop: &AtomicBool,
    seconds: f64,
    wall: Instant,
    samples: &mut Samples,
) -> anyhow::Result<WhjSummary> {
    let ids: Vec<JointId> = (1..=JOINTS).map(JointId::new).collect::<Result<_, _>>()?;
    let pb = progress.bar(u64::from(JOINTS), "WHJ connect");
    let mut tracking = Vec::new();
    let mut cycle_wire = Duration::ZERO;
    for &id in &ids {
        check_stop(stop)?;
        let joint = bus.joint(id)?;
        let identity = joint.identity()?;
        joint.disable()?;
        joint.set_mode(WorkMode::Position)?;
        joint.enable()?;
        // One servo frame at the present position: its request and feedback frames are
        // what the loop sends each cycle, so their wire time is the cycle's cost.
        let here = joint.status()?.position;
        let request = Request::PositionServo {
            joint: id,
            target: here,
        };
        let feedback = joint.command_position(here)?;
        let reply = Reply::ServoFeedback {
            joint: id,
            feedback,
        };
        cycle_wire += frame_duration(&request.to_frame(), BitRates::WHJ)
            + frame_duration(&reply.to_frame(), BitRates::WHJ);
        tracking.push(Tracking {
            id: id.get(),
            model: identity.model.name().to_owned(),
            firmware: identity.firmware.to_string(),
            rms_deg: 0.0,
            max_deg: 0.0,
            samples: 0,
            final_error: String::new(),
            error_free: false,
        });
        pb.inc(1);
    }
    pb.finish_and_clear();
    progress.line(&format!(
        "WHJ: {JOINTS} joints connected, position mode, enabled"
    ));

    let cyc = bus.cyclic(CyclicConfig {
        smooth: Some(MotionLimits {
            max_speed_deg_s: 120.0,
            max_accel_deg_s2: 800.0,
            ..MotionLimits::default()
        }),
        ..CyclicConfig::position(ids.clone(), PERIOD)
    })?;
    let first = cyc
        .next_report(Duration::from_secs(1))
        .ok_or_else(|| anyhow!("the cyclic loop produced no cycle within 1 s"))?;
    let start = first.scheduled;
    #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)] // <= 60 * 500
    let total = (seconds / PERIOD.as_secs_f64()).round() as u64;
    let pb = progress.bar(total, "500 Hz sine");
    progress.line(&format!("WHJ: {seconds} s sine trajectory at 500 Hz"));
    let mut err_sq = vec![0.0f64; ids.len()];
    let mut previous: Option<Vec<i32>> = None;
    let mut interrupted = false;
    loop {
        if stop.load(Ordering::Relaxed) {
            interrupted = true;
            break;
        }
        let Some(report) = cyc.next_report(Duration::from_millis(100)) else {
            continue;
        };
        let t = report.scheduled.duration_since(start).as_secs_f64();
        if t > seconds {
            break;
        }
        if report.cycle % 50 == 0 {
            pb.set_position(report.cycle.min(total));
        }
        // Feedback is the position when this cycle's command arrived: compare it with
        // the set-point sent the cycle before.
        if let Some(prev) = &previous {
            for (i, (fb, cmd)) in report.feedback.iter().zip(prev).enumerate() {
                if let (Some(fb), Some(tr)) = (fb, tracking.get_mut(i)) {
                    let e = (fb.position.degrees() - Position(*cmd).degrees()).abs();
                    if let Some(sq) = err_sq.get_mut(i) {
                        *sq += e * e;
                    }
                    tr.max_deg = tr.max_deg.max(e);
                    tr.samples += 1;
                }
            }
        }
        if report.cycle % 10 == 0 {
            let now = wall.elapsed().as_secs_f64();
            for (i, fb) in report.feedback.iter().enumerate() {
                if let Some(fb) = fb {
                    samples.push(now, WCK_PLOTTED.len() + i, fb.position.degrees());
                }
            }
        }
        previous = Some(report.commanded.clone());
        let targets = (0..ids.len())
            .map(|i| Position::from_degrees(sine_target(i, t)))
            .collect::<Result<Vec<_>, _>>()?;
        cyc.set_positions(&targets)?;
    }
    let stats = cyc.stop();
    pb.finish_and_clear();
    if interrupted {
        return Err(anyhow::Error::new(Interrupted));
    }
    for ((tr, sq), &id) in tracking.iter_mut().zip(&err_sq).zip(&ids) {
        #[allow(clippy::cast_precision_loss)]
        let n = tr.samples.max(1) as f64;
        tr.rms_deg = (sq / n).sqrt();
        let code = bus.joint_unchecked(id).error_code()?;
        tr.final_error = code.to_string();
        tr.error_free = code.is_empty();
    }
    Ok(WhjSummary {
        joints: tracking,
        stats,
        seconds,
        cycle_wire,
        sim_received: 0,
        sim_sent: 0,
    })
}

impl Samples {
    fn push(&mut self, t: f64, col: usize, v: f64) {
        self.0.push((t, col, v));
    }

    /// One row per distinct time, columns: the plotted wCK servos, then the WHJ joints.
    fn recording(&self) -> Recording {
        let columns = WCK_PLOTTED.len() + usize::from(JOINTS);
        let mut names: Vec<String> = WCK_PLOTTED
            .iter()
            .map(|id| format!("wck{id}_deg"))
            .collect();
        names.extend((1..=JOINTS).map(|j| format!("whj{j}_deg")));
        let mut time = Vec::new();
        let mut signals: Vec<Vec<Option<f64>>> = vec![Vec::new(); columns];
        for &(t, col, v) in &self.0 {
            if time.last() != Some(&t) {
                time.push(t);
                for s in &mut signals {
                    s.push(None);
                }
            }
            if let Some(cell) = signals.get_mut(col).and_then(|s| s.last_mut()) {
                *cell = Some(v);
            }
        }
        Recording {
            time_name: "t_s".into(),
            time,
            signals: names.into_iter().zip(signals).collect(),
        }
    }
}

fn us(d: Duration) -> f64 {
    d.as_secs_f64() * 1e6
}

fn percentiles_json(p: &Percentiles) -> serde_json::Value {
    json!({
        "samples": p.samples,
        "p50": us(p.p50),
        "p90": us(p.p90),
        "p99": us(p.p99),
        "max": us(p.max),
    })
}

/// The wCK wire time of everything sent and received, as a share of the run.
fn wck_busy(w: &WckSummary) -> f64 {
    let bytes = usize::try_from(w.bytes_in + w.bytes_out).unwrap_or(usize::MAX);
    let wire = robobus_wck::timing::wire_time(bytes, BaudRate::B115200);
    wire.as_secs_f64() / w.elapsed.as_secs_f64().max(1e-9)
}

fn worst_tracking(h: &WhjSummary) -> (f64, f64) {
    h.joints.iter().fold((0.0f64, 0.0f64), |(r, m), t| {
        (r.max(t.rms_deg), m.max(t.max_deg))
    })
}

fn summary_json(
    w: &WckSummary,
    h: &WhjSummary,
    elapsed: Duration,
    plot: Option<&PathBuf>,
) -> serde_json::Value {
    let (rms, max) = worst_tracking(h);
    let period = PERIOD.as_secs_f64();
    let mut errors: Vec<String> = Vec::new();
    for p in &w.poses {
        if p.settled.is_none() {
            errors.push(format!(
                "wCK pose `{}` still {} steps off",
                p.name, p.worst_steps
            ));
        }
    }
    for t in &h.joints {
        if !t.error_free {
            errors.push(format!("WHJ joint {} error {}", t.id, t.final_error));
        }
    }
    json!({
        "wall_s": elapsed.as_secs_f64(),
        "wck": {
            "servos_found": w.found.len(),
            "ids": w.found,
            "baud": 115_200,
            "scan_ms": w.scan.as_secs_f64() * 1e3,
            "poses": w.poses.iter().map(|p| json!({
                "name": p.name,
                "settled_ms": p.settled.map(|d| d.as_secs_f64() * 1e3),
                "worst_error_steps": p.worst_steps,
            })).collect::<Vec<_>>(),
            "status_polls": w.polls,
            "transactions": w.stats.attempts,
            "retries": w.stats.retries,
            "timeouts": w.stats.timeouts,
            "bad_replies": w.stats.bad_replies,
            "bytes_out": w.bytes_out,
            "bytes_in": w.bytes_in,
            "wire_utilisation": wck_busy(w),
            "status_poll_limit_hz": robobus_wck::timing::polling_rate_hz(usize::from(SERVOS), BaudRate::B115200),
        },
        "whj": {
            "joints": h.joints.len(),
            "identities": h.joints.iter().map(|t| json!({
                "id": t.id, "model": t.model, "firmware": t.firmware,
            })).collect::<Vec<_>>(),
            "seconds": h.seconds,
            "rate_hz": 1.0 / period,
            "cycles": h.stats.cycles,
            "complete": h.stats.complete,
            "deadline_misses": h.stats.deadline_misses,
            "missing_replies": h.stats.missing_replies,
            "late_replies": h.stats.late_replies,
            "overruns": h.stats.overruns,
            "send_errors": h.stats.send_errors,
            "round_trip_us": percentiles_json(&h.stats.round_trip),
            "start_lateness_us": percentiles_json(&h.stats.start_lateness),
            "tracking": h.joints.iter().map(|t| json!({
                "joint": t.id, "rms_deg": t.rms_deg, "max_deg": t.max_deg,
                "samples": t.samples, "error": t.final_error, "error_free": t.error_free,
            })).collect::<Vec<_>>(),
            "tracking_rms_deg": rms,
            "tracking_max_deg": max,
            "cycle_wire_us": us(h.cycle_wire),
            "wire_utilisation": h.cycle_wire.as_secs_f64() / period,
            "wire_limit_hz": 1.0 / h.cycle_wire.as_secs_f64().max(1e-9),
            "simulator_frames_in": h.sim_received,
            "simulator_frames_out": h.sim_sent,
        },
        "plot": plot.map(|p| p.display().to_string()),
        "errors": errors,
    })
}

#[allow(clippy::too_many_lines)] // one line of output per statement
fn summary_text(
    w: &WckSummary,
    h: &WhjSummary,
    elapsed: Duration,
    plot: Option<&PathBuf>,
) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "wCK humanoid: {SERVOS} x wCK-1108 on one 115200 bit/s bus (simulated, in-process)"
    );
    let _ = writeln!(
        s,
        "  scan    IDs 0..=30 in {:.0} ms: found {} servos ({}..={})",
        w.scan.as_secs_f64() * 1e3,
        w.found.len(),
        w.found.first().copied().unwrap_or(0),
        w.found.last().copied().unwrap_or(0)
    );
    for p in &w.poses {
        match p.settled {
            Some(t) => {
                let _ = writeln!(
                    s,
                    "  pose    {:<8} all {SERVOS} servos within 1 step (1.06 deg) after {:>4.0} ms",
                    p.name,
                    t.as_secs_f64() * 1e3
                );
            }
            None => {
                let _ = writeln!(
                    s,
                    "  pose    {:<8} still {} steps off after 1.2 s",
                    p.name, p.worst_steps
                );
            }
        }
    }
    let _ = writeln!(
        s,
        "  bus     {} status polls, {} transactions, {} retries, {} timeouts; {} bytes out, \
         {} back; wire busy {:.1} % (the wire allows {:.0} polls of all {SERVOS} servos per s)",
        w.polls,
        w.stats.attempts,
        w.stats.retries,
        w.stats.timeouts,
        w.bytes_out,
        w.bytes_in,
        100.0 * wck_busy(w),
        robobus_wck::timing::polling_rate_hz(usize::from(SERVOS), BaudRate::B115200)
    );
    let _ = writeln!(s);
    let model = h.joints.first().map_or("?", |t| t.model.as_str());
    let _ = writeln!(
        s,
        "WHJ arm: {} x {model} on one CAN FD bus (1 Mbit/s arbitration, 5 Mbit/s data; simulated, in-process)",
        h.joints.len()
    );
    let fw = h.joints.first().map_or("?", |t| t.firmware.as_str());
    let _ = writeln!(
        s,
        "  start   IAP release, identify (firmware {fw}), position mode, enable"
    );
    let st = &h.stats;
    let _ = writeln!(
        s,
        "  sine    {:.1} s, {AMPLITUDE_DEG} deg at {FREQUENCY_HZ} Hz: {} cycles at 500 Hz, {} complete, \
         {} deadline misses, {} missing replies, {} overruns",
        h.seconds, st.cycles, st.complete, st.deadline_misses, st.missing_replies, st.overruns
    );
    for t in &h.joints {
        let _ = writeln!(
            s,
            "          joint {}: tracking error rms {:.3} deg, max {:.3} deg; error bits: {}",
            t.id, t.rms_deg, t.max_deg, t.final_error
        );
    }
    let rt = st.round_trip;
    let _ = writeln!(
        s,
        "  latency round trip p50 {:.0} us, p90 {:.0} us, p99 {:.0} us, max {:.0} us; \
         cycle start late p99 {:.0} us",
        us(rt.p50),
        us(rt.p90),
        us(rt.p99),
        us(rt.max),
        us(st.start_lateness.p99)
    );
    let _ = writeln!(
        s,
        "  bus     {} frames per cycle take {:.0} us on the wire: {:.1} % busy at 500 Hz \
         (the wire allows about {:.0} Hz)",
        2 * h.joints.len(),
        us(h.cycle_wire),
        100.0 * h.cycle_wire.as_secs_f64() / PERIOD.as_secs_f64(),
        1.0 / h.cycle_wire.as_secs_f64().max(1e-9)
    );
    let _ = writeln!(s);
    if let Some(p) = plot {
        let _ = writeln!(s, "plot written to {}", p.display());
    }
    let _ = writeln!(
        s,
        "done in {:.1} s. Next: `robobus sim wck` / `robobus sim whj` serve these simulators \
         to other programs; `robobus monitor --sim` watches one live.",
        elapsed.as_secs_f64()
    );
    s
}
