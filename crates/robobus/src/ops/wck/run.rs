//! The wCK operations: plans and their execution.

use std::time::{Duration, Instant};

use robobus_link::ByteLink;
use robobus_wck::{BaudRate, Command, Position, Reply, Rotation, ServoId, TorqueLevel, WheelSpeed};
use serde::Serialize;

use super::motion::{Motion, Pose};
use super::plan::{WckPlan, WckStep};
use super::report::{FieldValue, Fields, reply_fields};
use crate::ErrorKind;
use crate::ops::protect::{self, Action, Drive, Fault, Limits, Monitor, Reading};
use crate::ops::safe::WckServos;
use crate::ops::{Control, DeviceResult, Failure, OpError, Progress, SafeState};
use crate::wck::{FoundServo, ScanOptions, WckBus};

/// The position a plan shows for a step whose position is read from the device (a hold).
pub const ASSUMED_POSITION: u8 = 127;

/// How often a timed wheel run reads the servo's status to see that it still answers.
pub const WHEEL_WATCH_PERIOD: Duration = Duration::from_millis(200);

// ----- safe state -----

/// After a stop: the safe state ([`SafeState::apply`]), then [`OpError::Interrupted`]
/// saying what it did.
fn interrupted<L: ByteLink>(
    bus: &mut WckBus<L>,
    ids: &[ServoId],
    state: SafeState,
    torque: TorqueLevel,
) -> OpError {
    state.interrupted(&mut WckServos { bus, ids, torque })
}

// ----- one exchange per step -----

/// One servo's row of a [`StepsReport`].
pub type StepResult = DeviceResult<FieldValue, Fields>;

/// The report of [`run_steps`]: `{"port", "baud", "command", "results": [...]}`, one
/// result per step, `{"id", ...fields}` or `{"id", "kind", "error"}`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StepsReport {
    /// The port.
    pub port: String,
    /// The rate, bit/s.
    pub baud: u32,
    /// The operation (`status`, `move`, ...).
    pub command: &'static str,
    /// One result per step.
    pub results: Vec<StepResult>,
}

/// The target of a command as a field value (`3`, or `all`).
pub fn target_value(command: &Command) -> FieldValue {
    match command.target() {
        robobus_wck::Target::Servo(id) => id.get().into(),
        robobus_wck::Target::Extended(id) => id.get().into(),
        robobus_wck::Target::Broadcast => "all".into(),
    }
}

/// Runs each step of `plan` through [`WckBus::execute`] (retries, read-back, ID / baud
/// verification), in order. A servo that fails is reported and the run carries on with the
/// next (status of many servos shows every one that answered); a link failure (the port is
/// gone) ends the run. Stops between steps when asked (no safe state: each step is one
/// short command).
#[allow(clippy::result_large_err)] // OpError carries the client errors by value
pub fn run_steps<L: ByteLink>(
    bus: &mut WckBus<L>,
    command: &'static str,
    plan: &WckPlan,
    control: &mut Control<'_>,
) -> Result<StepsReport, OpError> {
    let results = run_steps_with(bus, command, plan, control, target_value, |c, reply| {
        Ok(reply_fields(c, reply))
    })?;
    Ok(StepsReport {
        port: bus.device().to_string(),
        baud: bus.baud().bits_per_second(),
        command,
        results,
    })
}

/// [`run_steps`] with each result's ID and row made by the caller: `id` from the step's
/// command, `row` from the command and its reply (a row it cannot make of that reply is
/// the servo's failure).
#[allow(clippy::result_large_err)] // OpError carries the client errors by value
pub fn run_steps_with<L: ByteLink, I, T>(
    bus: &mut WckBus<L>,
    command: &'static str,
    plan: &WckPlan,
    control: &mut Control<'_>,
    id: impl Fn(&Command) -> I,
    mut row: impl FnMut(&Command, Option<Reply>) -> Result<T, Failure>,
) -> Result<Vec<DeviceResult<I, T>>, OpError> {
    let mut results = Vec::with_capacity(plan.steps.len());
    let total = plan.steps.len() as u64;
    for (n, step) in plan.steps.iter().enumerate() {
        if control.stopped() {
            return Err(OpError::Interrupted { detail: None });
        }
        if let Some(b) = step.baud {
            bus.set_host_baud(b)?;
        }
        let id = id(&step.command);
        match bus.execute(&step.command) {
            Ok(reply) => results.push(match row(&step.command, reply) {
                Ok(r) => DeviceResult::ok(id, r),
                Err(f) => DeviceResult::failed(id, f),
            }),
            Err(e) if e.kind() == ErrorKind::Link => return Err(e.into()),
            Err(e) => results.push(DeviceResult::failed(id, Failure::from(&e))),
        }
        control.report(&Progress::new(command, n as u64 + 1, Some(total)));
    }
    Ok(results)
}

/// How many equal replies a read of `plan` needs ([`crate::wck::WckConfig::confirm_reads`]):
/// with `verify` unset, 2 when the plan is one-shot parameter reads (gains, I gain, speed,
/// over-load, bounds, I/O: a wrong value there would be believed and copied), otherwise 1;
/// `Some(true)` 2 for every read, `Some(false)` 1. A confirmed read costs one more exchange
/// (about 1.5 ms at 115200 bit/s) and retries until two replies agree.
pub fn confirm_reads_for(plan: &WckPlan, verify: Option<bool>) -> u8 {
    let parameter_read = |c: &Command| {
        matches!(
            c,
            Command::GainRead { .. }
                | Command::IGainRead { .. }
                | Command::SpeedRead { .. }
                | Command::OverloadRead { .. }
                | Command::BoundaryRead { .. }
                | Command::IoRead { .. }
        )
    };
    let verify = verify.unwrap_or_else(|| {
        !plan.steps.is_empty() && plan.steps.iter().all(|s| parameter_read(&s.command))
    });
    if verify { 2 } else { 1 }
}

// ----- scan -----

/// What to scan (the command's IDs and rates).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ScanArgs {
    /// The IDs, in order.
    pub ids: Vec<ServoId>,
    /// The rates, in order.
    pub bauds: Vec<BaudRate>,
    /// Status reads per ID before it counts as absent.
    pub probes: u32,
}

impl ScanArgs {
    /// `ids` at one rate, or at every rate (slowest first, as the CLI lists them).
    pub fn new(ids: Vec<ServoId>, baud: BaudRate, all_bauds: bool) -> Self {
        Self {
            ids,
            bauds: if all_bauds {
                BaudRate::ALL.to_vec()
            } else {
                vec![baud]
            },
            probes: ScanOptions::default().probes,
        }
    }

    /// The plan of the scan if the IDs for which `answers(baud, id)` holds answer cleanly
    /// and the others stay silent: a silent ID is read `probes` times; an ID that answers
    /// is read once and then three more ways (10-bit position, I gain, over-load) to rule
    /// out two modules sharing it; right after a silent ID it is read once more first (that
    /// first answer may be the silent ID's late reply, so it is not credited: the ID is
    /// asked again once the late window has passed). The dry-run assumes that nobody
    /// answers; the real run
    /// sends this plan for the servos it found (plus repeats where replies were garbled,
    /// and the further probes that confirm a suspected duplicate).
    pub fn plan(&self, answers: &dyn Fn(BaudRate, ServoId) -> bool) -> WckPlan {
        let mut plan = WckPlan::default();
        plan.notes.push(format!(
            "a status read per ID, {} times if it stays silent; an ID that answers is then \
             read three more ways (10-bit position, I gain, over-load) to rule out a shared ID",
            self.probes.max(1)
        ));
        let mut after_silent = false;
        for &baud in &self.bauds {
            for &id in &self.ids {
                let step = |command| WckStep {
                    at_ms: None,
                    baud: (self.bauds.len() > 1).then_some(baud),
                    command,
                };
                let answering = answers(baud, id);
                if answering && after_silent {
                    plan.steps.push(step(Command::StatusRead { id }));
                }
                after_silent = !answering;
                if answering {
                    plan.steps.push(step(Command::StatusRead { id }));
                    plan.steps.push(step(Command::Read10 { id: id.into() }));
                    plan.steps.push(step(Command::IGainRead { id }));
                    plan.steps.push(step(Command::OverloadRead { id }));
                } else {
                    for _ in 0..self.probes.max(1) {
                        plan.steps.push(step(Command::StatusRead { id }));
                    }
                }
            }
        }
        plan
    }
}

/// A servo found by [`scan`].
#[derive(Debug, Clone, PartialEq, Serialize, schemars::JsonSchema)]
pub struct Found {
    /// Its ID.
    pub id: u8,
    /// Its rate, bit/s.
    pub baud: u32,
    /// Its load when probed.
    pub load: u8,
    /// Its position when probed, 0..=254.
    pub position: u8,
    /// The same in degrees.
    pub degrees: f64,
}

impl From<&FoundServo> for Found {
    fn from(f: &FoundServo) -> Self {
        Self {
            id: f.id.get(),
            baud: f.baud.bits_per_second(),
            load: f.status.load.get(),
            position: f.status.position.get(),
            degrees: (f.status.position.degrees() * 100.0).round() / 100.0,
        }
    }
}

/// An ID answered by more than one module (confirmed by repeated probes).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, schemars::JsonSchema)]
pub struct SharedId {
    /// The ID.
    pub id: u8,
    /// The rate, bit/s.
    pub baud: u32,
    /// What the probes showed.
    pub evidence: String,
}

/// The report of [`scan`]: `{"port", "bauds_tried", "found": [{"id", "baud", "load",
/// "position", "degrees"}], "duplicates": [{"id", "baud", "evidence"}]}`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ScanOpReport {
    /// The port.
    pub port: String,
    /// The rates tried, bit/s.
    pub bauds_tried: Vec<u32>,
    /// The servos found, by rate and ID.
    pub found: Vec<Found>,
    /// IDs answered by more than one module.
    pub duplicates: Vec<SharedId>,
    /// Set when the scan was stopped before its last ID (`found` holds what it found
    /// until then): how far it got.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub stopped: Option<String>,
}

impl ScanOpReport {
    /// Whether nothing answered.
    pub fn is_empty(&self) -> bool {
        self.found.is_empty() && self.duplicates.is_empty()
    }
}

/// Scans `args` ID by ID ([`WckBus::scan`] on each: status reads, duplicate check with
/// confirmation), reporting progress after each ID and stopping between IDs when asked.
/// Restores the bus's rate.
#[allow(clippy::result_large_err)] // OpError carries the client errors by value
pub fn scan<L: ByteLink>(
    bus: &mut WckBus<L>,
    args: &ScanArgs,
    control: &mut Control<'_>,
) -> Result<ScanOpReport, OpError> {
    let original = bus.baud();
    let total = (args.bauds.len() * args.ids.len()) as u64;
    let mut found: Vec<FoundServo> = Vec::new();
    let mut duplicates = Vec::new();
    let mut done = 0;
    let mut stopped = None;
    let result = (|| {
        for &baud in &args.bauds {
            bus.set_host_baud(baud)?;
            for &id in &args.ids {
                if control.stopped() {
                    stopped = Some(format!("scan stopped after {done} of {total} probes"));
                    return Ok::<(), OpError>(());
                }
                let options = ScanOptions {
                    bauds: Vec::new(),
                    ids: id.get()..=id.get(),
                    probes: args.probes,
                    ..ScanOptions::default()
                };
                let part = bus.scan(&options, |_| {})?;
                found.extend(part.found);
                duplicates.extend(part.duplicates.iter().map(|d| SharedId {
                    id: d.id.get(),
                    baud: d.baud.bits_per_second(),
                    evidence: d.evidence.clone(),
                }));
                done += 1;
                control.report(&Progress::new("scan", done, Some(total)).with_note(format!(
                    "{} bit/s, ID {id}: {} found",
                    baud.bits_per_second(),
                    found.len() + duplicates.len()
                )));
            }
        }
        Ok(())
    })();
    let restored = bus.set_host_baud(original);
    result?;
    restored?;
    found.sort_by_key(|f| (f.baud, f.id));
    Ok(ScanOpReport {
        port: bus.device().to_string(),
        bauds_tried: args.bauds.iter().map(|b| b.bits_per_second()).collect(),
        found: found.iter().map(Found::from).collect(),
        duplicates,
        stopped,
    })
}

// ----- timed runs -----

/// Runs a timed plan: each step at its time (a step without one right after the previous),
/// stopping on the caller's token (then `ids` go to `state`). A step marked as taking its
/// position from the device (a hold) is sent with the position the last status reply
/// reported. Each reply goes to `on_reply` with the instant it came (the bus's clock); a
/// host protection stop it returns ends the run: `ids` to the protection's safe state
/// ([`protection_state`]), the error naming the fault.
#[allow(clippy::result_large_err)] // OpError carries the client errors by value
fn run_timed<L: ByteLink>(
    bus: &mut WckBus<L>,
    steps: impl IntoIterator<Item = WckStep>,
    stage: &'static str,
    total_ms: u64,
    stop: (&[ServoId], SafeState, TorqueLevel),
    control: &mut Control<'_>,
    mut on_reply: impl FnMut(&WckStep, Option<Reply>, Instant) -> Option<Fault>,
) -> Result<Instant, OpError> {
    let start = bus.now();
    let mut last_position: Option<Position> = None;
    // A step without a time goes right after the one before (and counts as its time).
    let mut at_ms = 0;
    for mut step in steps {
        at_ms = step.at_ms.unwrap_or(at_ms);
        let due = start + Duration::from_millis(step.at_ms.unwrap_or(0));
        if !control.sleep_on(bus.link_mut(), due) {
            return Err(interrupted(bus, stop.0, stop.1, stop.2));
        }
        if let (Command::Move { position, .. }, Some(p)) = (&mut step.command, last_position)
            && step.at_ms.is_none()
        {
            *position = p;
        }
        let reply = match bus.execute(&step.command) {
            Ok(r) => r,
            Err(e) => {
                // The device stopped answering (or the port went away): stop the others.
                let _ = stop.1.apply(&mut WckServos {
                    bus,
                    ids: stop.0,
                    torque: stop.2,
                });
                return Err(e.into());
            }
        };
        if let Some(Reply::Status { position, .. }) = reply {
            last_position = Some(position);
        }
        if let Some(fault) = on_reply(&step, reply, bus.now()) {
            let safe = protection_state(stop.1);
            let failed = safe.apply(&mut WckServos {
                bus,
                ids: stop.0,
                torque: stop.2,
            });
            let mut text = format!(
                "{fault}; the {stage} stopped at {at_ms} ms, servo(s) {} {}",
                crate::ops::ids_text(stop.0),
                safe.keyword()
            );
            for f in failed {
                let _ = std::fmt::Write::write_fmt(
                    &mut text,
                    format_args!(" (not reached: {})", f.error),
                );
            }
            return Err(OpError::Device(text));
        }
        control.report(&Progress::new(stage, at_ms, Some(total_ms)));
    }
    Ok(start)
}

/// The safe state a host protection stop brings wCK servos to: the run's own when it
/// releases them (passive, or the bus-wide break), else passive: a servo held at its
/// torque keeps pushing into what stopped it.
pub(super) const fn protection_state(on_stop: SafeState) -> SafeState {
    match on_stop {
        SafeState::Break => SafeState::Break,
        SafeState::Passive | SafeState::Hold | SafeState::Disable => SafeState::Passive,
    }
}

/// Logs `faults` (a wCK servo has no temperature: its events are stops, never warnings or
/// derating to report): the stop, if one.
fn keep_events(faults: Vec<Fault>) -> Option<Fault> {
    let mut stop = None;
    for f in faults {
        tracing::warn!("{f}");
        if f.action == Action::Stop {
            stop = Some(f);
        }
    }
    stop
}

/// A wCK status reply as a protection reading at `at`: its position and load (as a
/// current); against `target` (steps) when one was sent.
fn wck_reading(at: Instant, load: u8, position: Position, target: Option<Position>) -> Reading {
    let p = position.degrees();
    let t = target.map(Position::degrees);
    Reading {
        position_deg: Some(p),
        error_deg: t.map(|t| (p - t).abs()),
        target_deg: t,
        current_a: Some(protect::wck_load_a(load)),
        ..Reading::at(at)
    }
}

/// Arguments of a wheel run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct WheelArgs {
    /// The servo.
    pub id: ServoId,
    /// Direction.
    pub rotation: Rotation,
    /// Speed 0..=15.
    pub speed: WheelSpeed,
    /// Turn this long, then stop per `on_stop`; `None` = leave it turning.
    pub duration: Option<Duration>,
    /// How it stops (after the duration, on a stop, when it stops answering).
    pub on_stop: SafeState,
}

/// The torque of a hold after a wheel run.
const WHEEL_HOLD_TORQUE: TorqueLevel = TorqueLevel::MIN;

impl WheelArgs {
    /// The plan: the wheel command at 0; with a duration, a status read every
    /// [`WHEEL_WATCH_PERIOD`] (the run ends early, in the safe state, when the servo stops
    /// answering), then the stop at the end: a passive command, the bus-wide break, or
    /// (hold) a status read and a position move to the position it reports (the plan shows
    /// [`ASSUMED_POSITION`]).
    pub fn plan(&self) -> WckPlan {
        let wheel = Command::Wheel {
            id: self.id,
            rotation: self.rotation,
            speed: self.speed,
        };
        let Some(d) = self.duration else {
            return WckPlan::one(wheel);
        };
        let id = self.id;
        let mut plan = WckPlan::default();
        let end = u64::try_from(d.as_millis()).unwrap_or(u64::MAX);
        let period = u64::try_from(WHEEL_WATCH_PERIOD.as_millis()).unwrap_or(200);
        plan.notes.push(format!(
            "wheel for {} s, a status read every {period} ms to see that the servo still \
             answers, then {}",
            d.as_secs_f64(),
            self.on_stop.keyword()
        ));
        plan.steps.push(WckStep::at(0, wheel));
        let mut t = period;
        while t < end {
            plan.steps.push(WckStep::at(t, Command::StatusRead { id }));
            t += period;
        }
        match self.on_stop {
            SafeState::Break => plan.steps.push(WckStep::at(end, Command::Break)),
            SafeState::Passive | SafeState::Disable => {
                plan.steps.push(WckStep::at(end, Command::Passive { id }));
            }
            SafeState::Hold => {
                plan.notes.push(format!(
                    "hold: a position move to the position the last status read reports \
                     (assumed {ASSUMED_POSITION} here)"
                ));
                plan.steps
                    .push(WckStep::at(end, Command::StatusRead { id }));
                plan.steps.push(WckStep::now(Command::Move {
                    id,
                    torque: WHEEL_HOLD_TORQUE,
                    position: Position::new(ASSUMED_POSITION).unwrap_or(Position::MIN),
                }));
            }
        }
        plan.notes
            .push("then a status read: where the shaft came to rest".into());
        plan.steps.push(WckStep::now(Command::StatusRead { id }));
        plan
    }
}

/// What a wheel `speed` (0..=15) in `rotation` is at least worth, °/s (counter-clockwise
/// positive): its share of the slowest wCK model's no-load speed (the module does not say
/// its model).
pub(super) fn wheel_deg_s(rotation: Rotation, speed: WheelSpeed) -> f64 {
    let v = f64::from(speed.get()) / 15.0 * robobus_wck::models::slowest_no_load_speed_dps();
    if rotation == Rotation::Ccw { v } else { -v }
}

/// A wheel's speed between two status reads, °/s; `None` where a reading is at the end
/// of the potentiometer's range (0 or 254 steps: the shaft may be anywhere in the 91°
/// past it) and they differ.
pub(super) fn wheel_speed(before: (Instant, Position), now: (Instant, Position)) -> Option<f64> {
    let dt = now.0.saturating_duration_since(before.0).as_secs_f64();
    let edge = |p: Position| p == Position::MIN || p == Position::MAX;
    if dt <= 0.0 || (before.1 != now.1 && (edge(before.1) || edge(now.1))) {
        return None;
    }
    Some((now.1.degrees() - before.1.degrees()) / dt)
}

/// The report of [`wheel`]: the wheel command's fields, and for a timed run `ran_ms`,
/// `stopped` (the safe state applied at the end) and `stopped_at` / `stopped_load` (a
/// status read after it).
pub type WheelReport = StepResult;

/// Wheel mode; with a duration, the timed plan of [`WheelArgs::plan`].
#[allow(clippy::result_large_err)] // OpError carries the client errors by value
pub fn wheel<L: ByteLink>(
    bus: &mut WckBus<L>,
    args: &WheelArgs,
    control: &mut Control<'_>,
) -> Result<WheelReport, OpError> {
    let plan = args.plan();
    let total = args
        .duration
        .map_or(0, |d| u64::try_from(d.as_millis()).unwrap_or(u64::MAX));
    let mut first: Option<Fields> = None;
    let mut rest: Option<Fields> = None;
    let mut monitor = Monitor::new(
        bus.now(),
        vec![(
            format!("servo {}", args.id.get()),
            Limits::wck().for_reading_period(WHEEL_WATCH_PERIOD),
        )],
    );
    let drive = Drive::Velocity {
        commanded_deg_s: wheel_deg_s(args.rotation, args.speed),
    };
    let mut last: Option<(Instant, Position)> = None;
    let mut turning = true;
    let start = run_timed(
        bus,
        plan.steps,
        "wheel",
        total,
        (&[args.id], args.on_stop, WHEEL_HOLD_TORQUE),
        control,
        |step, reply, at| {
            if first.is_none() {
                first = Some(reply_fields(&step.command, reply));
                // Where the wheel started: the first read's speed is measured from it.
                if let Some(Reply::Wheel { position, .. }) = reply {
                    last = Some((at, position));
                }
            } else if matches!(step.command, Command::StatusRead { .. }) {
                rest = Some(reply_fields(&step.command, reply));
            } else {
                // The stop at the end: no longer driven.
                turning = false;
            }
            let (true, Command::StatusRead { .. }, Some(Reply::Status { load, position })) =
                (turning, &step.command, reply)
            else {
                return None;
            };
            let speed = last.and_then(|l| wheel_speed(l, (at, position)));
            last = Some((at, position));
            let reading = wck_reading(at, load.get(), position, None);
            keep_events(monitor.feed_driven(0, &reading, speed, drive))
        },
    )?;
    let mut row = first.unwrap_or_default();
    if args.duration.is_some() {
        row.push(
            "ran_ms",
            u64::try_from(bus.now().saturating_duration_since(start).as_millis())
                .unwrap_or(u64::MAX),
        );
        row.push("stopped", args.on_stop.keyword());
        // Where the shaft came to rest: the plan's last status read, after the safe
        // state, not the wheel command's reply (the position before the run).
        let rest = rest.unwrap_or_default();
        for (key, name) in [("position", "stopped_at"), ("load", "stopped_load")] {
            if let Some(v) = rest.get(key) {
                row.push(name, v.clone());
            }
        }
    }
    Ok(DeviceResult::ok(args.id.get().into(), row))
}

/// The report of [`play`]: `{"port", "command": "play", "moves", "sent", "planned_ms",
/// "duration_ms", "last_positions"}`.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, schemars::JsonSchema)]
pub struct PlayReport {
    /// The port.
    pub port: String,
    /// Always `play`.
    pub command: &'static str,
    /// Synchronized moves sent.
    pub moves: u64,
    /// Packets sent: the moves and the watch reads ([`PLAY_WATCH_MS`](super::PLAY_WATCH_MS)).
    pub sent: u64,
    /// Status reads that watched the servos while the motion played (each answered: a
    /// servo that does not answer ends the run in the safe state, with an error).
    pub watch_reads: u64,
    /// When the last move was due, ms.
    pub planned_ms: u64,
    /// How long the run took, ms.
    pub duration_ms: u64,
    /// The last pose sent.
    pub last_positions: Vec<u8>,
}

/// Plays `motion` at `rate_hz` (0.1..=200): the moves of [`Motion::moves`], streamed, each
/// at its time, with a status read of one servo every [`PLAY_WATCH_MS`](super::PLAY_WATCH_MS)
/// (moves have no reply). On a stop, or when a watched servo does not answer, servos 0..n
/// go to `on_stop` (hold at the motion's torque); the silent servo is the error.
#[allow(clippy::result_large_err)] // OpError carries the client errors by value
pub fn play<L: ByteLink>(
    bus: &mut WckBus<L>,
    motion: &Motion,
    rate_hz: f64,
    on_stop: SafeState,
    control: &mut Control<'_>,
) -> Result<PlayReport, OpError> {
    check_rate(rate_hz, "--rate-hz")?;
    let ids: Vec<ServoId> = (0..motion.servos())
        .filter_map(|i| u8::try_from(i).ok().and_then(|i| ServoId::new(i).ok()))
        .collect();
    let total = motion.end_ms();
    let (mut sent, mut moves, mut planned, mut last) = (0u64, 0u64, 0u64, Vec::new());
    // Each servo is read every PLAY_WATCH_MS × servos (round robin).
    let period = Duration::from_millis(super::PLAY_WATCH_MS)
        * u32::try_from(ids.len().max(1)).unwrap_or(u32::MAX);
    let mut monitor = Monitor::new(
        bus.now(),
        ids.iter()
            .map(|id| {
                (
                    format!("servo {}", id.get()),
                    Limits::wck().for_reading_period(period),
                )
            })
            .collect(),
    );
    // The targets of the move before the last (a status read follows a move at once:
    // the servo has had a period to follow the one before it, not the last one).
    let (mut before, mut latest): (Vec<Position>, Vec<Position>) = (Vec::new(), Vec::new());
    let start = run_timed(
        bus,
        motion.moves(rate_hz),
        "play",
        total,
        (&ids, on_stop, motion.torque),
        control,
        |step, reply, at| {
            sent += 1;
            planned = planned.max(step.at_ms.unwrap_or(0));
            match (&step.command, reply) {
                (Command::SyncMove(s), _) => {
                    moves += 1;
                    last = s.positions().iter().map(|p| p.get()).collect();
                    before = std::mem::replace(&mut latest, s.positions().to_vec());
                    None
                }
                (Command::StatusRead { id }, Some(Reply::Status { load, position })) => {
                    let i = usize::from(id.get());
                    let target = before.get(i).or_else(|| latest.get(i)).copied();
                    let reading = wck_reading(at, load.get(), position, target);
                    keep_events(monitor.feed(i, &reading))
                }
                _ => None,
            }
        },
    )?;
    Ok(PlayReport {
        port: bus.device().to_string(),
        command: "play",
        moves,
        sent,
        watch_reads: sent - moves,
        planned_ms: planned,
        duration_ms: u64::try_from(bus.now().saturating_duration_since(start).as_millis())
            .unwrap_or(u64::MAX),
        last_positions: last,
    })
}

/// A rate in Hz, 0.1..=200.
#[allow(clippy::result_large_err)] // OpError carries the client errors by value
pub fn check_rate(rate_hz: f64, option: &str) -> Result<(), OpError> {
    if (0.1..=200.0).contains(&rate_hz) {
        Ok(())
    } else {
        Err(OpError::invalid(option, rate_hz, "allowed: 0.1..=200 Hz"))
    }
}

// ----- teach -----

/// When `teach` records a pose.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TeachTrigger {
    /// At a rate (0.1..=200 Hz), for a time or until the caller says [`TeachEvent::Finish`].
    Rate {
        /// Poses per second.
        rate_hz: f64,
        /// How long; `None` = until finished.
        duration: Option<Duration>,
    },
    /// One pose per [`TeachEvent::Record`], each with this transition time (ms).
    Events {
        /// The transition time written for each pose.
        pose_ms: u32,
    },
}

/// What the caller of [`teach`] says when asked (a key press, a web request...).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TeachEvent {
    /// Record a pose now.
    Record,
    /// End the recording.
    Finish,
    /// Nothing yet.
    Nothing,
}

/// Arguments of [`teach`].
#[derive(Debug, Clone, PartialEq)]
pub struct TeachArgs {
    /// Servos 0..n-1 (a pose lists servos 0, 1, ... in order).
    pub ids: Vec<ServoId>,
    /// When to record.
    pub trigger: TeachTrigger,
    /// Torque written into the file (and of a hold at the end).
    pub torque: TorqueLevel,
    /// What the servos do when recording ends (they are passive while it runs).
    pub on_stop: SafeState,
}

impl TeachArgs {
    /// Checks that the IDs are 0..n-1 and the rate is in range.
    #[allow(clippy::result_large_err)] // OpError carries the client errors by value
    pub fn check(&self) -> Result<(), OpError> {
        let contiguous = self
            .ids
            .iter()
            .enumerate()
            .all(|(i, id)| usize::from(id.get()) == i);
        if !contiguous || self.ids.is_empty() {
            let given: Vec<String> = self.ids.iter().map(ToString::to_string).collect();
            return Err(OpError::invalid(
                "teach <IDS>",
                format!("servo(s) {}", given.join(",")),
                "a keyframe file lists servos 0, 1, 2, ... in order, so teach records \
                 servos 0..N-1 (e.g. `0-5`)",
            ));
        }
        if let TeachTrigger::Rate { rate_hz, .. } = self.trigger {
            check_rate(rate_hz, "--rate-hz")?;
        }
        Ok(())
    }

    /// The plan: a passive command per servo (its reply is the position recorded),
    /// repeated per pose.
    pub fn plan(&self) -> WckPlan {
        let mut plan = WckPlan::default();
        for &id in &self.ids {
            plan.push(Command::Passive { id });
        }
        let when = match self.trigger {
            TeachTrigger::Events { .. } => {
                "once per Enter until q / end of input / Ctrl-C".to_string()
            }
            TeachTrigger::Rate {
                rate_hz,
                duration: None,
            } => format!("{rate_hz} times per second until Enter / Ctrl-C"),
            TeachTrigger::Rate {
                rate_hz,
                duration: Some(d),
            } => format!("{rate_hz} times per second for {} s", d.as_secs_f64()),
        };
        plan.notes.push(format!(
            "teach: the passive round below repeats {when}; each reply's position is recorded"
        ));
        plan
    }
}

/// The report of [`teach`]: how many poses were recorded.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct TeachReport {
    /// Poses recorded (each handed to the caller's `on_pose` as it was recorded).
    pub poses: u64,
}

/// One passive round: the positions of `ids`, in order.
#[allow(clippy::result_large_err)] // OpError carries the client errors by value
fn read_pose<L: ByteLink>(bus: &mut WckBus<L>, ids: &[ServoId]) -> Result<Vec<Position>, OpError> {
    let mut pose = Vec::with_capacity(ids.len());
    for &id in ids {
        pose.push(bus.servo(id).passive()?);
    }
    Ok(pose)
}

/// Records poses: every servo goes passive (the first round is the first pose), then a
/// pose per trigger. Each pose goes to `on_pose` as soon as it is recorded (so a file
/// written there keeps every pose however the recording ends); the library keeps none.
/// `events` is asked, with the longest time it may wait, whether to record or finish.
/// At the end the servos go to `on_stop` (they are passive already); on a stop, too, and
/// the result is [`OpError::Interrupted`].
#[allow(clippy::result_large_err)] // OpError carries the client errors by value
pub fn teach<L: ByteLink>(
    bus: &mut WckBus<L>,
    args: &TeachArgs,
    control: &mut Control<'_>,
    events: &mut dyn FnMut(Duration) -> TeachEvent,
    on_pose: &mut dyn FnMut(&Pose) -> Result<(), OpError>,
) -> Result<TeachReport, OpError> {
    args.check()?;
    let ids = &args.ids;
    let mut count = 0u64;
    let mut record = |bus: &mut WckBus<L>, ms: u32, control: &mut Control<'_>| {
        let pose = Pose {
            ms,
            positions: read_pose(bus, ids)?,
        };
        on_pose(&pose)?;
        count += 1;
        control.report(&Progress::new("teach", count, None));
        Ok::<(), OpError>(())
    };
    let stop = |bus: &mut WckBus<L>| interrupted(bus, ids, args.on_stop, args.torque);
    match args.trigger {
        TeachTrigger::Rate { rate_hz, duration } => {
            let period = Duration::from_secs_f64(1.0 / rate_hz);
            #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)] // 5..=10000 ms
            let period_ms = (1000.0 / rate_hz).round() as u32;
            let start = bus.now();
            record(bus, period_ms, control)?;
            let mut next = start + period;
            loop {
                // Wait for the next pose, looking at the caller's events meanwhile.
                loop {
                    if control.stopped() {
                        return Err(stop(bus));
                    }
                    let now = bus.now();
                    if now >= next {
                        break;
                    }
                    let wait = (next - now).min(Duration::from_millis(20));
                    let event = events(wait);
                    if control.stopped() {
                        return Err(stop(bus));
                    }
                    if event == TeachEvent::Finish {
                        return finish(bus, args, count);
                    }
                    // `events` waited on the wall clock; the link's own clock (a
                    // simulator's) moves only when waited on.
                    bus.sleep_until(now + wait);
                }
                if duration.is_some_and(|d| bus.now().saturating_duration_since(start) >= d) {
                    return finish(bus, args, count);
                }
                record(bus, period_ms, control)?;
                next += period;
            }
        }
        TeachTrigger::Events { pose_ms } => {
            record(bus, pose_ms, control)?;
            loop {
                if control.stopped() {
                    return Err(stop(bus));
                }
                let event = events(Duration::from_millis(50));
                if control.stopped() {
                    return Err(stop(bus));
                }
                match event {
                    TeachEvent::Record => record(bus, pose_ms, control)?,
                    TeachEvent::Finish => return finish(bus, args, count),
                    TeachEvent::Nothing => {}
                }
            }
        }
    }
}

#[allow(clippy::result_large_err)] // OpError carries the client errors by value
fn finish<L: ByteLink>(
    bus: &mut WckBus<L>,
    args: &TeachArgs,
    poses: u64,
) -> Result<TeachReport, OpError> {
    if !matches!(args.on_stop, SafeState::Passive | SafeState::Disable) {
        let failed = args.on_stop.apply(&mut WckServos {
            bus,
            ids: &args.ids,
            torque: args.torque,
        });
        if let Some(f) = failed.into_iter().next() {
            return Err(f.error);
        }
    }
    Ok(TeachReport { poses })
}
