//! `wck.set-id` (A-1 (14), EEPROM): a servo's new ID, verified at the new ID; needs
//! `confirm`.

use robobus_wck::{BaudRate, Command, ExtServoId, Reply};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::common::run_steps;
use super::{R, byte, confirm_of, plan_of, sid};
use crate::catalogue::bounds::ConfirmClass;
use crate::catalogue::operation::{Confirm, OpDoc, Operation, Report, RunCx};
use crate::catalogue::{Effect, Family, Plan};
use crate::ops::DeviceResult;
use crate::ops::wck::WckPlan;

request!(cli
    /// `wck.set-id` (A-1 (14), EEPROM): a new ID; needs `confirm`.
    SetId {
        /// Current ID, 0..=30.
        #[cfg_attr(feature = "cli", arg(value_parser = crate::catalogue::wck::cli::servo_id))]
        id: u32,
        /// New ID, 0..=253.
        #[cfg_attr(feature = "cli", arg(value_parser = crate::catalogue::wck::cli::ext_servo_id))]
        new_id: u32,
        /// Confirms the EEPROM write.
        #[serde(default)]
        #[cfg_attr(feature = "cli", arg(skip))]
        confirm: bool,
    }
);

/// The servo's new ID (`id` is the ID it had).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, JsonSchema)]
pub struct SetIdRow {
    /// The ID it answers at now, verified.
    pub new_id: u8,
}

impl SetId {
    /// The write's packet.
    fn steps(&self) -> R<WckPlan> {
        Ok(WckPlan::one(Command::IdSet {
            id: sid(self.id)?,
            new_id: byte("<NEW_ID>", self.new_id, ExtServoId::new)?,
        }))
    }
}

impl Operation for SetId {
    const OP: &'static str = "wck.set-id";
    const FAMILY: Family = Family::Wck;
    const DOC: OpDoc = OpDoc {
        args: "`id`, `new_id`",
        report: "`new_id`, verified at the new ID",
        confirm: "ID",
    };
    type Row = DeviceResult<u8, SetIdRow>;
    type Summary = ();

    fn bus(&self) -> Option<&str> {
        self.bus.as_deref()
    }

    fn effect(&self) -> Effect {
        Effect::Configure
    }

    fn confirmed(&self) -> bool {
        self.confirm
    }

    fn confirm(&mut self) {
        self.confirm = true;
    }

    fn check(&self) -> R<Confirm> {
        self.steps().map(|_| confirm_of(ConfirmClass::Id))
    }

    fn plan(&self, baud: BaudRate) -> R<Plan> {
        Ok(plan_of(Self::OP, &self.steps()?, baud, ConfirmClass::Id))
    }

    fn run(&self, cx: &mut RunCx<'_, '_>) -> R<Report<Self::Row, ()>> {
        run_steps(
            cx,
            Self::OP,
            self.bus(),
            "set-id",
            &self.steps()?,
            |_, reply| match reply? {
                Reply::Id(id) => Some(SetIdRow { new_id: id.get() }),
                _ => None,
            },
        )
    }
}
