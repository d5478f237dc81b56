//! `whj.speed`: a speed target (0x300+ID) in output RPM, kept for a time or left running
//! (also how `whj.current` runs).

use robobus_wck::BaudRate;
use robobus_whj::units::CurrentScale;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::{JointRow, R, duration, joint, moved, plan_of, target_steps};
use crate::catalogue::args::WhjOnStop;
use crate::catalogue::bounds;
use crate::catalogue::operation::{Confirm, OpDoc, Operation, Report, RunCx};
use crate::catalogue::wck::request;
use crate::catalogue::{Effect, Family, Moved, Plan};
use crate::ops::whj::{self as ops, ServoLoop, TargetArgs, TargetReport};
use crate::ops::{DeviceResult, OpError};

request!(cli
    /// `whj.speed`: speed target (0x300+ID), output RPM.
    Speed {
        /// Joint ID, 1..=30.
        #[cfg_attr(feature = "cli", arg(value_parser = crate::catalogue::whj::cli::joint))]
        joint: u32,
        /// Target speed, RPM, -37.5..=37.5.
        #[cfg_attr(feature = "cli", arg(allow_hyphen_values = true, value_parser = crate::catalogue::whj::cli::rpm))]
        rpm: f64,
        /// Keep the target this many seconds (0.01..=3600), then target 0 (also when
        /// stopped). Without it the joint keeps turning after the request.
        #[serde(default)]
        #[cfg_attr(feature = "cli", arg(long, value_name = "SECS", value_parser = crate::catalogue::whj::cli::duration))]
        duration: Option<f64>,
        /// What a stop leaves the joint in.
        #[serde(default)]
        #[cfg_attr(feature = "cli", arg(skip))]
        on_stop: WhjOnStop,
    }
);

/// What `whj.speed` and `whj.current` report.
pub(super) const TARGET_REPORT: &str = "one row: the feedback to the target frame \
     (`enabled`, `position_deg`, `speed_rpm`, `current_ma`, `error`), `keeps_running` (no \
     `duration`: the joint keeps the target), `note`";

/// The joint a speed or current target on `bus` sets moving, running its loop.
pub(super) fn target_moved(bus: Option<&str>, args: &TargetArgs) -> Moved {
    moved(bus, vec![args.joint.get()], args.servo)
}

/// Runs a speed or current target on the station's joint (validated already).
pub(super) fn run_target(
    op: &str,
    bus: Option<&str>,
    args: &TargetArgs,
    on_stop: WhjOnStop,
    cx: &mut RunCx<'_, '_>,
) -> Result<Report<JointRow<TargetReport>, ()>, OpError> {
    let port = cx.station.whj(bus)?;
    let j = port.bus().joint(args.joint)?;
    let r = ops::run_target(&j, args, cx.control, on_stop.into())?;
    let row = DeviceResult::ok(args.joint.get(), r);
    Ok(Report::devices(op, port.name(), vec![row]))
}

impl Speed {
    fn args(&self) -> R<TargetArgs> {
        Ok(TargetArgs {
            joint: joint("<JOINT>", self.joint)?,
            servo: ServoLoop::Speed,
            value: bounds::SPEED_RPM.check("<RPM>", self.rpm)?,
            duration: duration(self.duration)?,
        })
    }
}

impl Operation for Speed {
    const OP: &'static str = "whj.speed";
    const FAMILY: Family = Family::Whj;
    const DOC: OpDoc = OpDoc {
        args: "`joint`, `rpm` (±37.5), `duration` s (0.01..=3600), `on_stop`",
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
        self.check()?;
        Ok(Some(target_moved(self.bus(), &self.args()?)))
    }

    fn check(&self) -> Result<Confirm, OpError> {
        target_steps(&self.args()?, CurrentScale::OneMilliamp).map(|_| Confirm::NONE)
    }

    fn plan(&self, _baud: BaudRate) -> Result<Plan, OpError> {
        let steps = target_steps(&self.args()?, CurrentScale::OneMilliamp)?;
        Ok(plan_of(Self::OP, steps, true, Confirm::NONE))
    }

    fn run(&self, cx: &mut RunCx<'_, '_>) -> Result<Report<Self::Row, ()>, OpError> {
        self.check()?;
        run_target(Self::OP, self.bus(), &self.args()?, self.on_stop, cx)
    }
}
