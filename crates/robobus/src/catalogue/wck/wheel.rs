//! `wck.wheel` (A-1 (5)): a servo turns continuously; for a time, watched by status
//! reads, then stopped as `on_stop` says.

use robobus_wck::{BaudRate, Rotation, WheelSpeed};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::{R, byte, default_hold, moved, plan_of, secs, sid};
use crate::catalogue::args::WckOnStop;
use crate::catalogue::bounds::ConfirmClass;
use crate::catalogue::operation::{Confirm, OpDoc, Operation, Report, RunCx};
use crate::catalogue::{Effect, Family, Moved, Plan};
use crate::error::ErrorKind;
use crate::ops::wck::{self as wops, FieldValue, Fields, WheelArgs};
use crate::ops::{DeviceResult, Failure, Outcome};

request!(cli
    /// `wck.wheel` (A-1 (5)): turn continuously, optionally for a time.
    Wheel {
        /// Servo ID, 0..=30.
        #[cfg_attr(feature = "cli", arg(value_parser = crate::catalogue::wck::cli::servo_id))]
        id: u32,
        /// Direction: `ccw` or `cw`.
        #[cfg_attr(feature = "cli", arg(value_enum))]
        direction: Direction,
        /// Speed 0 (stop), 1 (minimum) ..= 15 (maximum).
        #[cfg_attr(feature = "cli", arg(value_parser = crate::catalogue::wck::cli::wheel_speed))]
        speed: u32,
        /// Turn for this many seconds (0.1..=3600), then stop per `on_stop`. Without it the
        /// servo keeps turning after the request returns.
        #[serde(default)]
        #[cfg_attr(feature = "cli", arg(long, value_name = "SECS", value_parser = crate::catalogue::wck::cli::seconds))]
        duration: Option<f64>,
        /// How the servo stops after `duration` or on a stop (Ctrl-C): hold (position move
        /// to where it is), passive or break.
        #[serde(default = "default_hold")]
        #[cfg_attr(feature = "cli", arg(long, value_enum, default_value = "hold", hide_possible_values = true))]
        on_stop: WckOnStop,
    }
);

/// Wheel direction.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
#[serde(rename_all = "lowercase")]
pub enum Direction {
    /// Counter-clockwise.
    Ccw,
    /// Clockwise.
    Cw,
}

/// A wheel run: the wheel command's reply, and for a timed run how it ended.
#[derive(Debug, Clone, PartialEq, Serialize, JsonSchema)]
pub struct WheelRow {
    /// Rotations counted since power-up (0..=255, wraps), before the run.
    pub rotations: u8,
    /// The position before the run, 0..=254.
    pub position: u8,
    /// The same in degrees.
    pub degrees: f64,
    /// A timed run: how long it turned, ms.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ran_ms: Option<u64>,
    /// A timed run: the safe state it ended in (`hold`, `passive`, `break`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stopped: Option<String>,
    /// A timed run: where the shaft came to rest, 0..=254 (a status read after the stop).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stopped_at: Option<u8>,
    /// A timed run: the load then.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stopped_load: Option<u8>,
}

impl WheelRow {
    /// The row of [`wops::wheel`]'s fields (`None`: a field is missing or out of its type).
    fn of(f: &Fields) -> Option<Self> {
        let int = |k: &str| match f.get(k) {
            Some(FieldValue::Int(n)) => Some(*n),
            _ => None,
        };
        let byte = |k: &str| int(k).and_then(|n| u8::try_from(n).ok());
        Some(Self {
            rotations: byte("rotations")?,
            position: byte("position")?,
            degrees: match f.get("degrees")? {
                FieldValue::Real(d) => *d,
                _ => return None,
            },
            ran_ms: int("ran_ms").and_then(|n| u64::try_from(n).ok()),
            stopped: match f.get("stopped") {
                Some(FieldValue::Text(s)) => Some(s.clone()),
                _ => None,
            },
            stopped_at: byte("stopped_at"),
            stopped_load: byte("stopped_load"),
        })
    }
}

impl Wheel {
    /// The run's arguments, validated.
    fn args(&self) -> R<WheelArgs> {
        Ok(WheelArgs {
            id: sid(self.id)?,
            rotation: match self.direction {
                Direction::Ccw => Rotation::Ccw,
                Direction::Cw => Rotation::Cw,
            },
            speed: byte("<SPEED>", self.speed, WheelSpeed::new)?,
            duration: self.duration.map(|d| secs("--duration", d)).transpose()?,
            on_stop: self.on_stop.into(),
        })
    }
}

impl Operation for Wheel {
    const OP: &'static str = "wck.wheel";
    const FAMILY: Family = Family::Wck;
    const DOC: OpDoc = OpDoc {
        args: "`id`, `direction` (ccw/cw), `speed` (0..=15), `duration` s, `on_stop`",
        report: "`rotations`, `position`, `degrees` (before the run); timed: `ran_ms`, \
                 `stopped` (the safe state), `stopped_at`, `stopped_load` (where it came to \
                 rest)",
        confirm: "-",
    };
    type Row = DeviceResult<u8, WheelRow>;
    type Summary = ();

    fn bus(&self) -> Option<&str> {
        self.bus.as_deref()
    }

    fn effect(&self) -> Effect {
        Effect::Motion
    }

    fn moved(&self) -> R<Option<Moved>> {
        let args = self.args()?;
        Ok(Some(moved(self.bus(), vec![args.id.get()])))
    }

    fn check(&self) -> R<Confirm> {
        self.args().map(|_| Confirm::NONE)
    }

    fn plan(&self, baud: BaudRate) -> R<Plan> {
        Ok(plan_of(
            Self::OP,
            &self.args()?.plan(),
            baud,
            ConfirmClass::None,
        ))
    }

    fn run(&self, cx: &mut RunCx<'_, '_>) -> R<Report<Self::Row, ()>> {
        let args = self.args()?;
        let port = cx.station.wck(self.bus())?;
        let name = port.name().to_owned();
        let r = wops::wheel(&mut *port.lock(), &args, cx.control)?;
        let id = args.id.get();
        let row = match r.outcome {
            Outcome::Ok(fields) => match WheelRow::of(&fields) {
                Some(row) => DeviceResult::ok(id, row),
                None => DeviceResult::failed(
                    id,
                    Failure::of(
                        ErrorKind::Device,
                        &format!("servo {id}: an unexpected wheel reply ({fields:?})"),
                    ),
                ),
            },
            Outcome::Failed(f) => DeviceResult::failed(id, f),
        };
        Ok(Report::devices(Self::OP, &name, vec![row]))
    }
}
