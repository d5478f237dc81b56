//! `whj.current`: a current target (0x400+ID) in mA, kept for a time or left running.

use robobus_wck::BaudRate;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::speed::{TARGET_REPORT, run_target, target_moved};
use super::{JointRow, Model, R, duration, joint, plan_of, scale_for, target_steps};
use crate::catalogue::args::WhjOnStop;
use crate::catalogue::bounds;
use crate::catalogue::operation::{Confirm, OpDoc, Operation, Report, RunCx};
use crate::catalogue::plan::WhjSteps;
use crate::catalogue::wck::request;
use crate::catalogue::{Effect, Family, Moved, Plan};
use crate::ops::OpError;
use crate::ops::whj::{ServoLoop, TargetArgs, TargetReport};

request!(cli
    /// `whj.current`: current target (0x400+ID), mA.
    Current {
        /// Joint ID, 1..=30.
        #[cfg_attr(feature = "cli", arg(value_parser = crate::catalogue::whj::cli::joint))]
        joint: u32,
        /// Target current, mA, -30000..=30000.
        #[cfg_attr(feature = "cli", arg(allow_hyphen_values = true, value_parser = crate::catalogue::whj::cli::milliamps))]
        milliamps: f64,
        /// Keep the target this many seconds (0.01..=3600), then target 0 (also when
        /// stopped). Without it the joint keeps the current after the request.
        #[serde(default)]
        #[cfg_attr(feature = "cli", arg(long, value_name = "SECS", value_parser = crate::catalogue::whj::cli::duration))]
        duration: Option<f64>,
        /// Model for the plan's current scale (a run reads it from the joint).
        #[serde(default)]
        #[cfg_attr(feature = "cli", arg(skip))]
        model: Option<Model>,
        /// What a stop leaves the joint in.
        #[serde(default)]
        #[cfg_attr(feature = "cli", arg(skip))]
        on_stop: WhjOnStop,
    }
);

impl Current {
    fn args(&self) -> R<TargetArgs> {
        Ok(TargetArgs {
            joint: joint("<JOINT>", self.joint)?,
            servo: ServoLoop::Current,
            value: bounds::CURRENT_MA.check("<MILLIAMPS>", self.milliamps)?,
            duration: duration(self.duration)?,
        })
    }

    /// The frames (`dry_run`: for a plan, whose mA-to-counts scale needs `model`).
    fn steps(&self, dry_run: bool) -> R<(TargetArgs, WhjSteps)> {
        let args = self.args()?;
        let scale = scale_for(self.model, dry_run, "current <MILLIAMPS>")?;
        let steps = target_steps(&args, scale)?;
        Ok((args, steps))
    }
}

impl Operation for Current {
    const OP: &'static str = "whj.current";
    const FAMILY: Family = Family::Whj;
    const DOC: OpDoc = OpDoc {
        args: "`joint`, `milliamps` (±30000), `duration`, `model`, `on_stop`",
        report: TARGET_REPORT,
        confirm: "-",
    };
    type Row = JointRow<TargetReport>;
    type Summary = ();

    fn bus(&self) -> Option<&str> {
        self.bus.as_deref()
    }

    fn effect(&self) -> Effect {
        Effect::Motion
    }

    fn moved(&self) -> Result<Option<Moved>, OpError> {
        let (args, _) = self.steps(false)?;
        Ok(Some(target_moved(self.bus(), &args)))
    }

    fn check(&self) -> Result<Confirm, OpError> {
        self.steps(false).map(|_| Confirm::NONE)
    }

    fn plan(&self, _baud: BaudRate) -> Result<Plan, OpError> {
        let (_, steps) = self.steps(true)?;
        Ok(plan_of(Self::OP, steps, true, Confirm::NONE))
    }

    fn run(&self, cx: &mut RunCx<'_, '_>) -> Result<Report<Self::Row, ()>, OpError> {
        let (args, _) = self.steps(false)?;
        run_target(Self::OP, self.bus(), &args, self.on_stop, cx)
    }
}
