//! `whj.move`: a smooth move in position mode, at most `max_speed`, as position frames.

use robobus_wck::BaudRate;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::{JointRow, PreflightArg, R, joint, moved, plan_of, preflight_note, step_limit};
use crate::catalogue::args::WhjOnStop;
use crate::catalogue::bounds;
use crate::catalogue::operation::{Confirm, OpDoc, Operation, Report, RunCx};
use crate::catalogue::plan::WhjSteps;
use crate::catalogue::wck::request;
use crate::catalogue::{Effect, Family, Moved, Plan};
use crate::ops::whj::{self as ops, MoveArgs, MoveReport, ServoLoop};
use crate::ops::{DeviceResult, OpError, preflight};

const fn d10() -> f64 {
    10.0
}
const fn d200() -> f64 {
    200.0
}

request!(cli
    /// `whj.move`: smooth move in position mode.
    Move {
        /// Joint ID, 1..=30.
        #[cfg_attr(feature = "cli", arg(value_parser = crate::catalogue::whj::cli::joint))]
        joint: u32,
        /// Target angle in degrees, -360..=360.
        #[cfg_attr(feature = "cli", arg(allow_hyphen_values = true, value_parser = crate::catalogue::whj::cli::angle))]
        degrees: f64,
        /// Largest speed of the steps, degrees per second (0.1..=180).
        #[serde(default = "d10")]
        #[cfg_attr(feature = "cli", arg(long, default_value_t = 10.0, value_parser = crate::catalogue::whj::cli::max_speed))]
        max_speed: f64,
        /// Position frames per second (1..=1000).
        #[serde(default = "d200")]
        #[cfg_attr(feature = "cli", arg(long, default_value_t = 200.0, value_parser = crate::catalogue::whj::cli::frame_rate))]
        rate_hz: f64,
        /// Start angle of a plan (a dry run; a real run reads the present position;
        /// without `from` a plan assumes 0).
        #[serde(default)]
        #[cfg_attr(feature = "cli", arg(long, allow_hyphen_values = true, value_parser = crate::catalogue::whj::cli::angle))]
        from: Option<f64>,
        /// What a stop leaves the joint in: `hold` or `disable`.
        #[serde(default)]
        #[cfg_attr(feature = "cli", arg(skip))]
        on_stop: WhjOnStop,
        /// Run the move first on the simulator seeded with the joint (`true`), never
        /// (`false`), or by default: when it lasts at most 60 s.
        #[serde(default, skip_serializing_if = "PreflightArg::is_default")]
        #[cfg_attr(feature = "cli", command(flatten))]
        preflight: PreflightArg,
    }
);

impl Move {
    /// The move's arguments, validated, and its plan's start (`from`, if given).
    fn args(&self) -> R<(MoveArgs, Option<f64>)> {
        let j = joint("<JOINT>", self.joint)?;
        let degrees = bounds::ANGLE_DEG.check("<DEGREES>", self.degrees)?;
        let from = self
            .from
            .map(|f| bounds::ANGLE_DEG.check("--from", f))
            .transpose()?;
        let args = MoveArgs {
            joint: j,
            target_deg: degrees,
            max_speed_deg_s: bounds::MOVE_SPEED_DEG_S.check("--max-speed", self.max_speed)?,
            rate_hz: bounds::FRAME_RATE_HZ.check("--rate-hz", self.rate_hz)?,
            step_limit_deg: step_limit(),
        };
        Ok((args, from))
    }

    /// The frames of a move from `from` (0° when not given: the plan says so).
    fn steps(&self) -> R<(MoveArgs, WhjSteps)> {
        let (args, from) = self.args()?;
        let mut plan = ops::plan_move(&args, from.unwrap_or(0.0), from.is_none())?;
        let length = preflight::plan_length(&plan).as_secs_f64();
        plan.notes
            .extend(preflight_note(args.joint, self.preflight.asked(), length));
        Ok((args, WhjSteps::of(&plan)))
    }
}

impl Operation for Move {
    const OP: &'static str = "whj.move";
    const FAMILY: Family = Family::Whj;
    const DOC: OpDoc = OpDoc {
        args: "`joint`, `degrees` (±360), `max_speed` deg/s (0.1..=180)=10, `rate_hz` (1..=1000)=200, `from`, `on_stop`, `preflight` (default: on up to 60 s)",
        report: "one row: `from_deg` (measured), `target_deg`, `position_deg` (after it \
                 settled), `frames`, `seconds`, `step_limited`, `held_back`, `error`",
        confirm: "-",
    };
    type Row = JointRow<MoveReport>;
    type Summary = ();

    fn bus(&self) -> Option<&str> {
        self.bus.as_deref()
    }

    fn effect(&self) -> Effect {
        Effect::Motion
    }

    fn moved(&self) -> Result<Option<Moved>, OpError> {
        let (args, _) = self.steps()?;
        Ok(Some(moved(
            self.bus(),
            vec![args.joint.get()],
            ServoLoop::Position,
        )))
    }

    fn check(&self) -> Result<Confirm, OpError> {
        self.steps().map(|_| Confirm::NONE)
    }

    fn plan(&self, _baud: BaudRate) -> Result<Plan, OpError> {
        let (_, steps) = self.steps()?;
        Ok(plan_of(Self::OP, steps, true, Confirm::NONE))
    }

    fn run(&self, cx: &mut RunCx<'_, '_>) -> Result<Report<Self::Row, ()>, OpError> {
        // Planned from the measured position only, the run's stop looked at while it is.
        let (args, _) = self.args()?;
        let port = cx.station.whj(self.bus())?;
        let j = port.bus().joint(args.joint)?;
        let plan = ops::prepare_move_stoppable(&j, &args, cx.control, self.on_stop.into())?;
        let flight = if preflight::wanted(self.preflight.asked(), preflight::plan_length(&plan)) {
            let seed = preflight::seed_whj(&j)?;
            Some(preflight::whj_move(&seed, &args, &plan, cx.control)?)
        } else {
            None
        };
        let mut r = ops::execute_move(&j, &args, &plan, cx.control, self.on_stop.into())?;
        r.preflight = flight;
        let row = DeviceResult::ok(args.joint.get(), r);
        Ok(Report::devices(Self::OP, port.name(), vec![row]))
    }
}
