//! `wck.teach`: poses recorded while the servos are moved by hand (passive meanwhile).

use std::cell::RefCell;

use robobus_wck::{BaudRate, ServoId};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::{NoRow, R, default_passive, moved, plan_of, secs, torque};
use crate::catalogue::args::{Ids, WckOnStop};
use crate::catalogue::bounds::{self, ConfirmClass};
use crate::catalogue::operation::{Confirm, OpDoc, Operation, Report, RunCx};
use crate::catalogue::{Effect, Family, Moved, Plan};
use crate::ops::OpError;
use crate::ops::wck::{self as wops, Pose, TeachArgs, TeachTrigger};

/// The longest transition time a pose recorded by an event gets, ms.
pub const MAX_POSE_MS: u32 = 600_000;

const fn default_pose_ms() -> u32 {
    1000
}

request!(cli
    /// `wck.teach`: record poses at a rate for a time (servos passive meanwhile).
    Teach {
        /// Servo IDs to record: 0..N-1 (e.g. `0-15`), since a pose lists servos 0, 1, ...
        #[cfg_attr(feature = "cli", arg(value_parser = crate::catalogue::wck::cli::servo_ids))]
        ids: Ids,
        /// Record at this many poses per second (0.1..=200; 10 when only `duration` is
        /// given) instead of at each record event of the front end (a keypress).
        #[serde(default)]
        #[cfg_attr(feature = "cli", arg(long, value_parser = crate::catalogue::wck::cli::rate_hz))]
        rate_hz: Option<f64>,
        /// Record for this many seconds (0.1..=3600), at `rate_hz`; without it a recording
        /// at a rate runs until the front end's finish event or a stop.
        #[serde(default)]
        #[cfg_attr(feature = "cli", arg(long, value_name = "SECS", value_parser = crate::catalogue::wck::cli::seconds))]
        duration: Option<f64>,
        /// Transition time written for each pose recorded by an event (a keypress), ms
        /// (0..=600000).
        #[serde(default = "default_pose_ms")]
        #[cfg_attr(feature = "cli", arg(long, default_value_t = 1000, value_parser = clap::value_parser!(u32).range(0..=600_000)))]
        pose_ms: u32,
        /// Torque level written into the poses (and of a hold at the end), 0 (maximum)
        /// ..= 4 (minimum).
        #[serde(default)]
        #[cfg_attr(feature = "cli", arg(long, default_value = "0", value_parser = crate::catalogue::wck::cli::torque))]
        torque: u32,
        /// What the servos do when recording ends: passive (stay limp), hold (keep the
        /// last pose with torque) or break.
        #[serde(default = "default_passive")]
        #[cfg_attr(feature = "cli", arg(long, value_enum, default_value = "passive", hide_possible_values = true))]
        on_stop: WckOnStop,
    }
);

/// What a `wck.teach` recorded (also after a stop or a failure: the report's `failed`
/// says why it ended).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, JsonSchema)]
pub struct TeachSummary {
    /// The servos, 0..N-1.
    pub ids: Vec<u8>,
    /// The torque level written into the poses.
    pub torque: u8,
    /// How many poses were recorded.
    pub recorded: u64,
    /// The poses, in order (absent for a front end that takes them as they come:
    /// [`crate::catalogue::Interaction::keep_poses`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub poses: Option<Vec<Pose>>,
}

impl Teach {
    /// The recording's arguments, validated.
    fn args(&self) -> R<TeachArgs> {
        if self.pose_ms > MAX_POSE_MS {
            return Err(OpError::invalid(
                "--pose-ms",
                self.pose_ms,
                format!("allowed: 0..={MAX_POSE_MS} ms"),
            ));
        }
        let trigger = match (self.rate_hz, self.duration) {
            (None, None) => TeachTrigger::Events {
                pose_ms: self.pose_ms,
            },
            (rate, duration) => TeachTrigger::Rate {
                rate_hz: bounds::WCK_RATE_HZ.check("--rate-hz", rate.unwrap_or(10.0))?,
                duration: duration.map(|d| secs("--duration", d)).transpose()?,
            },
        };
        let args = TeachArgs {
            ids: self.ids.parse("<IDS>")?,
            trigger,
            torque: torque(self.torque)?,
            on_stop: self.on_stop.into(),
        };
        args.check()?;
        Ok(args)
    }
}

impl Operation for Teach {
    const OP: &'static str = "wck.teach";
    const FAMILY: Family = Family::Wck;
    const DOC: OpDoc = OpDoc {
        args: "`ids` 0..N-1, `rate_hz` (0.1..=200), `duration` s (0.1..=3600), `pose_ms` \
               (0..=600000), `torque`, `on_stop`; without `rate_hz` and `duration` a pose \
               per record event of the front end's `Interaction`",
        report: "no rows; `summary`: `ids`, `torque`, `recorded`, `poses` (`ms`, \
                 `positions`; also after a stop: `failed` says why it ended)",
        confirm: "-",
    };
    type Row = NoRow;
    type Summary = TeachSummary;

    fn bus(&self) -> Option<&str> {
        self.bus.as_deref()
    }

    fn effect(&self) -> Effect {
        Effect::Motion
    }

    fn moved(&self) -> Result<Option<Moved>, OpError> {
        let args = self.args()?;
        let ids = args.ids.iter().map(|i| i.get()).collect();
        Ok(Some(moved(self.bus(), ids)))
    }

    fn check(&self) -> Result<Confirm, OpError> {
        self.args().map(|_| Confirm::NONE)
    }

    fn plan(&self, baud: BaudRate) -> Result<Plan, OpError> {
        Ok(plan_of(
            Self::OP,
            &self.args()?.plan(),
            baud,
            ConfirmClass::None,
        ))
    }

    /// Records until the duration, the front end's finish event, a stop or a failure;
    /// the poses recorded before a stop or a failure are the report's still.
    fn run(&self, cx: &mut RunCx<'_, '_>) -> Result<Report<NoRow, TeachSummary>, OpError> {
        let args = self.args()?;
        let port = cx.station.wck(self.bus())?;
        let keep = cx.interaction.keep_poses();
        let mut poses = Vec::new();
        let mut recorded = 0u64;
        let result = {
            let cell = RefCell::new(&mut *cx.interaction);
            let mut events = |wait| cell.borrow_mut().teach_event(wait);
            let mut on_pose = |pose: &Pose| {
                recorded += 1;
                if keep {
                    poses.push(pose.clone());
                }
                cell.borrow_mut().pose(pose)
            };
            wops::teach(
                &mut *port.lock(),
                &args,
                cx.control,
                &mut events,
                &mut on_pose,
            )
        };
        let mut out = Report::new(Self::OP, port.name()).summary(TeachSummary {
            ids: args.ids.iter().map(|i: &ServoId| i.get()).collect(),
            torque: args.torque.get(),
            recorded,
            poses: keep.then_some(poses),
        });
        if let Err(e) = result {
            out.fail(e.kind(), e.to_string());
        }
        Ok(out)
    }
}
