//! `wck.sync-move` (A-1 (2)): servos 0..N-1 moved at once by one packet, which has no
//! reply.

use robobus_wck::{BaudRate, Command, SyncMove as SyncMoveCmd};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::common::{All, NO_REPLY, run_steps};
use super::{R, moved, plan_of, pos, servos, torque};
use crate::catalogue::bounds::ConfirmClass;
use crate::catalogue::operation::{Confirm, OpDoc, Operation, Report, RunCx};
use crate::catalogue::{Effect, Family, Moved, Plan};
use crate::ops::wck::WckPlan;
use crate::ops::{DeviceResult, OpError};

request!(cli
    /// `wck.sync-move` (A-1 (2)): servos 0..N-1 at once, no reply.
    SyncMove {
        /// Target positions of servos 0, 1, 2, ... (1..=31 values, each 0..=254).
        #[cfg_attr(feature = "cli", arg(required = true, num_args = 1..=31, value_parser = crate::catalogue::wck::cli::position))]
        positions: Vec<u32>,
        /// Torque level, 0 (maximum) ..= 4 (minimum).
        #[serde(default)]
        #[cfg_attr(feature = "cli", arg(long, default_value = "0", value_parser = crate::catalogue::wck::cli::torque))]
        torque: u32,
    }
);

/// What the synchronized move sent (`id` `"all"`: one packet for every servo).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, JsonSchema)]
pub struct SyncMoveRow {
    /// The positions of servos 0, 1, ..., 0..=254.
    pub positions: Vec<u8>,
    /// The torque level, 0..=4.
    pub torque: u8,
    /// `none (the command has no reply)`.
    pub reply: String,
}

impl SyncMove {
    /// The move's packet.
    fn steps(&self) -> R<WckPlan> {
        let ps = self
            .positions
            .iter()
            .map(|&p| pos("<POSITIONS>", p))
            .collect::<R<Vec<_>>>()?;
        let sync = SyncMoveCmd::new(torque(self.torque)?, &ps).map_err(|e| {
            OpError::invalid(
                "<POSITIONS>",
                ps.len(),
                format!("{e} (one position per servo 0..=30)"),
            )
        })?;
        Ok(WckPlan::one(Command::SyncMove(sync)))
    }
}

impl Operation for SyncMove {
    const OP: &'static str = "wck.sync-move";
    const FAMILY: Family = Family::Wck;
    const DOC: OpDoc = OpDoc {
        args: "`positions` [0..=254], `torque`",
        report: "one row, `id` `all`: `positions`, `torque`, `reply` (the command has none)",
        confirm: "-",
    };
    type Row = DeviceResult<All, SyncMoveRow>;
    type Summary = ();

    fn bus(&self) -> Option<&str> {
        self.bus.as_deref()
    }

    fn effect(&self) -> Effect {
        Effect::Motion
    }

    /// Servos 0..N-1, N the number of positions.
    fn moved(&self) -> R<Option<Moved>> {
        self.steps()?;
        Ok(Some(moved(self.bus(), servos(self.positions.len()))))
    }

    fn check(&self) -> R<Confirm> {
        self.steps().map(|_| Confirm::NONE)
    }

    fn plan(&self, baud: BaudRate) -> R<Plan> {
        Ok(plan_of(Self::OP, &self.steps()?, baud, ConfirmClass::None))
    }

    fn run(&self, cx: &mut RunCx<'_, '_>) -> R<Report<Self::Row, ()>> {
        run_steps(
            cx,
            Self::OP,
            self.bus(),
            "sync-move",
            &self.steps()?,
            |c, reply| match (c, reply) {
                (Command::SyncMove(sync), None) => Some(SyncMoveRow {
                    positions: sync.positions().iter().map(|p| p.get()).collect(),
                    torque: sync.torque().get(),
                    reply: NO_REPLY.to_owned(),
                }),
                _ => None,
            },
        )
    }
}
