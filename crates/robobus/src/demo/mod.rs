//! The built-in simulated robot (feature `sim`) driven through the library as a program
//! drives real hardware: its station and its operations.
//!
//! - the station: [`Station::simulated`], the built-in robot (a wCK humanoid of 16
//!   simulated wCK-1108 servos, IDs 0..=15, on the 115200 bit/s bus `sim-wck`, and a WHJ
//!   arm of 7 WHJ30 joints, IDs 1..=7, on the CAN FD bus `sim-whj`), in-process on the
//!   simulators' virtual clocks: the run takes the simulated time it reports, in as little
//!   wall time as the processor allows, and is the same on any machine;
//! - the wCK humanoid: [`ops::wck::scan`] finds the servos; the three keyframes are a
//!   keyframe [`Motion`] played with [`ops::wck::play`] pose by pose (an interpolated
//!   transition, then a hold), each pose checked with one status read of every servo
//!   through the station's [`WckGroup`] handle;
//! - the WHJ arm: [`ops::whj::info`] connects and identifies each joint,
//!   [`ops::whj::set_mode`] / [`ops::whj::enable`] prepare them, and the station's checked
//!   cyclic loop ([`CyclicLoop`]) streams a 500 Hz sine, its tracking measured with
//!   [`Tracking`] (what a wave reports);
//! - the end: the station is closed into its safe state ([`SafeState::apply`]: the wCK
//!   break, every WHJ joint disabled), also when the run is stopped or fails.
//!
//! Its [`DemoReport`] says what moved, how well it tracked and the bus figures (cycles,
//! deadline misses, latency percentiles, wire utilisation against the limit the protocol
//! timing models give); it serializes to the document `robobus demo --json` prints.
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
use std::time::{Duration, Instant};

use robobus_wck::{BaudRate, Command, Position as WckPosition, ServoId, TorqueLevel};
use robobus_whj::timing::{BitRates, frame_duration};
use robobus_whj::{JointId, Reply, Request, WorkMode};

use crate::actuator::{WCK_DEFAULT_CENTRE, WCK_DEGREES_PER_STEP};
use crate::motion::Tracking;
use crate::ops::wck::{Frame, Motion, Pose, ScanArgs};
use crate::ops::whj::ServoLoop;
use crate::ops::{self, Control, DeviceResult, OpError, Progress, SafeState};
use crate::robot::simulated::{JOINTS, SERVOS};
use crate::station::Station;
use crate::station::WckPort;
use crate::station::cyclic::CyclicLoop;
use crate::station::handles::WckGroup;
use crate::whj::{CyclicStats, MotionLimits};

/// The cyclic loop's period: 500 Hz.
pub const PERIOD: Duration = Duration::from_millis(2);
/// Sine amplitude of the arm trajectory, degrees.
pub const AMPLITUDE_DEG: f64 = 20.0;
/// Sine frequency of the arm trajectory, Hz.
pub const FREQUENCY_HZ: f64 = 0.5;
/// The station's wCK bus.
const WCK_BUS: &str = "sim-wck";
/// The station's WHJ bus.
const WHJ_BUS: &str = "sim-whj";
/// The keyframes' move rate, Hz.
const KEYFRAME_RATE_HZ: f64 = 50.0;
/// A keyframe's transition from the pose before, ms.
const TRANSITION_MS: u32 = 600;
/// How long each keyframe is held, ms.
const HOLD_MS: u32 = 400;
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

pub(super) fn us(d: Duration) -> f64 {
    d.as_secs_f64() * 1e6
}

pub(super) fn internal(what: &str, e: impl core::fmt::Display) -> OpError {
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

/// The values of a multi-device operation, or its first failure.
fn every<T>(what: &str, results: Vec<DeviceResult<u8, T>>) -> Result<Vec<T>, OpError> {
    results
        .into_iter()
        .map(|r| match r.outcome {
            ops::Outcome::Ok(v) => Ok(v),
            ops::Outcome::Failed(f) => Err(OpError::Device(format!("{what}: {}", f.error))),
        })
        .collect()
}

/// Runs the demo on the built-in robot's station: the wCK humanoid, then the WHJ arm (see
/// the [module docs](self)). Progress stages: the scan's (IDs probed of 31), a
/// `"keyframes"` note per pose and the play's (ms of the pose), `"WHJ connect"` (of 7),
/// `"500 Hz sine"` (cycles); a progress without a total is a note on what happens next.
pub fn run(config: &DemoConfig, control: &mut Control<'_>) -> Result<DemoReport, OpError> {
    if !(config.seconds.is_finite() && SECONDS_RANGE.contains(&config.seconds)) {
        return Err(OpError::invalid(
            "--seconds",
            config.seconds,
            "out of range 0.5..=60",
        ));
    }
    let wall = Instant::now();
    let (station, wck_sim, whj_sim) = Station::simulated_with_handles()?;
    let mut trace = Trace::default();
    let (mut wck, wck_s) = humanoid(&station, control, &mut trace)?;
    let served = wck_sim.with_bus(|b| b.stats());
    wck.bytes_out = served.host_bytes;
    wck.bytes_in = served.received_bytes;
    let bytes = usize::try_from(served.host_bytes + served.received_bytes).unwrap_or(usize::MAX);
    let wire = robobus_wck::timing::wire_time(bytes, BaudRate::B115200);
    wck.wire_utilisation = wire.as_secs_f64() / wck_s.max(1e-9);
    let mut whj = arm(&station, control, config.seconds, wck_s, &mut trace)?;
    let served = whj_sim.with_bus(|b| b.stats());
    whj.simulator_frames_in = served.host_frames;
    whj.simulator_frames_out = served.joint_frames;
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
    errors.extend(
        station
            .close()
            .into_iter()
            .map(|e| format!("safe state: {e}")),
    );
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

/// The degrees of wCK step `p` from the centre.
fn wck_deg(p: u8) -> f64 {
    (f64::from(p) - f64::from(WCK_DEFAULT_CENTRE)) * WCK_DEGREES_PER_STEP
}

/// Keyframe `to` as a motion: from the pose before (`None` for the first: sent at once),
/// a [`TRANSITION_MS`] transition, then a [`HOLD_MS`] hold, ended by the pose once more (a
/// motion ends with its last move: a trailing hold would not be waited for).
fn keyframe(from: Option<&[WckPosition]>, to: &[WckPosition]) -> Motion {
    let mut frames: Vec<Frame> = from
        .map(|p| {
            Frame::Pose(Pose {
                ms: 0,
                positions: p.to_vec(),
            })
        })
        .into_iter()
        .collect();
    frames.push(Frame::Pose(Pose {
        ms: TRANSITION_MS,
        positions: to.to_vec(),
    }));
    frames.push(Frame::Hold(HOLD_MS));
    frames.push(Frame::Pose(Pose {
        ms: 0,
        positions: to.to_vec(),
    }));
    Motion {
        torque: TorqueLevel::MIN,
        frames,
    }
}

/// The humanoid's part, and how long it took in simulated time (s). The report's byte
/// counts and wire utilisation are the caller's (the simulator's counters).
fn humanoid(
    station: &Station,
    control: &mut Control<'_>,
    trace: &mut Trace,
) -> Result<(WckReport, f64), OpError> {
    let port = station.wck(Some(WCK_BUS))?;
    let start = port.lock().now();
    let since = |port: &WckPort| port.lock().now().saturating_duration_since(start);
    let args = ScanArgs {
        ids: (0..=30).filter_map(|raw| ServoId::new(raw).ok()).collect(),
        bauds: vec![BaudRate::B115200],
        probes: 3,
    };
    let scan = ops::wck::scan(&mut port.lock(), &args, control)?;
    let scan_time = since(&port);
    let found: Vec<u8> = scan.found.iter().map(|f| f.id).collect();
    note(
        control,
        "wCK scan",
        format!(
            "wCK scan found {} servos in {:.0} ms",
            found.len(),
            scan_time.as_secs_f64() * 1e3
        ),
    );
    if found != (0..SERVOS).collect::<Vec<_>>() {
        return Err(OpError::Device(format!(
            "the wCK scan found {} servos ({found:?}); the simulated humanoid has {SERVOS}",
            found.len()
        )));
    }
    for f in &scan.found {
        if let Some(col) = WCK_PLOTTED.iter().position(|&p| p == f.id) {
            trace.push(scan_time.as_secs_f64(), col, wck_deg(f.position));
        }
    }
    check_stop(control)?;

    let servos = WckGroup::new(station, Some(WCK_BUS), &found)?;
    let (poses, polls) = keyframes(&port, &servos, start, control, trace)?;
    let stats = port.lock().stats();
    Ok((
        WckReport {
            servos_found: found.len(),
            ids: found,
            baud: 115_200,
            scan_ms: scan_time.as_secs_f64() * 1e3,
            poses,
            status_polls: polls,
            transactions: stats.attempts,
            retries: stats.retries,
            timeouts: stats.timeouts,
            bad_replies: stats.bad_replies,
            bytes_out: 0,
            bytes_in: 0,
            wire_utilisation: 0.0,
            status_poll_limit_hz: robobus_wck::timing::polling_rate_hz(
                usize::from(SERVOS),
                BaudRate::B115200,
            ),
        },
        since(&port).as_secs_f64(),
    ))
}

/// Plays the keyframes pose by pose on `port` (see the [module docs](self)), checking each
/// with a status read of every servo of `servos`; the poses and the status reads made.
fn keyframes(
    port: &WckPort,
    servos: &WckGroup,
    start: Instant,
    control: &mut Control<'_>,
    trace: &mut Trace,
) -> Result<(Vec<PoseReport>, u64), OpError> {
    let since = || port.lock().now().saturating_duration_since(start);
    let mut poses = Vec::new();
    let mut polls = 0u64;
    let mut previous: Option<Vec<WckPosition>> = None;
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
        let motion = keyframe(previous.as_deref(), &positions);
        // The moves the play sends, for the plot (they are its plan).
        let t0 = since().as_secs_f64();
        for step in motion.moves(KEYFRAME_RATE_HZ) {
            if let (Some(at_ms), Command::SyncMove(m)) = (step.at_ms, &step.command) {
                #[allow(clippy::cast_precision_loss)] // at most minutes
                let t = t0 + at_ms as f64 / 1e3;
                for (col, &id) in WCK_PLOTTED.iter().enumerate() {
                    if let Some(p) = m.positions().get(usize::from(id)) {
                        trace.push(t, TRACED + col, wck_deg(p.get()));
                    }
                }
            }
        }
        let played = ops::wck::play(
            &mut port.lock(),
            &motion,
            KEYFRAME_RATE_HZ,
            SafeState::Hold,
            control,
        )?;
        polls += played.watch_reads;
        // Where every servo stands now.
        let readings = every("wCK status", servos.status()?)?;
        polls += readings.len() as u64;
        let t = since().as_secs_f64();
        let mut worst = 0u8;
        for (raw, (reading, target)) in servos.ids().into_iter().zip(readings.iter().zip(pose)) {
            worst = worst.max(reading.position.abs_diff(target));
            if let Some(col) = WCK_PLOTTED.iter().position(|&p| p == raw) {
                trace.push(t, col, wck_deg(reading.position));
            }
        }
        #[allow(clippy::cast_precision_loss)] // at most minutes
        poses.push(PoseReport {
            name,
            settled_ms: (worst <= 1).then_some(played.duration_ms as f64),
            worst_error_steps: worst,
        });
        previous = Some(positions);
        check_stop(control)?;
    }
    control.report(&Progress::new(
        "keyframes",
        KEYFRAMES.len() as u64,
        Some(KEYFRAMES.len() as u64),
    ));
    Ok((poses, polls))
}

fn sine_target(i: usize, t: f64) -> f64 {
    #[allow(clippy::cast_precision_loss)] // i < 7
    let phase = i as f64 * 0.4;
    AMPLITUDE_DEG * (TAU * FREQUENCY_HZ * t + phase).sin() - AMPLITUDE_DEG * phase.sin()
}

/// The arm's part; its trace starts at `offset_s` (after the humanoid's). The simulator's
/// frame counts are the caller's.
#[allow(clippy::too_many_lines)] // one sequence: connect, loop, figures
fn arm(
    station: &Station,
    control: &mut Control<'_>,
    seconds: f64,
    offset_s: f64,
    trace: &mut Trace,
) -> Result<WhjReport, OpError> {
    let port = station.whj(Some(WHJ_BUS))?;
    let bus = port.bus();
    let ids: Vec<JointId> = (1..=JOINTS)
        .map(JointId::new)
        .collect::<Result<_, _>>()
        .map_err(|e| internal("joint ID", e))?;
    let mut identities = Vec::new();
    for (done, &id) in ids.iter().enumerate() {
        control.report(&Progress::new(
            "WHJ connect",
            done as u64,
            Some(u64::from(JOINTS)),
        ));
        check_stop(control)?;
        let info = ops::whj::info(bus, id)?;
        identities.push(JointIdentity {
            id: id.get(),
            model: info.identity.model.to_owned(),
            firmware: info.identity.firmware,
        });
    }
    every("WHJ disable", ops::whj::enable(bus, &ids, false))?;
    every(
        "WHJ mode",
        ops::whj::set_mode(bus, &ids, WorkMode::Position),
    )?;
    every("WHJ enable", ops::whj::enable(bus, &ids, true))?;
    // One servo frame at each joint's present position: its request and feedback frames
    // are what the loop sends each cycle, so their wire time is the cycle's cost.
    let mut cycle_wire = Duration::ZERO;
    for &id in &ids {
        let joint = bus.joint_unchecked(id);
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
    }
    note(
        control,
        "WHJ connect",
        format!("WHJ: {JOINTS} joints connected, position mode, enabled"),
    );

    let raw: Vec<u8> = ids.iter().map(|id| id.get()).collect();
    let mut cyc = CyclicLoop::start_with(
        station,
        Some(WHJ_BUS),
        &raw,
        ServoLoop::Position,
        1.0 / PERIOD.as_secs_f64(),
        MotionLimits {
            max_speed_deg_s: 120.0,
            max_accel_deg_s2: 800.0,
            ..MotionLimits::default()
        },
    )?;
    #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)] // <= 60 * 500
    let total = (seconds / PERIOD.as_secs_f64()).round() as u64;
    note(
        control,
        "500 Hz sine",
        format!("WHJ: {seconds} s sine trajectory at 500 Hz"),
    );
    let mut tracking = vec![Tracking::default(); ids.len()];
    let mut previous: Option<Vec<f64>> = None;
    loop {
        check_stop(control)?;
        let sample = cyc.next(Duration::from_millis(100)).ok_or_else(|| {
            OpError::Device("the cyclic loop produced no cycle within 100 ms".into())
        })?;
        #[allow(clippy::cast_precision_loss)] // cycles far below 2^52
        let t = sample.cycle as f64 * PERIOD.as_secs_f64();
        if t > seconds {
            break;
        }
        if sample.cycle % 50 == 0 {
            control.report(&Progress::new(
                "500 Hz sine",
                sample.cycle.min(total),
                Some(total),
            ));
        }
        // Feedback is the position when this cycle's command arrived: compare it with
        // the set-point sent the cycle before.
        if let Some(prev) = &previous {
            for ((fb, want), tr) in sample.feedback.iter().zip(prev).zip(&mut tracking) {
                if let Some(fb) = fb {
                    tr.add(fb.position_deg, *want);
                }
            }
        }
        if sample.cycle % 10 == 0 {
            let at = offset_s + t;
            for (i, fb) in sample.feedback.iter().enumerate() {
                if let Some(fb) = fb {
                    trace.push(at, WCK_PLOTTED.len() + i, fb.position_deg);
                }
            }
            for (i, cmd) in sample.commanded.iter().enumerate() {
                trace.push(at, TRACED + WCK_PLOTTED.len() + i, *cmd);
            }
        }
        previous = Some(sample.commanded);
        let targets: Vec<f64> = (0..ids.len()).map(|i| sine_target(i, t)).collect();
        cyc.set(&targets)?;
    }
    let stats = cyc
        .finish()
        .ok_or_else(|| OpError::Device("the cyclic loop had stopped".into()))?;
    let mut joints = Vec::new();
    for (&id, t) in ids.iter().zip(&tracking) {
        let code = bus.joint_unchecked(id).error_code()?;
        joints.push(JointTracking {
            joint: id.get(),
            rms_deg: t.rms().unwrap_or(0.0),
            max_deg: t.max().unwrap_or(0.0),
            samples: t.samples(),
            error: code.to_string(),
            error_free: code.is_empty(),
        });
    }
    Ok(whj_report(identities, seconds, joints, stats, cycle_wire))
}

/// The arm's report from what it did.
fn whj_report(
    identities: Vec<JointIdentity>,
    seconds: f64,
    tracking: Vec<JointTracking>,
    stats: CyclicStats,
    cycle_wire: Duration,
) -> WhjReport {
    let (rms, max) = tracking.iter().fold((0.0f64, 0.0f64), |(r, m), t| {
        (r.max(t.rms_deg), m.max(t.max_deg))
    });
    let period = PERIOD.as_secs_f64();
    WhjReport {
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
    }
}

mod report;

pub use report::{
    DemoReport, JointIdentity, JointTracking, LatencyUs, PoseReport, Trace, WckReport, WhjReport,
};
