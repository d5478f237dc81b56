//! `wck.set-baud` (A-1 (7), EEPROM): a servo's baud rate.

use robobus_wck::{BaudRate, Command, Reply};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::common::run_steps;
use super::{R, confirm_of, plan_of, sid};
use crate::catalogue::bounds::ConfirmClass;
use crate::catalogue::operation::{Confirm, OpDoc, Operation, Report, RunCx};
use crate::catalogue::{Effect, Family, Plan};
use crate::ops::wck::WckPlan;
use crate::ops::{DeviceResult, OpError};

request!(cli
    /// `wck.set-baud` (A-1 (7), EEPROM): a servo's baud rate; needs `confirm`.
    SetBaud {
        /// Servo ID, 0..=30.
        #[cfg_attr(feature = "cli", arg(value_parser = crate::catalogue::wck::cli::servo_id))]
        id: u32,
        /// New baud rate, bit/s: 4800, 9600, 38400, 57600, 115200, 230400, 460800 or
        /// 921600.
        #[cfg_attr(feature = "cli", arg(value_parser = crate::catalogue::wck::cli::baud))]
        rate: u32,
        /// Confirms the EEPROM write.
        #[serde(default)]
        #[cfg_attr(feature = "cli", arg(skip))]
        confirm: bool,
    }
);

/// A servo's new rate, verified at that rate.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, JsonSchema)]
pub struct SetBaudRow {
    /// The rate the servo answers at now, bit/s.
    pub baud: u32,
}

impl SetBaud {
    /// The one packet it sends.
    fn steps(&self) -> R<WckPlan> {
        let baud = BaudRate::from_bits_per_second(self.rate)
            .map_err(|e| OpError::invalid("<RATE>", self.rate, e.to_string()))?;
        Ok(WckPlan::one(Command::BaudSet {
            id: sid(self.id)?,
            baud,
        }))
    }
}

impl Operation for SetBaud {
    const OP: &'static str = "wck.set-baud";
    const FAMILY: Family = Family::Wck;
    const DOC: OpDoc = OpDoc {
        args: "`id`, `rate` bit/s",
        report: "per servo: `baud` (verified at the new rate)",
        confirm: "EEPROM",
    };
    type Row = DeviceResult<u8, SetBaudRow>;
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
        self.steps()?;
        Ok(confirm_of(ConfirmClass::NonVolatile))
    }

    fn plan(&self, baud: BaudRate) -> R<Plan> {
        Ok(plan_of(
            Self::OP,
            &self.steps()?,
            baud,
            ConfirmClass::NonVolatile,
        ))
    }

    fn run(&self, cx: &mut RunCx<'_, '_>) -> R<Report<Self::Row, ()>> {
        run_steps(
            cx,
            Self::OP,
            self.bus(),
            "set-baud",
            &self.steps()?,
            |_, reply| match reply? {
                Reply::Baud(b) => Some(SetBaudRow {
                    baud: b.bits_per_second(),
                }),
                _ => None,
            },
        )
    }
}
