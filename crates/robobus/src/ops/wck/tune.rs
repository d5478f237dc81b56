//! Guided gain tuning of one wCK servo: the same position step with each of several
//! runtime gain sets, the response recorded and measured, the best kept on request.
//!
//! For each gain set, in the order given: the servo is brought back to the start
//! position and waited for until it is at rest there, the runtime P and D gains are set
//! (A-1 (12), effective at once, lost at power-off), then the step is commanded and the position read as fast as the bus
//! allows for the hold time, on the bus's clock (the simulator's virtual clock, or the
//! wall clock on a real port). The start is where the servo was found; the step goes
//! away from the nearer boundary and must stay within the servo's boundaries, or nothing
//! is sent.
//!
//! Figures of merit per set, from the response `y` (position minus start, in the step's
//! direction) against the step `A`:
//!
//! - rise time: from the first reading at 10 % of `A` to the first at 90 %;
//! - overshoot: the largest `y` beyond `A`, in % of `A`;
//! - settling time: from the step until `y` stays within the band (2 % of `A`, at least
//!   one position step: the servo's resolution) to the end of the hold; `None` if it
//!   never does;
//! - steady-state error: the mean of the last 10 % of the readings minus `A`, in steps.
//!
//! The best set settles soonest (one that never settles is worst); equal settling times
//! go to the smaller overshoot. Sets whose responses do not differ from the first place
//! by more than the measurement's resolution (the interval between two readings in
//! settling time, one position step in overshoot) are a tie, and no set is named best.
//!
//! Every step starts from the same state: before it the servo is brought back to the
//! start with the gains of its EEPROM (the gains it has after a power-up: wCK cannot
//! report its runtime gains) and waited for until it reads the start for [`AT_REST`]
//! (at most [`RETURN_LIMIT`]); only then are the set's gains written and the step
//! commanded, so identical gains give identical responses on the simulator. The same
//! return ends the run, before [`tune`] returns, and the runtime gains stay the EEPROM's
//! unless the best set is kept (a tie keeps the first tied set, in the order given): in
//! runtime, or in EEPROM.

use std::time::{Duration, Instant};

use robobus_link::ByteLink;
use robobus_wck::{DGain, PGain, Position, ServoId, TorqueLevel};
use serde::Serialize;

use crate::ops::safe::WckServos;
use crate::ops::{Control, OpError, Progress, SafeState};
use crate::wck::{Gains, WckBus};

/// The most gain sets one run compares.
pub const MAX_GAIN_SETS: usize = 8;
/// The hold times a step takes, ms.
pub const HOLD_MS: std::ops::RangeInclusive<u32> = 100..=5000;
/// The step sizes allowed, position steps.
pub const AMPLITUDE_STEPS: std::ops::RangeInclusive<u8> = 2..=60;
/// How long the servo must read its start position, reading after reading, to count as
/// back and at rest there (before each step, and before [`tune`] returns).
pub const AT_REST: Duration = Duration::from_millis(300);
/// The longest the servo is waited for to come back to its start: past this, the run
/// fails saying where it is.
pub const RETURN_LIMIT: Duration = Duration::from_secs(3);

/// What to do with the best gain set.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, schemars::JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum Keep {
    /// Nothing: the runtime gains go back to the EEPROM's.
    #[default]
    None,
    /// Keep it as the runtime gains (until power-off).
    Runtime,
    /// Write it to EEPROM (needs confirmation).
    Eeprom,
}

/// Arguments of [`tune`].
#[derive(Debug, Clone, PartialEq)]
pub struct TuneArgs {
    /// The servo.
    pub id: ServoId,
    /// The step, position steps ([`AMPLITUDE_STEPS`]).
    pub amplitude: u8,
    /// The gain sets to compare, 1..=[`MAX_GAIN_SETS`].
    pub gains: Vec<Gains>,
    /// How long each step is recorded, ms ([`HOLD_MS`]).
    pub hold_ms: u32,
    /// The torque level of the moves.
    pub torque: TorqueLevel,
    /// What to do with the best set.
    pub keep: Keep,
}

impl TuneArgs {
    /// Checks the arguments (nothing is sent).
    ///
    /// # Errors
    ///
    /// [`OpError::Invalid`] naming the option and the allowed range.
    pub fn validate(&self) -> Result<(), OpError> {
        if !AMPLITUDE_STEPS.contains(&self.amplitude) {
            return Err(OpError::invalid(
                "--amplitude",
                self.amplitude,
                format!(
                    "allowed: {}..={} position steps",
                    AMPLITUDE_STEPS.start(),
                    AMPLITUDE_STEPS.end()
                ),
            ));
        }
        if self.gains.is_empty() || self.gains.len() > MAX_GAIN_SETS {
            return Err(OpError::invalid(
                "--gains",
                self.gains.len(),
                format!("give 1..={MAX_GAIN_SETS} gain sets"),
            ));
        }
        if !HOLD_MS.contains(&self.hold_ms) {
            return Err(OpError::invalid(
                "--hold-ms",
                self.hold_ms,
                format!("allowed: {}..={} ms", HOLD_MS.start(), HOLD_MS.end()),
            ));
        }
        Ok(())
    }
}

/// The response to one gain set.
#[derive(Debug, Clone, PartialEq, Serialize, schemars::JsonSchema)]
pub struct StepResponse {
    /// P gain.
    pub p: u8,
    /// D gain.
    pub d: u8,
    /// Rise time (10 % to 90 % of the step), ms; `None` if it never got to 90 %.
    pub rise_ms: Option<f64>,
    /// Overshoot, % of the step.
    pub overshoot_pct: f64,
    /// Settling time (2 % band, at least one step), ms; `None` if it never settled.
    pub settling_ms: Option<f64>,
    /// Mean error over the last 10 % of the hold, position steps.
    pub steady_state_error: f64,
    /// The readings: ms since the step, position (steps).
    pub trace: Vec<(f64, u8)>,
}

/// What [`tune`] measured.
#[derive(Debug, Clone, PartialEq, Serialize, schemars::JsonSchema)]
pub struct TuneReport {
    /// Where the steps started, position steps.
    pub start: u8,
    /// Where they went.
    pub target: u8,
    /// One response per gain set, in the order given.
    pub responses: Vec<StepResponse>,
    /// The index of the best set; `None`: a tie (see `tied`).
    pub best: Option<usize>,
    /// The sets that tie for the first place (their responses do not differ by more than
    /// the measurement's resolution), in the order given; empty when one is best.
    pub tied: Vec<usize>,
    /// What was kept: `none`, `runtime` or `eeprom`.
    pub kept: Keep,
}

/// The figures of merit of a response (see the [module docs](self)).
#[must_use]
pub fn figures(trace: &[(f64, u8)], start: u8, target: u8, p: u8, d: u8) -> StepResponse {
    let step = f64::from(target) - f64::from(start);
    let sign = step.signum();
    let amp = step.abs();
    let rel = |pos: u8| (f64::from(pos) - f64::from(start)) * sign;
    let first_at = |level: f64| {
        trace
            .iter()
            .find(|(_, pos)| rel(*pos) >= level)
            .map(|p| p.0)
    };
    let rise_ms = first_at(0.1 * amp)
        .zip(first_at(0.9 * amp))
        .map(|(t10, t90)| t90 - t10);
    let peak = trace
        .iter()
        .map(|(_, pos)| rel(*pos))
        .fold(0.0f64, f64::max);
    let overshoot_pct = ((peak - amp) / amp * 100.0).max(0.0);
    let band = (0.02 * amp).max(1.0);
    let last_out = trace
        .iter()
        .rposition(|(_, pos)| (rel(*pos) - amp).abs() > band);
    let settling_ms = match last_out {
        None => trace.first().map(|_| 0.0),
        Some(i) if i + 1 < trace.len() => Some(trace[i + 1].0),
        Some(_) => None,
    };
    let tail = (trace.len() / 10).max(1);
    let tail_start = trace.len().saturating_sub(tail);
    #[allow(clippy::cast_precision_loss)] // a few thousand readings
    let steady_state_error = trace[tail_start..]
        .iter()
        .map(|(_, pos)| rel(*pos) - amp)
        .sum::<f64>()
        / tail.min(trace.len()).max(1) as f64;
    StepResponse {
        p,
        d,
        rise_ms,
        overshoot_pct,
        settling_ms,
        steady_state_error,
        trace: trace.to_vec(),
    }
}

/// The best response and the ties (see the [module docs](self)): `(Some(best), [])`
/// when one set settles soonest (then has the smaller overshoot) by more than the
/// measurement's resolution, `(None, tied)` when several do not differ from the first
/// place by more than it: the longest interval between two readings of either trace in
/// settling time, one position step of `amplitude` in overshoot.
#[must_use]
pub fn rank(responses: &[StepResponse], amplitude: u8) -> (Option<usize>, Vec<usize>) {
    let key = |r: &StepResponse| (r.settling_ms.unwrap_or(f64::INFINITY), r.overshoot_pct);
    let Some(first) = (0..responses.len()).min_by(|&a, &b| {
        key(&responses[a])
            .partial_cmp(&key(&responses[b]))
            .unwrap_or(std::cmp::Ordering::Equal)
    }) else {
        return (None, Vec::new());
    };
    let gap = |r: &StepResponse| {
        r.trace
            .windows(2)
            .map(|w| w[1].0 - w[0].0)
            .fold(0.0f64, f64::max)
    };
    let step_pct = 100.0 / f64::from(amplitude.max(1));
    let b = &responses[first];
    let tied: Vec<usize> = (0..responses.len())
        .filter(|&i| {
            let r = &responses[i];
            let settles_alike = match (r.settling_ms, b.settling_ms) {
                (Some(x), Some(y)) => (x - y).abs() <= gap(r).max(gap(b)),
                (None, None) => true,
                _ => false,
            };
            settles_alike && (r.overshoot_pct - b.overshoot_pct).abs() <= step_pct
        })
        .collect();
    if tied.len() > 1 {
        (None, tied)
    } else {
        (Some(first), Vec::new())
    }
}

/// Runs the steps (see the [module docs](self)); `confirmed` allows [`Keep::Eeprom`].
///
/// # Errors
///
/// [`OpError::Invalid`] / [`OpError::Refused`] before anything moves (bad arguments, a
/// step that would leave the boundaries, an EEPROM keep without confirmation); the
/// servo's error when it stops answering (its runtime gains are then set back, and it is
/// left holding); [`OpError::Interrupted`] after a stop (the same).
pub fn tune<L: ByteLink>(
    bus: &mut WckBus<L>,
    args: &TuneArgs,
    confirmed: bool,
    control: &mut Control<'_>,
) -> Result<TuneReport, OpError> {
    args.validate()?;
    if args.keep == Keep::Eeprom && !confirmed {
        return Err(OpError::Refused(
            "keeping the best gains in EEPROM rewrites the servo's non-volatile memory; \
             confirm with --yes; nothing was sent"
                .into(),
        ));
    }
    let id = args.id;
    let (eeprom, bounds, here) = {
        let mut s = bus.servo(id);
        (s.gains()?, s.boundaries()?, s.status()?.position.get())
    };
    let (lo, hi) = (bounds.lower().get(), bounds.upper().get());
    // Away from the nearer boundary.
    let up = hi.saturating_sub(here) >= here.saturating_sub(lo);
    let target = if up {
        here.checked_add(args.amplitude)
    } else {
        here.checked_sub(args.amplitude)
    }
    .filter(|t| (lo..=hi).contains(t))
    .ok_or_else(|| {
        OpError::Refused(format!(
            "servo {}: a step of {} from position {here} leaves its boundaries {lo}..={hi}; \
             nothing was sent",
            id.get(),
            args.amplitude
        ))
    })?;
    let result = run_steps(bus, args, (here, target), eeprom, control);
    let mut report = match result {
        Ok(r) => r,
        Err(e) => {
            // Stopped or failed: the gains of a power-up again, and no further motion
            // (a stopped servo holds where the stop left it).
            if let Err(g) = bus.servo(id).set_runtime_gains(eeprom) {
                tracing::warn!(error = %g, "tune: setting the runtime gains back");
            }
            return Err(e);
        }
    };
    // Back at the start, at rest, with the gains of a power-up (which reach it), before
    // anything is kept or the call returns.
    back_at_start(bus, args, here, eeprom, control)?;
    if args.keep != Keep::None {
        // A tie keeps the first of the tied sets, in the order given.
        let chosen = report.best.or_else(|| report.tied.first().copied());
        if let Some(g) = chosen.and_then(|i| args.gains.get(i)).copied() {
            let mut s = bus.servo(id);
            s.set_runtime_gains(g)?;
            if args.keep == Keep::Eeprom {
                s.set_gains(g)?;
            }
        }
    }
    report.kept = args.keep;
    Ok(report)
}

/// Brings the servo back to `start` with the runtime gains `gains` and waits until it
/// reads `start` for [`AT_REST`], at most [`RETURN_LIMIT`] (a stop holds it where it is).
fn back_at_start<L: ByteLink>(
    bus: &mut WckBus<L>,
    args: &TuneArgs,
    start: u8,
    gains: Gains,
    control: &mut Control<'_>,
) -> Result<(), OpError> {
    let id = args.id;
    bus.servo(id).set_runtime_gains(gains)?;
    bus.servo(id).move_to(args.torque, pos(start))?;
    let limit = bus.now() + RETURN_LIMIT;
    let mut since: Option<Instant> = None;
    loop {
        if control.stopped() {
            return Err(SafeState::Hold.interrupted(&mut WckServos {
                bus,
                ids: &[id],
                torque: args.torque,
            }));
        }
        let at = bus.servo(id).status()?.position.get();
        let now = bus.now();
        if at == start {
            let first = *since.get_or_insert(now);
            if now.saturating_duration_since(first) >= AT_REST {
                return Ok(());
            }
        } else {
            since = None;
        }
        if now >= limit {
            return Err(OpError::Device(format!(
                "servo {}: not back at its start position {start} within {} s (at {at});                  its runtime gains are P {} D {}",
                id.get(),
                RETURN_LIMIT.as_secs(),
                gains.p.get(),
                gains.d.get()
            )));
        }
    }
}

/// A position read from the device or computed within its boundaries.
fn pos(p: u8) -> Position {
    Position::new(p).unwrap_or(Position::MAX)
}

fn run_steps<L: ByteLink>(
    bus: &mut WckBus<L>,
    args: &TuneArgs,
    (start, target): (u8, u8),
    eeprom: Gains,
    control: &mut Control<'_>,
) -> Result<TuneReport, OpError> {
    let id = args.id;
    let total = u64::try_from(args.gains.len()).unwrap_or(u64::MAX);
    let mut responses = Vec::new();
    let stop = |bus: &mut WckBus<L>| {
        SafeState::Hold.interrupted(&mut WckServos {
            bus,
            ids: &[id],
            torque: args.torque,
        })
    };
    for (k, &g) in args.gains.iter().enumerate() {
        if control.stopped() {
            return Err(stop(bus));
        }
        control.report(&Progress {
            stage: "tune",
            done: u64::try_from(k).unwrap_or(0),
            total: Some(total),
            note: Some(format!("P {} D {}", g.p.get(), g.d.get())),
        });
        // Every step from the same state: at rest at the start, reached with the gains
        // of a power-up; then this set's gains.
        back_at_start(bus, args, start, eeprom, control)?;
        bus.servo(id).set_runtime_gains(g)?;
        let t0: Instant = bus.now();
        bus.servo(id).move_to(args.torque, pos(target))?;
        let end = t0 + Duration::from_millis(u64::from(args.hold_ms));
        let mut trace = Vec::new();
        while bus.now() < end {
            if control.stopped() {
                return Err(stop(bus));
            }
            let p = bus.servo(id).status()?.position.get();
            trace.push((
                bus.now().saturating_duration_since(t0).as_secs_f64() * 1e3,
                p,
            ));
        }
        responses.push(figures(&trace, start, target, g.p.get(), g.d.get()));
    }
    let (best, tied) = rank(&responses, args.amplitude);
    Ok(TuneReport {
        start,
        target,
        responses,
        best,
        tied,
        kept: Keep::None,
    })
}

/// Parses a gain set `P,D` (`20,30`).
///
/// # Errors
///
/// The text, naming what is wrong.
pub fn parse_gains(s: &str) -> Result<Gains, String> {
    let (p, d) = s
        .split_once(',')
        .ok_or_else(|| format!("{s}: expected P,D (e.g. 20,30)"))?;
    let num = |t: &str| {
        t.trim()
            .parse::<u8>()
            .map_err(|_| format!("{s}: expected P,D numbers"))
    };
    Ok(Gains {
        p: PGain::new(num(p)?).map_err(|e| format!("{s}: {e}"))?,
        d: DGain::new(num(d)?).map_err(|e| format!("{s}: {e}"))?,
    })
}
