//! The built-in simulated robot (feature `sim`): a wCK humanoid and a WHJ arm, simulated in
//! this process and driven through the client library, as a first session with real
//! hardware would drive them.
//!
//! - a wCK humanoid: 16 simulated wCK-1108 servos (IDs 0..=15) on a 115200 bit/s bus,
//!   reached through an in-process [`SimLink`](robobus_sim::wck::SimLink) (its replies do not
//!   depend on how loaded the machine is);
//! - a 7-joint WHJ30 arm (IDs 1..=7) on an in-process CAN FD bus, served on its own thread.
//!
//! [`run`] scans the wCK bus, plays three keyframes as synchronized moves while polling
//! every servo, connects the WHJ joints (IAP release, identify), enables them in position
//! mode and streams a 500 Hz sine trajectory through the cyclic loop. Its [`DemoReport`]
//! says what moved, how well it tracked and the bus figures (cycles, deadline misses,
//! latency percentiles, wire utilisation against the limit the protocol timing models
//! give); it serializes to the document `robobus demo --json` prints. Every joint is
//! disabled at the end, also when the run is stopped or fails.
//!
//! ```no_run
//! use robobus::demo::{DemoConfig, run};
//! use robobus::ops::{Control, Progress, StopToken};
//!
//! let stop = StopToken::new();
//! let mut show = |p: &Progress| eprintln!("{} {}/{:?}", p.stage, p.done, p.total);
//! let report = run(&DemoConfig { seconds: 1.0 }, &mut Control::new(&stop).with_progress(&mut show))?;
//! assert_eq!(report.wck.servos_found, 16);
//! # Ok::<(), robobus::ops::OpError>(())
//! ```

use std::f64::consts::TAU;
use std::sync::Arc;
use std::time::{Duration, Instant};

use robobus_link::{ByteLink, MemoryBus};
use robobus_wck::{BaudRate, Position as WckPosition, ServoId, TorqueLevel};
use robobus_whj::timing::{BitRates, frame_duration};
use robobus_whj::units::Position;
use robobus_whj::{JointId, Reply, Request, WorkMode};
use serde::Serialize;

use crate::ops::safe::WhjJoints;
use crate::ops::whj::ServoLoop;
use crate::ops::{Control, OpError, Progress, SafeState};
use crate::wck::{ScanOptions, WckBus};
use crate::whj::{CyclicConfig, CyclicStats, JointBus, JointBusConfig, MotionLimits, Percentiles};

/// wCK servos of the humanoid (IDs 0..SERVOS).
pub const SERVOS: u8 = 16;
/// WHJ joints of the arm (IDs 1..=JOINTS).
pub const JOINTS: u8 = 7;
/// The cyclic loop's period: 500 Hz.
pub const PERIOD: Duration = Duration::from_millis(2);
/// Sine amplitude of the arm trajectory, degrees.
pub const AMPLITUDE_DEG: f64 = 20.0;
/// Sine frequency of the arm trajectory, Hz.
pub const FREQUENCY_HZ: f64 = 0.5;
/// Degrees per wCK position step.
const WCK_DEG_PER_STEP: f64 = 1.055;
/// The shortest and longest sine run, seconds.
pub const SECONDS_RANGE: core::ops::RangeInclusive<f64> = 0.5..=60.0;

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

/// The plotted wCK servos (the ones the keyframes move most).
const WCK_PLOTTED: [u8; 4] = [0, 2, 4, 6];
/// Signals in the trace: the plotted wCK servos and the WHJ joints (each also traced as
/// its target, `TRACED` columns further on).
const TRACED: usize = WCK_PLOTTED.len() + JOINTS as usize;

/// What the demo does.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DemoConfig {
    /// How long the WHJ arm follows its sine trajectory, seconds ([`SECONDS_RANGE`]).
    pub seconds: f64,
}

/// What the demo did: the document `robobus demo --json` prints.
#[derive(Debug, Clone, Serialize)]
pub struct DemoReport {
    /// Wall time of the whole run, s.
    pub wall_s: f64,
    /// The wCK humanoid.
    pub wck: WckReport,
    /// The WHJ arm.
    pub whj: WhjReport,
    /// The plot file, when the front end wrote one (set by the caller).
    pub plot: Option<String>,
    /// What did not go as it should (a pose that did not settle, an error bit latched).
    pub errors: Vec<String>,
    /// Positions over time, for a plot (not serialized).
    #[serde(skip)]
    pub trace: Trace,
}

/// One keyframe's outcome.
#[derive(Debug, Clone, Serialize)]
pub struct PoseReport {
    /// The keyframe's name.
    pub name: &'static str,
    /// When every servo stood within one step of it, ms after the move (`None`: not within 1.2 s).
    pub settled_ms: Option<f64>,
    /// The largest distance from the target at the end, steps.
    pub worst_error_steps: u8,
}

/// What the wCK part did.
#[derive(Debug, Clone, Serialize)]
pub struct WckReport {
    /// Servos the scan found.
    pub servos_found: usize,
    /// Their IDs.
    pub ids: Vec<u8>,
    /// Bus rate, bit/s.
    pub baud: u32,
    /// Scan time, ms.
    pub scan_ms: f64,
    /// The keyframes.
    pub poses: Vec<PoseReport>,
    /// Status reads while the poses settled.
    pub status_polls: u64,
    /// Transactions (attempts) of the client.
    pub transactions: u64,
    /// Retries.
    pub retries: u64,
    /// Timeouts.
    pub timeouts: u64,
    /// Implausible replies.
    pub bad_replies: u64,
    /// Bytes the host sent.
    pub bytes_out: u64,
    /// Bytes the servos sent.
    pub bytes_in: u64,
    /// Wire time of all bytes / run time.
    pub wire_utilisation: f64,
    /// Status polls of all servos per second the wire allows.
    pub status_poll_limit_hz: f64,
}

/// One joint's identity.
#[derive(Debug, Clone, Serialize)]
pub struct JointIdentity {
    /// Joint ID.
    pub id: u8,
    /// Model name.
    pub model: String,
    /// Firmware version.
    pub firmware: String,
}

/// One joint's tracking of the sine.
#[derive(Debug, Clone, Serialize)]
pub struct JointTracking {
    /// Joint ID.
    pub joint: u8,
    /// RMS of feedback − previous set-point, degrees.
    pub rms_deg: f64,
    /// Largest such error, degrees.
    pub max_deg: f64,
    /// Samples compared.
    pub samples: u64,
    /// Error bits read after the run.
    pub error: String,
    /// No error bit latched after the run.
    pub error_free: bool,
}

/// Latency percentiles, µs.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct LatencyUs {
    /// Number of samples.
    pub samples: usize,
    /// Median.
    pub p50: f64,
    /// 90th percentile.
    pub p90: f64,
    /// 99th percentile.
    pub p99: f64,
    /// Largest.
    pub max: f64,
}

impl From<&Percentiles> for LatencyUs {
    fn from(p: &Percentiles) -> Self {
        Self {
            samples: p.samples,
            p50: us(p.p50),
            p90: us(p.p90),
            p99: us(p.p99),
            max: us(p.max),
        }
    }
}

/// What the WHJ part did.
#[derive(Debug, Clone, Serialize)]
pub struct WhjReport {
    /// Joints connected.
    pub joints: usize,
    /// Their identities.
    pub identities: Vec<JointIdentity>,
    /// Sine run, s.
    pub seconds: f64,
    /// Loop rate, Hz.
    pub rate_hz: f64,
    /// Cycles run.
    pub cycles: u64,
    /// Cycles with every joint's feedback in time.
    pub complete: u64,
    /// Cycles that missed their deadline.
    pub deadline_misses: u64,
    /// Feedback frames that never came.
    pub missing_replies: u64,
    /// Feedback frames that came after their cycle.
    pub late_replies: u64,
    /// Cycles that started after the next one was due.
    pub overruns: u64,
    /// Frames the link refused.
    pub send_errors: u64,
    /// Command → feedback round trip.
    pub round_trip_us: LatencyUs,
    /// How late cycles started.
    pub start_lateness_us: LatencyUs,
    /// Each joint's tracking.
    pub tracking: Vec<JointTracking>,
    /// The worst joint's RMS tracking error, degrees.
    pub tracking_rms_deg: f64,
    /// The worst joint's largest tracking error, degrees.
    pub tracking_max_deg: f64,
    /// Wire time of one cycle's frames, µs.
    pub cycle_wire_us: f64,
    /// Cycle wire time / period.
    pub wire_utilisation: f64,
    /// Cycles per second the wire allows.
    pub wire_limit_hz: f64,
    /// Frames the simulator received.
    pub simulator_frames_in: u64,
    /// Frames the simulator sent.
    pub simulator_frames_out: u64,
    /// The loop's own statistics.
    #[serde(skip)]
    pub stats: CyclicStats,
    /// Wire time of one cycle.
    #[serde(skip)]
    pub cycle_wire: Duration,
}

/// Positions over time: (seconds since the start, signal, degrees). Signals are the
/// plotted wCK servos, then the WHJ joints, then the targets of both in the same order
/// (the keyframe positions sent, the set-points the loop sent) ([`Trace::names`]).
#[derive(Debug, Clone, Default)]
pub struct Trace(pub Vec<(f64, usize, f64)>);

impl Trace {
    fn push(&mut self, t: f64, col: usize, v: f64) {
        self.0.push((t, col, v));
    }

    /// The signal names: `wck0_deg`, ..., `whj1_deg`, ..., then the targets:
    /// `wck0_target_deg`, ..., `whj1_target_deg`, ...
    pub fn names() -> Vec<String> {
        let mut names: Vec<String> = WCK_PLOTTED
            .iter()
            .map(|id| format!("wck{id}_deg"))
            .collect();
        names.extend((1..=JOINTS).map(|j| format!("whj{j}_deg")));
        let targets: Vec<String> = names
            .iter()
            .map(|n| n.replace("_deg", "_target_deg"))
            .collect();
        names.extend(targets);
        names
    }

    /// One row per distinct time: the time and one value per signal (`None`: not sampled).
    pub fn rows(&self) -> (Vec<f64>, Vec<Vec<Option<f64>>>) {
        let columns = 2 * TRACED;
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
        (time, signals)
    }
}

fn us(d: Duration) -> f64 {
    d.as_secs_f64() * 1e6
}

fn internal(what: &str, e: impl core::fmt::Display) -> OpError {
    OpError::Device(format!("simulated robot: {what}: {e}"))
}

fn check_stop(control: &Control<'_>) -> Result<(), OpError> {
    if control.stopped() {
        Err(OpError::Interrupted {
            detail: Some("every simulated joint was disabled".into()),
        })
    } else {
        Ok(())
    }
}

/// Runs the demo: the wCK humanoid, then the WHJ arm. Progress stages: `"wCK scan"`
/// (IDs probed of 31), `"keyframes"` (of 3), `"WHJ connect"` (of 7), `"500 Hz sine"`
/// (cycles); a progress without a total is a note on what happens next.
pub fn run(config: &DemoConfig, control: &mut Control<'_>) -> Result<DemoReport, OpError> {
    if !(config.seconds.is_finite() && SECONDS_RANGE.contains(&config.seconds)) {
        return Err(OpError::invalid(
            "--seconds",
            config.seconds,
            "out of range 0.5..=60",
        ));
    }
    let wall = Instant::now();
    let mut trace = Trace::default();
    let wck = humanoid(control, wall, &mut trace)?;
    let whj = arm(control, config.seconds, wall, &mut trace)?;
    let mut errors = Vec::new();
    for p in &wck.poses {
        if p.settled_ms.is_none() {
            errors.push(format!(
                "wCK pose `{}` still {} steps off",
                p.name, p.worst_error_steps
            ));
        }
    }
    for t in &whj.tracking {
        if !t.error_free {
            errors.push(format!("WHJ joint {} error {}", t.joint, t.error));
        }
    }
    Ok(DemoReport {
        wall_s: wall.elapsed().as_secs_f64(),
        wck,
        whj,
        plot: None,
        errors,
        trace,
    })
}

fn note(control: &mut Control<'_>, stage: &'static str, text: String) {
    control.report(&Progress::new(stage, 0, None).with_note(text));
}

fn humanoid(
    control: &mut Control<'_>,
    wall: Instant,
    trace: &mut Trace,
) -> Result<WckReport, OpError> {
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
    let result = humanoid_run(&mut bus, control, wall, trace);
    let served = sim.with_bus(|b| b.stats());
    let (found, scan, poses, polls) = result?;
    let stats = bus.stats();
    let elapsed = started.elapsed();
    let bytes = usize::try_from(served.host_bytes + served.received_bytes).unwrap_or(usize::MAX);
    let wire = robobus_wck::timing::wire_time(bytes, BaudRate::B115200);
    Ok(WckReport {
        servos_found: found.len(),
        ids: found,
        baud: 115_200,
        scan_ms: scan.as_secs_f64() * 1e3,
        poses,
        status_polls: polls,
        transactions: stats.attempts,
        retries: stats.retries,
        timeouts: stats.timeouts,
        bad_replies: stats.bad_replies,
        bytes_out: served.host_bytes,
        bytes_in: served.received_bytes,
        wire_utilisation: wire.as_secs_f64() / elapsed.as_secs_f64().max(1e-9),
        status_poll_limit_hz: robobus_wck::timing::polling_rate_hz(
            usize::from(SERVOS),
            BaudRate::B115200,
        ),
    })
}

type HumanoidRun = (Vec<u8>, Duration, Vec<PoseReport>, u64);

fn servo(raw: u8) -> Result<ServoId, OpError> {
    ServoId::new(raw).map_err(|e| internal("servo ID", e))
}

fn humanoid_run<L: ByteLink>(
    bus: &mut WckBus<L>,
    control: &mut Control<'_>,
    wall: Instant,
    trace: &mut Trace,
) -> Result<HumanoidRun, OpError> {
    let options = ScanOptions {
        check_duplicates: false,
        probes: 3,
        ..ScanOptions::at(BaudRate::B115200)
    };
    let t0 = Instant::now();
    let report = bus.scan(&options, |p| {
        control.report(
            &Progress::new("wCK scan", p.done as u64, Some(31))
                .with_note(format!("{} found", p.found)),
        );
    })?;
    let scan = t0.elapsed();
    let mut found: Vec<u8> = report.found.iter().map(|f| f.id.get()).collect();
    // A second look at any missing ID (with the client's retries), as a user rescans: on
    // a busy machine a module's answer can miss the scan's short deadline.
    for raw in 0..SERVOS {
        if !found.contains(&raw) && bus.servo(servo(raw)?).status().is_ok() {
            found.push(raw);
        }
    }
    found.sort_unstable();
    note(
        control,
        "wCK scan",
        format!(
            "wCK scan found {} servos in {:.0} ms",
            found.len(),
            scan.as_secs_f64() * 1e3
        ),
    );
    if found.len() != usize::from(SERVOS) {
        return Err(OpError::Device(format!(
            "the wCK scan found {} servos ({found:?}); the simulated humanoid has {SERVOS}",
            found.len()
        )));
    }
    check_stop(control)?;

    let torque = TorqueLevel::new(0).map_err(|e| internal("torque", e))?;
    let mut poses = Vec::new();
    let mut polls = 0u64;
    for (done, (name, pose)) in KEYFRAMES.into_iter().enumerate() {
        control.report(
            &Progress::new("keyframes", done as u64, Some(KEYFRAMES.len() as u64))
                .with_note(format!("wCK keyframe `{name}`")),
        );
        let positions = pose
            .iter()
            .map(|&p| WckPosition::new(p))
            .collect::<Result<Vec<_>, _>>()
            .map_err(|e| internal("keyframe", e))?;
        bus.sync_move(torque, &positions)?;
        let start = Instant::now();
        let mut settled = None;
        let mut worst = u8::MAX;
        // Poll every servo until all stand within one step, for at most 1.2 s.
        while start.elapsed() < Duration::from_millis(1200) {
            check_stop(control)?;
            worst = 0;
            let t = wall.elapsed().as_secs_f64();
            for (raw, target) in (0..SERVOS).zip(pose) {
                let at = bus.servo(servo(raw)?).status()?.position.get();
                polls += 1;
                worst = worst.max(at.abs_diff(target));
                if let Some(col) = WCK_PLOTTED.iter().position(|&p| p == raw) {
                    trace.push(t, col, (f64::from(at) - 127.0) * WCK_DEG_PER_STEP);
                    trace.push(
                        t,
                        TRACED + col,
                        (f64::from(target) - 127.0) * WCK_DEG_PER_STEP,
                    );
                }
            }
            if worst <= 1 {
                settled = Some(start.elapsed());
                break;
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        poses.push(PoseReport {
            name,
            settled_ms: settled.map(|d| d.as_secs_f64() * 1e3),
            worst_error_steps: worst,
        });
    }
    control.report(&Progress::new(
        "keyframes",
        KEYFRAMES.len() as u64,
        Some(KEYFRAMES.len() as u64),
    ));
    Ok((found, scan, poses, polls))
}

fn sine_target(i: usize, t: f64) -> f64 {
    #[allow(clippy::cast_precision_loss)] // i < 7
    let phase = i as f64 * 0.4;
    AMPLITUDE_DEG * (TAU * FREQUENCY_HZ * t + phase).sin() - AMPLITUDE_DEG * phase.sin()
}

fn arm(
    control: &mut Control<'_>,
    seconds: f64,
    wall: Instant,
    trace: &mut Trace,
) -> Result<WhjReport, OpError> {
    let (arm_server, bus) = ArmServer::start((1..=JOINTS).collect(), 7)?;
    let result = arm_run(&bus, control, seconds, wall, trace);
    // Safe state whatever happened: every joint disabled.
    let ids: Vec<JointId> = (1..=JOINTS)
        .filter_map(|id| JointId::new(id).ok())
        .collect();
    disable_all(&bus, &ids);
    drop(bus);
    let served = arm_server.stop()?;
    let mut report = result?;
    report.simulator_frames_in = served.received;
    report.simulator_frames_out = served.sent;
    Ok(report)
}

#[allow(clippy::too_many_lines)] // one sequence: connect, loop, figures
fn arm_run(
    bus: &JointBus,
    control: &mut Control<'_>,
    seconds: f64,
    wall: Instant,
    trace: &mut Trace,
) -> Result<WhjReport, OpError> {
    let ids: Vec<JointId> = (1..=JOINTS)
        .map(JointId::new)
        .collect::<Result<_, _>>()
        .map_err(|e| internal("joint ID", e))?;
    let mut identities = Vec::new();
    let mut cycle_wire = Duration::ZERO;
    for (done, &id) in ids.iter().enumerate() {
        control.report(&Progress::new(
            "WHJ connect",
            done as u64,
            Some(u64::from(JOINTS)),
        ));
        check_stop(control)?;
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
        identities.push(JointIdentity {
            id: id.get(),
            model: identity.model.name().to_owned(),
            firmware: identity.firmware.to_string(),
        });
    }
    note(
        control,
        "WHJ connect",
        format!("WHJ: {JOINTS} joints connected, position mode, enabled"),
    );

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
        .ok_or_else(|| OpError::Device("the cyclic loop produced no cycle within 1 s".into()))?;
    let start = first.scheduled;
    #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)] // <= 60 * 500
    let total = (seconds / PERIOD.as_secs_f64()).round() as u64;
    note(
        control,
        "500 Hz sine",
        format!("WHJ: {seconds} s sine trajectory at 500 Hz"),
    );
    let mut err_sq = vec![0.0f64; ids.len()];
    let mut max_err = vec![0.0f64; ids.len()];
    let mut compared = vec![0u64; ids.len()];
    let mut previous: Option<Vec<i32>> = None;
    let mut interrupted = false;
    loop {
        if control.stopped() {
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
            control.report(&Progress::new(
                "500 Hz sine",
                report.cycle.min(total),
                Some(total),
            ));
        }
        // Feedback is the position when this cycle's command arrived: compare it with
        // the set-point sent the cycle before.
        if let Some(prev) = &previous {
            for (i, (fb, cmd)) in report.feedback.iter().zip(prev).enumerate() {
                if let Some(fb) = fb {
                    let e = (fb.position.degrees() - Position(*cmd).degrees()).abs();
                    if let (Some(sq), Some(mx), Some(n)) =
                        (err_sq.get_mut(i), max_err.get_mut(i), compared.get_mut(i))
                    {
                        *sq += e * e;
                        *mx = mx.max(e);
                        *n += 1;
                    }
                }
            }
        }
        if report.cycle % 10 == 0 {
            let now = wall.elapsed().as_secs_f64();
            for (i, fb) in report.feedback.iter().enumerate() {
                if let Some(fb) = fb {
                    trace.push(now, WCK_PLOTTED.len() + i, fb.position.degrees());
                }
            }
            for (i, cmd) in report.commanded.iter().enumerate() {
                trace.push(
                    now,
                    TRACED + WCK_PLOTTED.len() + i,
                    Position(*cmd).degrees(),
                );
            }
        }
        previous = Some(report.commanded.clone());
        let targets = (0..ids.len())
            .map(|i| Position::from_degrees(sine_target(i, t)))
            .collect::<Result<Vec<_>, _>>()
            .map_err(|e| internal("sine target", e))?;
        cyc.set_positions(&targets)?;
    }
    let stats = cyc.stop();
    if interrupted {
        return Err(OpError::Interrupted {
            detail: Some("every simulated joint was disabled".into()),
        });
    }
    let mut tracking = Vec::new();
    for (i, &id) in ids.iter().enumerate() {
        let n = compared.get(i).copied().unwrap_or(0);
        #[allow(clippy::cast_precision_loss)]
        let rms = (err_sq.get(i).copied().unwrap_or(0.0) / n.max(1) as f64).sqrt();
        let code = bus.joint_unchecked(id).error_code()?;
        tracking.push(JointTracking {
            joint: id.get(),
            rms_deg: rms,
            max_deg: max_err.get(i).copied().unwrap_or(0.0),
            samples: n,
            error: code.to_string(),
            error_free: code.is_empty(),
        });
    }
    let (rms, max) = tracking.iter().fold((0.0f64, 0.0f64), |(r, m), t| {
        (r.max(t.rms_deg), m.max(t.max_deg))
    });
    let period = PERIOD.as_secs_f64();
    Ok(WhjReport {
        joints: identities.len(),
        identities,
        seconds,
        rate_hz: 1.0 / period,
        cycles: stats.cycles,
        complete: stats.complete,
        deadline_misses: stats.deadline_misses,
        missing_replies: stats.missing_replies,
        late_replies: stats.late_replies,
        overruns: stats.overruns,
        send_errors: stats.send_errors,
        round_trip_us: (&stats.round_trip).into(),
        start_lateness_us: (&stats.start_lateness).into(),
        tracking,
        tracking_rms_deg: rms,
        tracking_max_deg: max,
        cycle_wire_us: us(cycle_wire),
        wire_utilisation: cycle_wire.as_secs_f64() / period,
        wire_limit_hz: 1.0 / cycle_wire.as_secs_f64().max(1e-9),
        simulator_frames_in: 0,
        simulator_frames_out: 0,
        stats,
        cycle_wire,
    })
}

/// Every joint of `ids` to [`SafeState::Disable`] through [`SafeState::apply`] (the one
/// safe stop), whatever happened before; a failure is logged.
fn disable_all(bus: &JointBus, ids: &[JointId]) {
    let joints: Vec<_> = ids.iter().map(|&id| bus.joint_unchecked(id)).collect();
    for f in SafeState::Disable.apply(&mut WhjJoints {
        joints: &joints,
        servo: ServoLoop::Position,
    }) {
        tracing::warn!(failure = %f, "simulated arm: safe state");
    }
}

/// Simulated WHJ30 joints served on a thread of their own over an in-process CAN FD bus
/// (stopped when dropped).
#[derive(Debug)]
pub(crate) struct ArmServer(robobus_sim::whj::Served);

impl ArmServer {
    /// Joints `ids` (simulation seed `seed`), and a client bus to them.
    pub(crate) fn start(ids: Vec<u8>, seed: u64) -> Result<(Self, JointBus), OpError> {
        use robobus_sim::whj::{Served, WhjBus, WhjModel};

        let wire = MemoryBus::new();
        let served = Served::spawn(
            "sim-whj-arm",
            WhjBus::chain(ids, WhjModel::Whj30, seed),
            wire.endpoint(),
        )
        .map_err(|e| internal("starting the simulated WHJ arm", e))?;
        let bus = JointBus::open_with(wire.endpoint(), JointBusConfig::simulated())?;
        Ok((Self(served), bus))
    }

    /// Stops serving; what the simulator served.
    fn stop(self) -> Result<robobus_sim::whj::ServeStats, OpError> {
        self.0
            .stop()
            .map(|(_, stats)| stats)
            .map_err(|e| internal("the WHJ arm", e))
    }
}

/// A simulated WHJ30 arm in this process that moves by itself: each joint follows a slow
/// sine (15° amplitude, 0.2 Hz, phase 0.5 rad per joint, starting from 0°) through a
/// 200 Hz smoothed cyclic loop, so that a monitor has something to show without hardware
/// (`robobus monitor --sim`). [`SimArm::sample`] gives the loop's latest feedback; the
/// joints are disabled and the simulator stopped when the arm is dropped.
#[derive(Debug)]
pub struct SimArm {
    ids: Vec<JointId>,
    cyc: Option<crate::whj::OwnedCyclic>,
    bus: Arc<JointBus>,
    server: Option<ArmServer>,
    start: Instant,
}

impl SimArm {
    /// Starts the simulator with joints `ids`, connects them, enables them in position
    /// mode and starts the loop.
    pub fn start(ids: &[JointId]) -> Result<Self, OpError> {
        let (server, bus) = ArmServer::start(ids.iter().map(|j| j.get()).collect(), 5)?;
        let mut arm = Self {
            ids: ids.to_vec(),
            cyc: None,
            bus: Arc::new(bus),
            server: Some(server),
            start: Instant::now(),
        };
        for &id in ids {
            let j = arm.bus.joint(id)?;
            j.disable()?;
            j.set_mode(robobus_whj::WorkMode::Position)?;
            j.enable()?;
        }
        arm.cyc = Some(arm.bus.cyclic_owned(CyclicConfig {
            smooth: Some(crate::whj::MotionLimits::default()),
            ..CyclicConfig::position(ids.to_vec(), Duration::from_millis(5))
        })?);
        arm.start = Instant::now();
        Ok(arm)
    }

    /// The joints.
    #[must_use]
    pub fn joints(&self) -> &[JointId] {
        &self.ids
    }

    /// The loop's latest cycle (feedback per joint, `None` for a joint that did not answer
    /// in it), after which the sine's next targets are set.
    pub fn sample(&self) -> Option<crate::whj::CycleReport> {
        let cyc = self.cyc.as_ref()?;
        let latest = cyc.latest();
        let t = self.start.elapsed().as_secs_f64();
        let targets: Vec<Position> = (0..self.ids.len())
            .filter_map(|i| {
                #[allow(clippy::cast_precision_loss)] // at most 30 joints
                let phase = i as f64 * 0.5;
                Position::from_degrees(15.0 * (TAU * 0.2 * t + phase).sin() - 15.0 * phase.sin())
                    .ok()
            })
            .collect();
        let _ = cyc.set_positions(&targets);
        latest
    }
}

impl Drop for SimArm {
    fn drop(&mut self) {
        if let Some(cyc) = self.cyc.take() {
            let _ = cyc.stop();
        }
        disable_all(&self.bus, &self.ids);
        if let Some(server) = self.server.take() {
            let _ = server.stop();
        }
    }
}
