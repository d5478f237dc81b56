//! `whj.wave`: a test signal (sine or square) as servo frames, with its tracking
//! statistics.

use robobus_wck::BaudRate;
use robobus_whj::units::CurrentScale;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::{Model, PreflightArg, R, joint, moved, plan_of, preflight_note, scale_for, step_limit};
use crate::catalogue::args::WhjOnStop;
use crate::catalogue::bounds;
use crate::catalogue::operation::{Confirm, OpDoc, Operation, Report, RunCx};
use crate::catalogue::plan::WhjSteps;
use crate::catalogue::wck::request;
use crate::catalogue::{Effect, Family, Moved, Plan};
use crate::error::ErrorKind;
use crate::ops::whj::{self as ops, FeedbackReport, ServoLoop, WaveArgs, WaveReport};
use crate::ops::{OpError, preflight};

/// Frames without a reply at the end of a wave after which the joint counts as gone (a
/// no-device failure): one lost reply is a glitch, ten in a row at the end a silent joint.
pub const GONE_AFTER: u64 = 10;

const fn d05() -> f64 {
    0.5
}
const fn d4() -> f64 {
    4.0
}
const fn d200() -> f64 {
    200.0
}

/// Wave shape.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, JsonSchema)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
#[serde(rename_all = "lowercase")]
pub enum Shape {
    /// offset + amplitude * sin(2 pi f t).
    #[default]
    Sine,
    /// offset + amplitude while sin(2 pi f t) >= 0, else offset - amplitude.
    Square,
}

/// Which loop a wave drives.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, JsonSchema)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
#[serde(rename_all = "lowercase")]
pub enum WaveMode {
    /// Position servo frames (0x200+ID); amplitude and offset in degrees.
    #[default]
    Position,
    /// Speed servo frames (0x300+ID); amplitude and offset in RPM.
    Speed,
    /// Current servo frames (0x400+ID); amplitude and offset in mA.
    Current,
}

impl WaveMode {
    /// The joint's loop this mode drives.
    pub const fn servo(self) -> ServoLoop {
        match self {
            Self::Position => ServoLoop::Position,
            Self::Speed => ServoLoop::Speed,
            Self::Current => ServoLoop::Current,
        }
    }
}

request!(cli
    /// `whj.wave`: a test signal as servo frames.
    Wave {
        /// Joint ID, 1..=30.
        #[cfg_attr(feature = "cli", arg(value_parser = crate::catalogue::whj::cli::joint))]
        joint: u32,
        /// Signal shape.
        #[serde(default)]
        #[cfg_attr(feature = "cli", arg(long, value_enum, default_value = "sine"))]
        shape: Shape,
        /// Which servo loop the signal drives.
        #[serde(default)]
        #[cfg_attr(feature = "cli", arg(long, value_enum, default_value = "position"))]
        mode: WaveMode,
        /// Amplitude (degrees, RPM or mA by `mode`), >= 0.
        #[cfg_attr(feature = "cli", arg(long, value_parser = crate::catalogue::whj::cli::finite))]
        amplitude: f64,
        /// Frequency in Hz, 0.01..=20 and at most `rate_hz` / 4.
        #[serde(default = "d05")]
        #[cfg_attr(feature = "cli", arg(long, default_value_t = 0.5, value_parser = crate::catalogue::whj::cli::finite))]
        frequency: f64,
        /// Offset (degrees, RPM or mA by `mode`).
        #[serde(default)]
        #[cfg_attr(feature = "cli", arg(long, default_value_t = 0.0, allow_hyphen_values = true, value_parser = crate::catalogue::whj::cli::finite))]
        offset: f64,
        /// Duration in seconds, 0.01..=600.
        #[serde(default = "d4")]
        #[cfg_attr(feature = "cli", arg(long, default_value_t = 4.0, value_parser = crate::catalogue::whj::cli::finite))]
        duration: f64,
        /// Frames per second (1..=1000).
        #[serde(default = "d200")]
        #[cfg_attr(feature = "cli", arg(long, default_value_t = 200.0, value_parser = crate::catalogue::whj::cli::frame_rate))]
        rate_hz: f64,
        /// Send the wave as broadcast frames (0x2F position, 0x4F current; joints 1..=7;
        /// position waves at `rate_hz` >= 100, since a joint stops a broadcast position
        /// stream after 20 ms without a frame).
        #[serde(default)]
        #[cfg_attr(feature = "cli", arg(long))]
        broadcast: bool,
        /// Start angle of a position wave in a plan (a dry run; a real run starts the step
        /// limiter at the present position; without `from` a plan assumes 0).
        #[serde(default)]
        #[cfg_attr(feature = "cli", arg(long, allow_hyphen_values = true, value_parser = crate::catalogue::whj::cli::angle))]
        from: Option<f64>,
        /// Model for the current scale of a plan.
        #[serde(default)]
        #[cfg_attr(feature = "cli", arg(skip))]
        model: Option<Model>,
        /// What a stop leaves the joint in.
        #[serde(default)]
        #[cfg_attr(feature = "cli", arg(skip))]
        on_stop: WhjOnStop,
        /// Run the wave first on the simulator seeded with the joint (`true`), never
        /// (`false`), or by default: when it lasts at most 60 s.
        #[serde(default, skip_serializing_if = "PreflightArg::is_default")]
        #[cfg_attr(feature = "cli", command(flatten))]
        preflight: PreflightArg,
    }
);

/// The joint's row: its last feedback (left out when none came), the frames sent, and
/// whether that feedback is older than the last frame.
#[derive(Debug, Clone, PartialEq, Serialize, JsonSchema)]
pub struct WaveRow {
    /// The joint.
    pub id: u8,
    /// The last feedback that came.
    #[serde(flatten)]
    pub last: Option<FeedbackReport>,
    /// Frames sent.
    pub cycles: u64,
    /// The last frame went without a reply, or none came: the values shown are older.
    pub stale: bool,
}

impl Wave {
    /// The wave's arguments, validated.
    fn args(&self) -> R<WaveArgs> {
        Ok(WaveArgs {
            joint: joint("<JOINT>", self.joint)?,
            shape: match self.shape {
                Shape::Sine => ops::Shape::Sine,
                Shape::Square => ops::Shape::Square,
            },
            servo: self.mode.servo(),
            amplitude: self.amplitude,
            frequency: self.frequency,
            offset: self.offset,
            duration: self.duration,
            rate_hz: bounds::FRAME_RATE_HZ.check("--rate-hz", self.rate_hz)?,
            step_limit_deg: step_limit(),
        })
    }

    /// Its frames from `from` (or 0°, assumed), their mA-to-counts scale from `model`
    /// (`dry_run`: a plan of a current wave needs it).
    fn steps(&self, dry_run: bool) -> R<(WaveArgs, WhjSteps)> {
        let args = self.args()?;
        let scale = if self.mode == WaveMode::Current {
            scale_for(self.model, dry_run, "wave --mode current")?
        } else {
            CurrentScale::OneMilliamp
        };
        let from = self
            .from
            .map(|f| bounds::ANGLE_DEG.check("--from", f))
            .transpose()?;
        let start = from.unwrap_or(0.0);
        let mut plan = if self.broadcast {
            ops::plan_broadcast_wave(&args, start, scale, from.is_none())?
        } else {
            ops::plan_wave(&args, start, scale, from.is_none())?
        };
        let length = preflight::plan_length(&plan).as_secs_f64();
        plan.notes
            .extend(preflight_note(args.joint, self.preflight.asked(), length));
        Ok((args, WhjSteps::of(&plan)))
    }
}

/// Why a wave's joint counts as silent, if it does: no reply at all, or none to the
/// last [`GONE_AFTER`] frames.
fn silence(joint: u8, r: &WaveReport) -> Option<String> {
    if r.complete == 0 {
        Some(format!(
            "joint {joint}: no reply to any of the {} wave frames",
            r.cycles
        ))
    } else if r.missing_at_end >= GONE_AFTER {
        Some(format!(
            "joint {joint}: silent for the last {} wave frames ({} of {} without a reply; the \
             last values shown are stale)",
            r.missing_at_end, r.missing_replies, r.cycles
        ))
    } else {
        None
    }
}

impl Operation for Wave {
    const OP: &'static str = "whj.wave";
    const FAMILY: Family = Family::Whj;
    const DOC: OpDoc = OpDoc {
        args: "`joint`, `shape`, `mode`, `amplitude`, `frequency` Hz=0.5, `offset`, `duration` \
               s=4, `rate_hz`=200, `broadcast`, `model`, `on_stop`, `preflight` (default: on \
               up to 60 s)",
        report: "last feedback; summary: wave statistics",
        confirm: "-",
    };
    type Row = WaveRow;
    type Summary = WaveReport;

    fn bus(&self) -> Option<&str> {
        self.bus.as_deref()
    }

    fn effect(&self) -> Effect {
        Effect::Motion
    }

    fn moved(&self) -> R<Option<Moved>> {
        let (args, _) = self.steps(false)?;
        Ok(Some(moved(
            self.bus(),
            vec![args.joint.get()],
            self.mode.servo(),
        )))
    }

    fn check(&self) -> R<Confirm> {
        self.steps(false).map(|_| Confirm::NONE)
    }

    fn plan(&self, _baud: BaudRate) -> R<Plan> {
        let (_, steps) = self.steps(true)?;
        Ok(plan_of(Self::OP, steps, true, Confirm::NONE))
    }

    fn run(&self, cx: &mut RunCx<'_, '_>) -> Result<Report<WaveRow, WaveReport>, OpError> {
        // Planned from the measured position only, the run's stop looked at while it is.
        let args = self.args()?;
        let port = cx.station.whj(self.bus())?;
        let j = port.bus().joint(args.joint)?;
        let plan = if self.broadcast {
            ops::prepare_broadcast_wave(&j, &args)?
        } else {
            ops::prepare_wave_stoppable(&j, &args, cx.control, self.on_stop.into())?
        };
        let flight = if preflight::wanted(self.preflight.asked(), preflight::plan_length(&plan)) {
            let seed = preflight::seed_whj(&j)?;
            Some(preflight::whj_wave(&seed, &args, &plan, cx.control)?)
        } else {
            None
        };
        let mut r = ops::execute_wave(&j, &args, &plan, cx.control, self.on_stop.into())?;
        r.preflight = flight;
        let id = args.joint.get();
        let row = WaveRow {
            id,
            stale: r.stale || r.last.is_none(),
            last: r.last.take(),
            cycles: r.cycles,
        };
        let silent = silence(id, &r);
        // The summary is the statistics: the last feedback is the row's.
        let mut report = Report::with_rows(Self::OP, port.name(), vec![row]).summary(r);
        if let Some(e) = silent {
            report.fail(ErrorKind::NoDevice, e);
        }
        Ok(report)
    }
}
