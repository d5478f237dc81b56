//! Running a `robobus whj` command through the client library ([`robobus::whj::JointBus`]).
//!
//! [`execute`] opens the bus named by `--bus` (`udp`, `udp:GROUP:PORT` or a `SocketCAN`
//! interface), connects each joint the command names ([`JointBus::joint`]: IAP release,
//! identify) and runs the command as a [`WhjRun`]: scans, register reads and writes, enable
//! / disable / modes, smooth moves ([`Profile`]: speed- and acceleration-limited steps, so
//! no frame exceeds the joint's step protection), single servo frames, and test waves
//! through the cyclic loop ([`JointBus::cyclic`]) with a progress bar on a terminal.
//!
//! # Output
//!
//! Text: a table, one row per joint (or register), columns named like the JSON fields.
//! `--json`: one object `{"bus", "command", "results": [...]}` (`wave` adds `"stats"`).
//! Field names carry their units: `position_deg`, `speed_rpm`, `current_ma`, `voltage_v`,
//! `temperature_c`.
//!
//! # Errors and exit codes
//!
//! A joint that does not answer ([`WhjError::Timeout`], [`WhjError::Silent`]) is a
//! [`Timeout`] (exit code 3; the message names the joint), and so is a `SocketCAN`
//! interface that cannot be opened; every other client error is a runtime error (1).
//! Ctrl-C / SIGTERM during `move` or `wave` brings the joint to the safe state chosen with
//! `--on-stop` (hold where it is, or disable) and returns [`Interrupted`] (exit code 130).

use std::fmt::Write as _;
use std::io::IsTerminal as _;
use std::time::{Duration, Instant};

use anyhow::{Context as _, anyhow};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use robobus::whj::{
    CyclicConfig, Feedback, Joint, JointBus, JointBusConfig, MotionLimits, Profile, Protocol,
    ServoMode, WhjError,
};
use robobus_link::FrameLink;
use robobus_whj::registers::{Half, RegisterInfo};
use robobus_whj::units::{Current, CurrentScale, Position, TargetSpeed};
use robobus_whj::{JointId, RegisterAddr, WorkMode};
use serde_json::{Value, json};

use crate::exit::{Interrupted, Timeout};
use crate::output;
use crate::sim_whj::{BusSpec, parse_bus};

/// What brings a joint to a safe state when `move` or `wave` is interrupted.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub(crate) enum OnStop {
    // Plain comments: doc comments would become clap's per-value help and switch every
    // `robobus whj` help page to the long layout; `--on-stop`'s own help explains them.
    // Stay enabled and hold the present position (speed / current waves: target 0).
    #[default]
    Hold,
    // Disable the drive.
    Disable,
}

/// Which servo loop a wave drives.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum WaveLoop {
    /// Position targets, degrees.
    Position,
    /// Speed targets, RPM.
    Speed,
    /// Current targets, mA.
    Current,
}

/// A test signal for `wave`.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Wave {
    /// Square instead of sine.
    pub(crate) square: bool,
    /// The loop it drives.
    pub(crate) mode: WaveLoop,
    /// Amplitude, in the loop's unit.
    pub(crate) amplitude: f64,
    /// Frequency, Hz.
    pub(crate) frequency: f64,
    /// Offset, in the loop's unit.
    pub(crate) offset: f64,
    /// Duration, seconds.
    pub(crate) duration: f64,
    /// Cycles per second.
    pub(crate) rate_hz: f64,
}

impl Wave {
    /// The signal at `t` seconds.
    pub(crate) fn at(&self, t: f64) -> f64 {
        let s = (std::f64::consts::TAU * self.frequency * t).sin();
        if !self.square {
            self.offset + self.amplitude * s
        } else if s >= 0.0 {
            self.offset + self.amplitude
        } else {
            self.offset - self.amplitude
        }
    }
}

/// How a `robobus whj` command runs on the bus.
#[derive(Debug, Clone)]
pub(crate) enum WhjRun {
    /// Find joints among these IDs.
    Scan(Vec<JointId>),
    /// Identity, limits, status of one joint.
    Info(JointId),
    /// Status of joints.
    Status(Vec<JointId>),
    /// Enable (`true`) or disable drives.
    Enable(Vec<JointId>, bool),
    /// Set the work mode.
    Mode(Vec<JointId>, WorkMode),
    /// Smooth move to an angle.
    Move {
        /// The joint.
        joint: JointId,
        /// Target, degrees.
        degrees: f64,
        /// Largest speed, degrees per second.
        max_speed: f64,
        /// Frames per second.
        rate_hz: f64,
    },
    /// One speed servo frame, RPM.
    Speed(JointId, f64),
    /// One current servo frame, mA.
    Current(JointId, f64),
    /// Set zero.
    Zero(JointId),
    /// Clear errors.
    Clear(Vec<JointId>),
    /// Save to flash.
    Save(Vec<JointId>),
    /// Read registers.
    Read {
        /// The joint.
        joint: JointId,
        /// First register.
        addr: RegisterAddr,
        /// Its table entry, if not reserved.
        info: Option<&'static RegisterInfo>,
        /// Registers to read; `None` = the register (or pair) by name.
        count: Option<u8>,
    },
    /// Write a register and read it back.
    Write {
        /// The joint.
        joint: JointId,
        /// The register.
        addr: RegisterAddr,
        /// Its table entry, if not reserved.
        info: Option<&'static RegisterInfo>,
        /// The value (unit of the register, or counts with `raw`).
        value: f64,
        /// The value is in counts.
        raw: bool,
    },
    /// New ID, saved to flash.
    SetId(JointId, JointId),
    /// A test signal through the cyclic loop.
    Wave(JointId, Wave),
    /// Start the application of joints in the bootloader.
    ReleaseIap(Vec<JointId>),
}

/// Everything [`execute`] needs.
#[derive(Debug)]
pub(crate) struct WhjJob<'a> {
    /// The subcommand, for messages.
    pub(crate) action: &'static str,
    /// The bus as given.
    pub(crate) bus: &'a str,
    /// What to do.
    pub(crate) run: &'a WhjRun,
    /// Safe state after Ctrl-C.
    pub(crate) on_stop: OnStop,
    /// `--json`.
    pub(crate) json: bool,
}

/// Installs the one Ctrl-C / SIGTERM handler ([`crate::interrupt`]).
fn arm_ctrlc() {
    let _ = crate::interrupt::stop_token();
}

/// Maps a client error to its exit code: timeouts (3) name the joint.
pub(crate) fn whj_error(e: WhjError) -> anyhow::Error {
    if e.is_timeout() {
        anyhow::Error::new(Timeout(e.to_string()))
    } else {
        anyhow::Error::new(e)
    }
}

/// Opens the link of a `--bus` value.
pub(crate) fn open_link(bus: &str) -> anyhow::Result<Box<dyn FrameLink + Send>> {
    let spec = parse_bus(bus).map_err(|e| crate::exit::usage(format!("--bus: {e}")))?;
    match spec {
        BusSpec::Udp { group, port } => {
            let cfg = robobus_link::udp::UdpBusConfig {
                group,
                port,
                ..robobus_link::udp::UdpBusConfig::default()
            };
            Ok(Box::new(
                robobus_link::udp::UdpBus::open(&cfg)
                    .with_context(|| format!("joining the UDP bus {group}:{port}"))?,
            ))
        }
        #[cfg(target_os = "linux")]
        // Like a serial port that is not there: no device (exit code 3).
        BusSpec::SocketCan(iface) => Ok(Box::new(
            robobus_link::socketcan::SocketCanLink::open(&iface).map_err(|e| {
                anyhow::Error::new(Timeout(format!("opening SocketCAN interface {iface}: {e}")))
            })?,
        )),
        #[cfg(not(target_os = "linux"))]
        BusSpec::SocketCan(iface) => Err(anyhow!(
            "SocketCAN interface {iface}: SocketCAN exists on Linux only; use --bus udp"
        )),
    }
}

type Row = Vec<(&'static str, Value)>;

/// Runs a `robobus whj` command on the bus.
pub(crate) fn execute(job: &WhjJob<'_>) -> anyhow::Result<()> {
    let link = open_link(job.bus)?;
    let connect_timeout = match job.run {
        // A joint in its bootloader answers the IAP release at once; a scan must not wait
        // seconds for every absent ID.
        WhjRun::Scan(_) => Duration::from_millis(150),
        _ => Duration::from_secs(2),
    };
    let bus = JointBus::open_with(
        link,
        JointBusConfig {
            connect_timeout,
            ..JointBusConfig::default()
        },
    )
    .map_err(whj_error)?;
    let mut extra = None;
    let rows = run(&bus, job, &mut extra)?;
    if job.json {
        let mut doc = json!({
            "bus": job.bus,
            "command": job.action,
            "results": rows.iter().map(|r| {
                Value::Object(r.iter().map(|(k, v)| ((*k).to_owned(), v.clone())).collect())
            }).collect::<Vec<_>>(),
        });
        if let (Some(stats), Some(obj)) = (extra, doc.as_object_mut()) {
            obj.insert("stats".into(), stats);
        }
        output::print_json(&doc)
    } else {
        let mut text = table(&rows);
        if let Some(Value::Object(stats)) = extra {
            for (k, v) in stats {
                let _ = writeln!(text, "{k}: {}", cell(&v));
            }
        }
        output::print(&text)
    }
}

fn connect(bus: &JointBus, id: JointId) -> anyhow::Result<Joint<'_>> {
    bus.joint(id).map_err(whj_error)
}

#[allow(clippy::too_many_lines)] // one arm per subcommand
fn run(bus: &JointBus, job: &WhjJob<'_>, extra: &mut Option<Value>) -> anyhow::Result<Vec<Row>> {
    let e = whj_error;
    let mut rows = Vec::new();
    match job.run {
        WhjRun::Scan(ids) => return scan(bus, ids),
        WhjRun::Info(id) => {
            let j = connect(bus, *id)?;
            let ident = j.identity().map_err(e)?;
            let (min, max) = j.position_limits().map_err(e)?;
            let mode = j.mode().map_err(e)?;
            let mut row = identity_row(*id, &ident);
            row.push(("unique_id", json!(ident.unique_id.to_string())));
            row.push(("mode", json!(mode_name(mode))));
            row.push(("min_deg", json!(min.degrees())));
            row.push(("max_deg", json!(max.degrees())));
            rows.push(row);
        }
        WhjRun::Status(ids) => {
            for &id in ids {
                rows.push(status_row(&connect(bus, id)?)?);
            }
        }
        WhjRun::Enable(ids, on) => {
            for &id in ids {
                let j = connect(bus, id)?;
                if *on { j.enable() } else { j.disable() }.map_err(e)?;
                rows.push(vec![
                    ("joint", json!(id.get())),
                    ("enabled", json!(j.is_enabled().map_err(e)?)),
                ]);
            }
        }
        WhjRun::Mode(ids, mode) => {
            for &id in ids {
                let j = connect(bus, id)?;
                j.set_mode(*mode).map_err(e)?;
                rows.push(vec![
                    ("joint", json!(id.get())),
                    ("mode", json!(mode_name(j.mode().map_err(e)?))),
                ]);
            }
        }
        WhjRun::Move {
            joint,
            degrees,
            max_speed,
            rate_hz,
        } => rows.push(smooth_move(
            bus,
            *joint,
            *degrees,
            *max_speed,
            *rate_hz,
            job.on_stop,
        )?),
        WhjRun::Speed(id, rpm) => {
            let j = connect(bus, *id)?;
            check_demand(&j, WaveLoop::Speed, *rpm, *rpm)?;
            let target = TargetSpeed::from_rpm(*rpm).map_err(|e| anyhow!("{e}"))?;
            let fb = j.command_speed(target).map_err(e)?;
            rows.push(feedback_row(*id, &fb.into(), scale_of(&j)));
        }
        WhjRun::Current(id, ma) => {
            let j = connect(bus, *id)?;
            check_demand(&j, WaveLoop::Current, *ma, *ma)?;
            let fb = j.command_current(*ma).map_err(e)?;
            rows.push(feedback_row(*id, &fb.into(), scale_of(&j)));
        }
        WhjRun::Zero(id) => {
            let j = connect(bus, *id)?;
            j.set_zero().map_err(e)?;
            rows.push(vec![
                ("joint", json!(id.get())),
                ("position_deg", json!(j.position().map_err(e)?.degrees())),
            ]);
        }
        WhjRun::Clear(ids) => {
            for &id in ids {
                let j = connect(bus, id)?;
                let before = j.clear_error().map_err(e)?;
                let after = j.error_code().map_err(e)?;
                rows.push(vec![
                    ("joint", json!(id.get())),
                    ("error_before", json!(before.to_string())),
                    ("error", json!(after.to_string())),
                ]);
            }
        }
        WhjRun::Save(ids) => {
            for &id in ids {
                let j = connect(bus, id)?;
                j.save_to_flash().map_err(e)?;
                rows.push(vec![("joint", json!(id.get())), ("saved", json!(true))]);
            }
        }
        WhjRun::Read {
            joint,
            addr,
            info,
            count,
        } => {
            let j = connect(bus, *joint)?;
            if let (Some(info), None) = (info, count) {
                let v = j.read_register(info.name).map_err(e)?;
                rows.push(register_row(*joint, v.info, v.raw, v.value, v.unit));
            } else {
                let n = count.unwrap_or(1);
                let words = j.read_words(*addr, n).map_err(e)?;
                for (k, w) in (addr.get()..).zip(words) {
                    let name = RegisterAddr::new(k)
                        .ok()
                        .and_then(RegisterInfo::by_addr)
                        .map_or("(reserved)", |i| i.name);
                    rows.push(vec![
                        ("joint", json!(joint.get())),
                        ("addr", json!(format!("0x{k:02X}"))),
                        ("register", json!(name)),
                        ("raw", json!(w)),
                    ]);
                }
            }
        }
        WhjRun::Write {
            joint,
            addr,
            info,
            value,
            raw,
        } => {
            let j = connect(bus, *joint)?;
            if let Some(info) = info {
                if *raw {
                    #[allow(clippy::cast_possible_truncation)] // whole, checked by the plan
                    j.write_register_raw(info.name, value.round() as i32)
                        .map_err(e)?;
                } else {
                    j.write_register(info.name, *value).map_err(e)?;
                }
                let v = j.read_register(info.name).map_err(e)?;
                rows.push(register_row(*joint, v.info, v.raw, v.value, v.unit));
            } else {
                #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
                let word = value.round().clamp(0.0, 65535.0) as u16;
                j.write_word(*addr, word).map_err(e)?;
                let back = j.read_words(*addr, 1).map_err(e)?;
                rows.push(vec![
                    ("joint", json!(joint.get())),
                    ("addr", json!(format!("0x{:02X}", addr.get()))),
                    ("raw", json!(back.first())),
                ]);
            }
        }
        WhjRun::SetId(id, new_id) => {
            let j = connect(bus, *id)?;
            j.disable().map_err(e)?;
            j.write_register_raw("SYS_ID", i32::from(new_id.get()))
                .map_err(e)?;
            j.save_to_flash().map_err(e)?;
            rows.push(vec![
                ("joint", json!(id.get())),
                ("new_id", json!(new_id.get())),
                ("saved", json!(true)),
                (
                    "note",
                    json!("the new ID applies after a power cycle of the joint"),
                ),
            ]);
        }
        WhjRun::Wave(id, wave) => {
            let (row, stats) = run_wave(bus, *id, wave, job.on_stop)?;
            rows.push(row);
            *extra = Some(stats);
        }
        WhjRun::ReleaseIap(ids) => {
            for &id in ids {
                let j = bus.joint_unchecked(id);
                j.release_iap().map_err(e)?;
                let ident = j.identity().map_err(e)?;
                let mut row = identity_row(id, &ident);
                row.push(("released", json!(true)));
                rows.push(row);
            }
        }
    }
    Ok(rows)
}

fn scale_of(j: &Joint<'_>) -> CurrentScale {
    j.identity()
        .map_or(CurrentScale::OneMilliamp, |i| i.current_scale())
}

const fn mode_name(m: WorkMode) -> &'static str {
    match m {
        WorkMode::OpenLoop => "open-loop",
        WorkMode::Current => "current",
        WorkMode::Speed => "speed",
        WorkMode::Position => "position",
        WorkMode::Unknown(_) => "unknown",
    }
}

fn identity_row(id: JointId, ident: &robobus::whj::Identity) -> Row {
    vec![
        ("joint", json!(id.get())),
        ("model", json!(ident.model.name())),
        ("firmware", json!(ident.firmware.to_string())),
        ("node_id", json!(ident.node_id)),
        ("reduction", json!(ident.reduction_ratio)),
    ]
}

fn status_row(j: &Joint<'_>) -> anyhow::Result<Row> {
    let st = j.status().map_err(whj_error)?;
    let mode = j.mode().map_err(whj_error)?;
    let scale = scale_of(j);
    Ok(vec![
        ("joint", json!(j.id().get())),
        ("enabled", json!(st.is_enabled())),
        ("mode", json!(mode_name(mode))),
        ("position_deg", json!(st.position.degrees())),
        ("current_ma", json!(st.current.map(|c| c.milliamps(scale)))),
        ("voltage_v", json!(f64::from(st.voltage.volts()))),
        ("temperature_c", json!(f64::from(st.temperature.celsius()))),
        (
            "brake",
            json!(if st.brake_locked() {
                "locked"
            } else {
                "released"
            }),
        ),
        ("error", json!(st.error.to_string())),
    ])
}

fn feedback_row(id: JointId, fb: &Feedback, scale: CurrentScale) -> Row {
    vec![
        ("joint", json!(id.get())),
        ("enabled", json!(fb.enabled)),
        ("position_deg", json!(fb.position.degrees())),
        ("speed_rpm", json!(fb.speed.rpm())),
        ("current_ma", json!(fb.current.milliamps(scale))),
        ("error", json!(fb.error.to_string())),
    ]
}

fn register_row(
    id: JointId,
    info: &'static RegisterInfo,
    raw: i32,
    value: Option<f64>,
    unit: &str,
) -> Row {
    let name = if info.half == Half::Low {
        info.name.strip_suffix("_L").unwrap_or(info.name)
    } else {
        info.name
    };
    vec![
        ("joint", json!(id.get())),
        ("addr", json!(format!("0x{:02X}", info.addr.get()))),
        ("register", json!(name)),
        ("raw", json!(raw)),
        ("value", json!(value)),
        ("unit", json!(unit)),
    ]
}

fn progress_bar(len: u64, template: &str) -> ProgressBar {
    if !std::io::stderr().is_terminal() {
        return ProgressBar::hidden();
    }
    let pb = ProgressBar::with_draw_target(Some(len), ProgressDrawTarget::stderr());
    if let Ok(style) = ProgressStyle::with_template(template) {
        pb.set_style(style.progress_chars("=> "));
    }
    pb
}

fn scan(bus: &JointBus, ids: &[JointId]) -> anyhow::Result<Vec<Row>> {
    let pb = progress_bar(ids.len() as u64, "scan [{bar:30}] {pos}/{len} {msg}");
    let mut rows = Vec::new();
    for &id in ids {
        pb.set_message(format!("J{}", id.get()));
        match bus.joint(id) {
            Ok(j) => {
                let ident = j.identity().map_err(whj_error)?;
                rows.push(identity_row(id, &ident));
            }
            Err(e) if e.is_timeout() => {}
            Err(e) => return Err(whj_error(e)),
        }
        pb.inc(1);
    }
    pb.finish_and_clear();
    if rows.is_empty() {
        let list: Vec<String> = ids.iter().map(|j| j.get().to_string()).collect();
        return Err(anyhow::Error::new(Timeout(format!(
            "no joint answered on IDs {} (check power, bit rate 1 / 5 Mbit/s, termination, \
             and --bus)",
            list.join(",")
        ))));
    }
    Ok(rows)
}

/// The safe state after an interrupt; the error to return.
fn interrupted(j: &Joint<'_>, on_stop: OnStop, mode: WaveLoop) -> anyhow::Error {
    let result = match on_stop {
        OnStop::Disable => j.disable(),
        OnStop::Hold => match mode {
            WaveLoop::Position => j.position().and_then(|p| j.command_position(p)).map(|_| ()),
            WaveLoop::Speed => j.command_speed(TargetSpeed(0)).map(|_| ()),
            WaveLoop::Current => j.command_current(0.0).map(|_| ()),
        },
    };
    let state = match on_stop {
        OnStop::Disable => "disabled",
        OnStop::Hold => "holding",
    };
    match result {
        Ok(()) => {
            eprintln!("robobus: interrupted; joint {} {state}", j.id().get());
            anyhow::Error::new(Interrupted)
        }
        Err(e) => anyhow::Error::new(Interrupted)
            .context(format!("could not bring the joint to the safe state: {e}")),
    }
}

fn require(j: &Joint<'_>, want: WorkMode, what: &str) -> anyhow::Result<()> {
    let mode = j.mode().map_err(whj_error)?;
    if mode != want {
        return Err(anyhow!(
            "joint {} is in {} mode; {what} needs {} mode: run `robobus whj mode {} {}` first",
            j.id().get(),
            mode_name(mode),
            mode_name(want),
            j.id().get(),
            mode_name(want)
        ));
    }
    if !j.is_enabled().map_err(whj_error)? {
        return Err(anyhow!(
            "joint {} is disabled; run `robobus whj enable {}` first",
            j.id().get(),
            j.id().get()
        ));
    }
    Ok(())
}

/// Checks a motion command against what this joint allows, after connecting and before
/// any servo frame is sent (the CLI's fixed bounds were checked while parsing): angles
/// within its position limits (0x44..0x47), speeds within its model's published peak
/// output speed, currents within its current limit register (0x40, when it holds a
/// value). A refusal is a usage error (exit code 2) naming the value, the joint's bound
/// and where it comes from.
/// `lo..=hi` is the range of values the command asks of the loop `mode`, in its unit
/// (degrees, RPM, mA).
fn check_demand(j: &Joint<'_>, mode: WaveLoop, lo: f64, hi: f64) -> anyhow::Result<()> {
    let id = j.id().get();
    let worst = lo.abs().max(hi.abs());
    match mode {
        WaveLoop::Position => {
            let (min, max) = j.position_limits().map_err(whj_error)?;
            let (min, max) = (min.degrees(), max.degrees());
            if lo < min || hi > max {
                let asked = if lo < min { lo } else { hi };
                return Err(crate::exit::usage(format!(
                    "angle {asked} deg is outside joint {id}'s position limits \
                     {min}..={max} deg (registers 0x44..0x47); nothing sent"
                )));
            }
        }
        WaveLoop::Speed => {
            let model = j.identity().map_err(whj_error)?.model;
            if let Some(peak) = model.peak_output_speed_rpm()
                && worst > peak
            {
                return Err(crate::exit::usage(format!(
                    "speed {worst} RPM is beyond joint {id}'s peak output speed: \
                     -{peak}..={peak} RPM ({model}, product parameters); nothing sent"
                )));
            }
        }
        WaveLoop::Current => {
            let limit = j
                .read_register("LIT_MAX_CURRENT")
                .map_err(whj_error)?
                .value
                .filter(|v| *v > 0.0);
            if let Some(limit) = limit
                && worst > limit
            {
                return Err(crate::exit::usage(format!(
                    "current {worst} mA is beyond joint {id}'s current limit: \
                     -{limit}..={limit} mA (register 0x40 LIT_MAX_CURRENT); nothing sent"
                )));
            }
        }
    }
    Ok(())
}

fn smooth_move(
    bus: &JointBus,
    id: JointId,
    degrees: f64,
    max_speed: f64,
    rate_hz: f64,
    on_stop: OnStop,
) -> anyhow::Result<Row> {
    arm_ctrlc();
    let j = connect(bus, id)?;
    require(&j, WorkMode::Position, "move")?;
    check_demand(&j, WaveLoop::Position, degrees, degrees)?;
    let limits = MotionLimits {
        max_speed_deg_s: max_speed,
        max_accel_deg_s2: (max_speed * 4.0).max(10.0),
        period: Duration::from_secs_f64(1.0 / rate_hz),
        ..MotionLimits::default()
    };
    let start = j.status().map_err(whj_error)?.position.degrees();
    let mut profile = Profile::new(start, limits);
    let dt = limits.period.as_secs_f64();
    let distance = (degrees - start).abs();
    #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)] // <= 72_000
    let pb = progress_bar(
        (distance * 100.0).ceil().max(1.0) as u64,
        "move [{bar:30}] {msg}",
    );
    let began = Instant::now();
    let mut next = began;
    let mut settle: Option<Instant> = None;
    let mut frames = 0u64;
    let fb = loop {
        if crate::interrupt::stop_token().is_stopped() {
            pb.finish_and_clear();
            return Err(interrupted(&j, on_stop, WaveLoop::Position));
        }
        let cmd = profile.step(degrees, dt);
        let target = Position::from_degrees(cmd).map_err(|e| anyhow!("{e}"))?;
        let fb = j.command_position(target).map_err(whj_error)?;
        frames += 1;
        let at = fb.position.degrees();
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        pb.set_position(((distance - (degrees - at).abs()).max(0.0) * 100.0) as u64);
        pb.set_message(format!("{at:.2} deg"));
        if profile.at_rest(degrees) {
            if (at - degrees).abs() <= limits.tolerance_deg {
                break fb;
            }
            let since = *settle.get_or_insert_with(Instant::now);
            if since.elapsed() > limits.settle_timeout {
                pb.finish_and_clear();
                return Err(anyhow!(
                    "joint {}: move to {degrees:.4} deg ended at {at:.4} deg (error code {})",
                    id.get(),
                    fb.error
                ));
            }
        }
        next += limits.period;
        let now = Instant::now();
        if next > now {
            std::thread::sleep(next - now);
        } else {
            next = now;
        }
    };
    pb.finish_and_clear();
    Ok(vec![
        ("joint", json!(id.get())),
        ("from_deg", json!(start)),
        ("target_deg", json!(degrees)),
        ("position_deg", json!(fb.position.degrees())),
        ("frames", json!(frames)),
        ("seconds", json!(began.elapsed().as_secs_f64())),
    ])
}

/// Checks that `j` can run `wave` (enabled in the wave's mode, the values within its own
/// bounds); the servo frame kind the wave sends.
fn wave_ready(j: &Joint<'_>, wave: &Wave) -> anyhow::Result<ServoMode> {
    let (mode, servo) = match wave.mode {
        WaveLoop::Position => (WorkMode::Position, ServoMode::Position),
        WaveLoop::Speed => (WorkMode::Speed, ServoMode::Speed),
        WaveLoop::Current => (WorkMode::Current, ServoMode::Current),
    };
    require(j, mode, "wave")?;
    let (lo, hi) = (wave.offset - wave.amplitude, wave.offset + wave.amplitude);
    check_demand(j, wave.mode, lo, hi)?;
    Ok(servo)
}

fn run_wave(
    bus: &JointBus,
    id: JointId,
    wave: &Wave,
    on_stop: OnStop,
) -> anyhow::Result<(Row, Value)> {
    arm_ctrlc();
    let j = connect(bus, id)?;
    let servo = wave_ready(&j, wave)?;
    let scale = scale_of(&j);
    let period = Duration::from_secs_f64(1.0 / wave.rate_hz);
    let target = |t: f64| -> anyhow::Result<i32> {
        let v = wave.at(t);
        Ok(match wave.mode {
            WaveLoop::Position => Position::from_degrees(v).map_err(|e| anyhow!("{e}"))?.raw(),
            WaveLoop::Speed => TargetSpeed::from_rpm(v).map_err(|e| anyhow!("{e}"))?.raw(),
            WaveLoop::Current => Current::from_milliamps(v, scale)
                .map_err(|e| anyhow!("{e}"))?
                .raw(),
        })
    };
    let cyc = bus
        .cyclic(CyclicConfig {
            joints: vec![id],
            period,
            mode: servo,
            protocol: Protocol::PointToPoint,
            // A square wave becomes steep ramps, never a step past the joint's protection.
            smooth: (wave.mode == WaveLoop::Position).then_some(MotionLimits {
                max_speed_deg_s: 180.0,
                max_accel_deg_s2: 3000.0,
                ..MotionLimits::default()
            }),
        })
        .map_err(whj_error)?;
    let set = |raw: i32| match wave.mode {
        WaveLoop::Position => cyc.set_positions(&[Position(raw)]),
        WaveLoop::Speed => cyc.set_speeds(&[TargetSpeed(raw)]),
        WaveLoop::Current => cyc.set_currents(&[Current(raw)]),
    };
    set(target(0.0)?).map_err(whj_error)?;
    #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)] // <= 600 s * 1000 Hz
    let total = (wave.duration * wave.rate_hz).round() as u64;
    let pb = progress_bar(total, "wave [{bar:30}] {pos}/{len} cycles {msg}");
    let mut start = None;
    let mut previous: Option<i32> = None;
    let (mut err_sq, mut err_max, mut n) = (0.0f64, 0.0f64, 0u64);
    let mut last_fb = None;
    loop {
        if crate::interrupt::stop_token().is_stopped() {
            let _ = cyc.stop();
            pb.finish_and_clear();
            return Err(interrupted(&j, on_stop, wave.mode));
        }
        let Some(report) = cyc.next_report(Duration::from_millis(200)) else {
            continue;
        };
        let t0 = *start.get_or_insert(report.scheduled);
        let t = report.scheduled.duration_since(t0).as_secs_f64();
        if t > wave.duration {
            break;
        }
        pb.set_position(report.cycle.min(total));
        if let Some(Some(fb)) = report.feedback.first() {
            if wave.mode == WaveLoop::Position
                && let Some(prev) = previous
            {
                let e = (fb.position.degrees() - Position(prev).degrees()).abs();
                err_sq += e * e;
                err_max = err_max.max(e);
                n += 1;
            }
            last_fb = Some(*fb);
        }
        previous = report.commanded.first().copied();
        set(target(t + period.as_secs_f64())?).map_err(whj_error)?;
    }
    let stats = cyc.stop();
    pb.finish_and_clear();
    let mut row = match &last_fb {
        Some(fb) => feedback_row(id, fb, scale),
        None => vec![("joint", json!(id.get()))],
    };
    row.insert(1, ("cycles", json!(stats.cycles)));
    #[allow(clippy::cast_precision_loss)]
    let rms = (wave.mode == WaveLoop::Position && n > 0).then(|| (err_sq / n as f64).sqrt());
    let us = |d: Duration| d.as_secs_f64() * 1e6;
    let summary = json!({
        "cycles": stats.cycles,
        "complete": stats.complete,
        "deadline_misses": stats.deadline_misses,
        "missing_replies": stats.missing_replies,
        "round_trip_p50_us": us(stats.round_trip.p50),
        "round_trip_p99_us": us(stats.round_trip.p99),
        "round_trip_max_us": us(stats.round_trip.max),
        "tracking_rms_deg": rms,
        "tracking_max_deg": rms.map(|_| err_max),
    });
    Ok((row, summary))
}

/// One value as table text: floats with 4 decimals, null as `-`.
fn cell(v: &Value) -> String {
    match v {
        Value::Null => "-".to_owned(),
        Value::String(s) => s.clone(),
        Value::Number(n) => n
            .as_f64()
            .filter(|_| n.is_f64())
            .map_or_else(|| n.to_string(), |f| format!("{f:.4}")),
        other => other.to_string(),
    }
}

/// Rows as an aligned table; columns from the first row's keys (and any later new ones).
fn table(rows: &[Row]) -> String {
    let mut cols: Vec<&'static str> = Vec::new();
    for r in rows {
        for (k, _) in r {
            if !cols.contains(k) {
                cols.push(k);
            }
        }
    }
    let cells: Vec<Vec<String>> = rows
        .iter()
        .map(|r| {
            cols.iter()
                .map(|c| {
                    r.iter()
                        .find(|(k, _)| k == c)
                        .map_or_else(String::new, |(_, v)| cell(v))
                })
                .collect()
        })
        .collect();
    let widths: Vec<usize> = cols
        .iter()
        .enumerate()
        .map(|(i, c)| {
            cells
                .iter()
                .filter_map(|r| r.get(i).map(String::len))
                .chain([c.len()])
                .max()
                .unwrap_or(0)
        })
        .collect();
    let mut s = String::new();
    let line = |s: &mut String, items: &mut dyn Iterator<Item = String>| {
        let parts: Vec<String> = items
            .zip(&widths)
            .map(|(t, w)| format!("{t:<w$}"))
            .collect();
        let _ = writeln!(s, "{}", parts.join("  ").trim_end());
    };
    line(&mut s, &mut cols.iter().map(|c| c.to_ascii_uppercase()));
    for r in &cells {
        line(&mut s, &mut r.iter().cloned());
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn waves_have_their_shape() {
        let w = Wave {
            square: false,
            mode: WaveLoop::Position,
            amplitude: 2.0,
            frequency: 1.0,
            offset: 1.0,
            duration: 1.0,
            rate_hz: 100.0,
        };
        assert!((w.at(0.25) - 3.0).abs() < 1e-9);
        assert!((w.at(0.75) + 1.0).abs() < 1e-9);
        let sq = Wave { square: true, ..w };
        assert!((sq.at(0.1) - 3.0).abs() < 1e-9);
        assert!((sq.at(0.6) + 1.0).abs() < 1e-9);
    }

    #[test]
    fn tables_align_columns_and_show_missing_values() {
        let rows = vec![
            vec![("joint", json!(1)), ("error", json!("none"))],
            vec![("joint", json!(12)), ("value", Value::Null)],
        ];
        let t = table(&rows);
        let lines: Vec<&str> = t.lines().collect();
        assert_eq!(lines[0], "JOINT  ERROR  VALUE");
        assert_eq!(lines[1], "1      none");
        assert_eq!(lines[2], "12            -");
    }
}
