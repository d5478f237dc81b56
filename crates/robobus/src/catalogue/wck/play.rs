//! `wck.play`: a keyframe motion played as synchronized moves.

use robobus_wck::BaudRate;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::{NoRow, R, default_hold, moved, plan_of, servos};
use crate::catalogue::args::WckOnStop;
use crate::catalogue::bounds::{self, ConfirmClass};
use crate::catalogue::operation::{Confirm, OpDoc, Operation, Report, RunCx};
use crate::catalogue::plan::MAX_PLAN_STEPS;
use crate::catalogue::{Effect, Family, Moved, Plan};
use crate::ops::OpError;
use crate::ops::wck::{self as wops, Frame, Motion, PlayReport, WckPlan};

const fn default_rate() -> f64 {
    50.0
}

request!(cli
    /// `wck.play`: play a keyframe motion (its text) as synchronized moves.
    Play {
        /// The keyframe motion text (what a motion file holds).
        #[cfg_attr(feature = "cli", arg(skip))]
        motion: String,
        /// Synchronized moves per second while interpolating, 0.1..=200.
        #[serde(default = "default_rate")]
        #[cfg_attr(feature = "cli", arg(long, default_value_t = 50.0, value_parser = crate::catalogue::wck::cli::rate_hz))]
        rate_hz: f64,
        /// What the servos do on a stop (Ctrl-C): hold (keep the current position),
        /// passive or break.
        #[serde(default = "default_hold")]
        #[cfg_attr(feature = "cli", arg(long, value_enum, default_value = "hold", hide_possible_values = true))]
        on_stop: WckOnStop,
    }
);

impl Play {
    /// The motion and the rate, validated.
    fn parsed(&self) -> R<(Motion, f64)> {
        let rate = bounds::WCK_RATE_HZ.check("--rate-hz", self.rate_hz)?;
        let motion = Motion::parse(&self.motion).map_err(|e| {
            OpError::invalid("motion", format!("{}:{}", e.line, e.column), e.message)
        })?;
        Ok((motion, rate))
    }
}

impl Operation for Play {
    const OP: &'static str = "wck.play";
    const FAMILY: Family = Family::Wck;
    const DOC: OpDoc = OpDoc {
        args: "`motion` (keyframe text), `rate_hz`=50, `on_stop`",
        report: "no rows; `summary`: `port`, `command` (`play`), `moves`, `sent`, \
                 `watch_reads`, `planned_ms`, `duration_ms`, `last_positions`",
        confirm: "-",
    };
    type Row = NoRow;
    type Summary = PlayReport;

    fn bus(&self) -> Option<&str> {
        self.bus.as_deref()
    }

    fn effect(&self) -> Effect {
        Effect::Motion
    }

    /// Servos 0..N-1, N the most positions a pose of the motion lists.
    fn moved(&self) -> Result<Option<Moved>, OpError> {
        let (motion, _) = self.parsed()?;
        let n = motion.frames.iter().filter_map(|f| match f {
            Frame::Pose(p) => Some(p.positions.len()),
            Frame::Hold(_) => None,
        });
        Ok(Some(moved(self.bus(), servos(n.max().unwrap_or(0)))))
    }

    fn check(&self) -> Result<Confirm, OpError> {
        self.parsed().map(|_| Confirm::NONE)
    }

    /// The first [`MAX_PLAN_STEPS`] moves (a motion is streamed: `truncated` past them).
    fn plan(&self, baud: BaudRate) -> Result<Plan, OpError> {
        let (motion, rate) = self.parsed()?;
        let mut plan = WckPlan::default();
        plan.notes.push(Motion::plan_note(rate));
        plan.steps.extend(motion.moves(rate).take(MAX_PLAN_STEPS));
        let mut out = plan_of(Self::OP, &plan, baud, ConfirmClass::None);
        out.truncated = plan.steps.len() >= MAX_PLAN_STEPS;
        Ok(out)
    }

    fn run(&self, cx: &mut RunCx<'_, '_>) -> Result<Report<NoRow, PlayReport>, OpError> {
        let (motion, rate) = self.parsed()?;
        let port = cx.station.wck(self.bus())?;
        let r = wops::play(
            &mut *port.lock(),
            &motion,
            rate,
            self.on_stop.into(),
            cx.control,
        )?;
        Ok(Report::new(Self::OP, port.name()).summary(r))
    }
}
