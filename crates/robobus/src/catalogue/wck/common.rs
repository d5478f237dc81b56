//! What the wCK operations that send one packet per step share: running a plan's steps
//! on the station's bus with each reply made into the operation's typed row
//! ([`run_steps`]), the `id` of a row ([`StepId`]: a servo's number, or `"all"` for a
//! broadcast), and the row of a parameter (`wck.get` and `wck.set`: [`ParamRow`]).

use robobus_wck::{Command, Position, Reply, Target};
use schemars::JsonSchema;
use serde::Serialize;

use super::confirm_reads_for;
use crate::catalogue::operation::{Report, RunCx};
use crate::ops::wck::{WckPlan, run_steps_with};
use crate::ops::{DeviceResult, ErrorKind, Failure, OpError};

/// What a command without a reply reports under `reply`.
pub(super) const NO_REPLY: &str = "none (the command has no reply)";

/// A quantity rounded to two decimals, as every wCK report shows degrees and volts.
pub(super) fn round2(v: f64) -> f64 {
    (v * 100.0).round() / 100.0
}

/// A position's angle in degrees, rounded to two decimals.
pub(super) fn degrees(p: Position) -> f64 {
    round2(p.degrees())
}

/// The servo a one-servo motion request (`wck.move`, `wck.move10`) on `bus` sets moving:
/// its `id` (checked already by the request's steps).
pub(super) fn moved_servo(bus: Option<&str>, id: u32) -> crate::catalogue::Moved {
    super::moved(bus, vec![u8::try_from(id).unwrap_or(u8::MAX)])
}

/// The `id` of a broadcast's row: `"all"`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, JsonSchema)]
pub enum All {
    /// Every servo of the bus.
    #[serde(rename = "all")]
    All,
}

/// The `id` of a step's row, from the command it sent.
pub(super) trait StepId: Sized {
    /// The ID `command` addresses.
    fn of(command: &Command) -> Self;
}

impl StepId for u8 {
    fn of(command: &Command) -> Self {
        match command.target() {
            Target::Servo(id) => id.get(),
            Target::Extended(id) => id.get(),
            // Not a command of an operation whose rows are per servo.
            Target::Broadcast => Self::MAX,
        }
    }
}

impl StepId for All {
    fn of(_: &Command) -> Self {
        Self::All
    }
}

/// Runs each step of `plan` on the station's wCK bus `bus` (one exchange per packet,
/// the reads confirmed as the bus's policy says: [`confirm_reads_for`]) and makes each
/// reply into a row with `row`; a servo that fails, or whose reply does not fit the row,
/// is its row's failure, and the report's.
#[allow(clippy::result_large_err)] // OpError carries the client errors by value
pub(super) fn run_steps<I: StepId + Serialize, T: Serialize>(
    cx: &mut RunCx<'_, '_>,
    op: &str,
    bus: Option<&str>,
    action: &'static str,
    plan: &WckPlan,
    row: impl Fn(&Command, Option<Reply>) -> Option<T>,
) -> Result<Report<DeviceResult<I, T>, ()>, OpError> {
    let port = cx.station.wck(bus)?;
    let name = port.name().to_owned();
    let mut guard = port.lock();
    let wck = &mut *guard;
    let saved = wck.config_mut().confirm_reads;
    wck.config_mut().confirm_reads = confirm_reads_for(plan, port.verify_reads());
    let results = run_steps_with(wck, action, plan, cx.control, I::of, |command, reply| {
        row(command, reply).ok_or_else(|| unexpected(command, reply))
    });
    wck.config_mut().confirm_reads = saved;
    Ok(Report::devices(op, &name, results?))
}

/// A reply that does not fit the command's row (the protocol layer decodes each reply
/// by its command, so this names a fault of the device).
fn unexpected(command: &Command, reply: Option<Reply>) -> Failure {
    Failure::of(
        ErrorKind::Device,
        &format!("{command:?}: unexpected reply {reply:?}"),
    )
}

/// A servo parameter as read or written (`wck.get`, `wck.set`): the values the servo
/// answered (a write's read-back).
#[derive(Debug, Clone, PartialEq, Serialize, JsonSchema)]
#[serde(untagged)]
pub enum ParamRow {
    /// P and D gains.
    Gains {
        /// P gain.
        p_gain: u8,
        /// D gain.
        d_gain: u8,
    },
    /// I gain.
    IGain {
        /// I gain.
        i_gain: u8,
    },
    /// Speed level and acceleration range, as the servo answered.
    Speed {
        /// Speed level, 0..=30.
        speed: u8,
        /// Acceleration range, 20..=100.
        accel: u8,
    },
    /// Runtime speed and acceleration: sent, the command has no reply.
    SpeedSent {
        /// Speed level sent.
        speed: u8,
        /// Acceleration range sent.
        accel: u8,
        /// `none (the command has no reply)`.
        reply: String,
    },
    /// Over-load threshold.
    Overload {
        /// The threshold, mA.
        milliamps: u16,
        /// Its code in the servo.
        overload_code: u8,
    },
    /// Movement boundaries.
    Bounds {
        /// Lower boundary, 0..=254.
        lower: u8,
        /// The same in degrees.
        lower_degrees: f64,
        /// Upper boundary, 0..=254.
        upper: u8,
        /// The same in degrees.
        upper_degrees: f64,
    },
    /// Digital outputs and the A/D input (a read).
    Io {
        /// Output bits, 0..=3.
        outputs: u8,
        /// Output 1 on.
        do1: bool,
        /// Output 2 on.
        do2: bool,
        /// A/D input, 0..=255.
        adc: u8,
        /// The same in volts (0..=5).
        adc_volts: f64,
    },
    /// Digital outputs (a write's read-back).
    Outputs {
        /// Output bits, 0..=3.
        outputs: u8,
        /// Output 1 on.
        do1: bool,
        /// Output 2 on.
        do2: bool,
    },
}

impl ParamRow {
    /// The row of a parameter command's reply (`None`: not a parameter's reply).
    pub(super) fn of(command: &Command, reply: Option<Reply>) -> Option<Self> {
        let Some(reply) = reply else {
            return Self::sent(command);
        };
        Some(match reply {
            Reply::Gains { p, d } => Self::Gains {
                p_gain: p.get(),
                d_gain: d.get(),
            },
            Reply::IGain(i) => Self::IGain { i_gain: i.get() },
            Reply::SpeedAccel { speed, accel } => Self::Speed {
                speed: speed.get(),
                accel: accel.get(),
            },
            Reply::Overload(o) => Self::Overload {
                milliamps: o.milliamps(),
                overload_code: o.get(),
            },
            Reply::Boundaries(b) => Self::Bounds {
                lower: b.lower().get(),
                lower_degrees: degrees(b.lower()),
                upper: b.upper().get(),
                upper_degrees: degrees(b.upper()),
            },
            Reply::Io { outputs, adc } => Self::Io {
                outputs: outputs.get(),
                do1: outputs.do1(),
                do2: outputs.do2(),
                adc,
                adc_volts: round2(f64::from(adc) * 5.0 / 255.0),
            },
            Reply::Outputs(o) => Self::Outputs {
                outputs: o.get(),
                do1: o.do1(),
                do2: o.do2(),
            },
            _ => return None,
        })
    }

    /// A parameter command without a reply: what it sent.
    fn sent(command: &Command) -> Option<Self> {
        match command {
            Command::RuntimeSpeedSet { speed, accel, .. } => Some(Self::SpeedSent {
                speed: speed.get(),
                accel: accel.get(),
                reply: NO_REPLY.to_owned(),
            }),
            _ => None,
        }
    }
}
