//! `wck.set`: write a parameter of a servo (gains, I gain, speed, over-load, boundaries,
//! outputs), into EEPROM unless `runtime`; an EEPROM write needs `confirm`.

use robobus_wck::{
    Accel, BaudRate, Boundaries, Command, DGain, IGain, IoBits, Overload, PGain, Speed,
};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::common::{ParamRow, run_steps};
use super::{Param, R, byte, confirm_of, need, plan_of, pos, sid};
use crate::catalogue::bounds::ConfirmClass;
use crate::catalogue::operation::{Confirm, OpDoc, Operation, Report, RunCx};
use crate::catalogue::{Effect, Family, Plan};
use crate::ops::wck::WckPlan;
use crate::ops::{DeviceResult, OpError};

request!(
    /// `wck.set`: write a parameter (EEPROM unless `runtime`; needs `confirm`).
    Set {
        /// The parameter: `gains` (p, d), `i-gain` (i), `speed` (speed, accel), `overload`
        /// (milliamps), `bounds` (lower, upper), `io` (outputs).
        param: Param,
        /// Servo ID, 0..=30.
        id: u32,
        /// P gain 1..=254 (gains).
        #[serde(default)]
        p: Option<u32>,
        /// D gain 0..=254 (gains).
        #[serde(default)]
        d: Option<u32>,
        /// I gain 0..=254 (i-gain).
        #[serde(default)]
        i: Option<u32>,
        /// Speed level 0..=30 (speed).
        #[serde(default)]
        speed: Option<u32>,
        /// Acceleration range 20..=100 (speed).
        #[serde(default)]
        accel: Option<u32>,
        /// Over-load threshold in mA, 400..=1800 (overload).
        #[serde(default)]
        milliamps: Option<u32>,
        /// Lower boundary 0..=254 (bounds).
        #[serde(default)]
        lower: Option<u32>,
        /// Upper boundary 0..=254 (bounds).
        #[serde(default)]
        upper: Option<u32>,
        /// Output bits 0..=3 (io).
        #[serde(default)]
        outputs: Option<u32>,
        /// Only until power-off (gains, i-gain, speed), not in EEPROM.
        #[serde(default)]
        runtime: bool,
        /// Confirms an EEPROM write (the CLI's `--yes`).
        #[serde(default)]
        confirm: bool,
    }
);

impl Set {
    /// The write's command, its values validated.
    pub(super) fn command(&self) -> R<Command> {
        let id = sid(self.id)?;
        Ok(match self.param {
            Param::Gains => {
                let p = byte("<P>", need("<P>", self.p)?, PGain::new)?;
                let d = byte("<D>", need("<D>", self.d)?, DGain::new)?;
                if self.runtime {
                    Command::RuntimeGainSet { id, p, d }
                } else {
                    Command::GainSet { id, p, d }
                }
            }
            Param::IGain => {
                let i = byte("<I>", need("<I>", self.i)?, IGain::new)?;
                if self.runtime {
                    Command::RuntimeIGainSet { id, i }
                } else {
                    Command::IGainSet { id, i }
                }
            }
            Param::Speed => {
                let speed = byte("<SPEED>", need("<SPEED>", self.speed)?, Speed::new)?;
                let accel = byte("<ACCEL>", need("<ACCEL>", self.accel)?, Accel::new)?;
                if self.runtime {
                    Command::RuntimeSpeedSet { id, speed, accel }
                } else {
                    Command::SpeedSet { id, speed, accel }
                }
            }
            Param::Overload => {
                let ma = need("<MILLIAMPS>", self.milliamps)?;
                Command::OverloadSet {
                    id,
                    overload: Overload::from_milliamps(u16::try_from(ma).unwrap_or(u16::MAX))
                        .map_err(|e| OpError::invalid("<MILLIAMPS>", ma, e.to_string()))?,
                }
            }
            Param::Bounds => {
                let lower = pos("<LOWER>", need("<LOWER>", self.lower)?)?;
                let upper = pos("<UPPER>", need("<UPPER>", self.upper)?)?;
                Command::BoundarySet {
                    id,
                    bounds: Boundaries::new(lower, upper)
                        .map_err(|e| OpError::invalid("<UPPER>", upper.get(), e.to_string()))?,
                }
            }
            Param::Io => Command::IoWrite {
                id,
                outputs: byte("<OUTPUTS>", need("<OUTPUTS>", self.outputs)?, IoBits::new)?,
            },
        })
    }

    /// The write's packet, and whether it writes EEPROM.
    fn steps(&self) -> R<(WckPlan, ConfirmClass)> {
        let plan = WckPlan::one(self.command()?);
        let class = if plan.writes_eeprom() {
            ConfirmClass::NonVolatile
        } else {
            ConfirmClass::None
        };
        Ok((plan, class))
    }
}

impl Operation for Set {
    const OP: &'static str = "wck.set";
    const FAMILY: Family = Family::Wck;
    const DOC: OpDoc = OpDoc {
        args: "`param`, `id`, `p` `d` / `i` / `speed` `accel` / `milliamps` / `lower` `upper` / `outputs`, `runtime`",
        report: "the read-back, as `wck.get` names it (`outputs` `do1` `do2` for io; a runtime \
                 speed has no reply: `speed`, `accel` sent and `reply`)",
        confirm: "EEPROM unless runtime",
    };
    type Row = DeviceResult<u8, ParamRow>;
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
        self.steps().map(|(_, class)| confirm_of(class))
    }

    fn plan(&self, baud: BaudRate) -> R<Plan> {
        let (plan, class) = self.steps()?;
        Ok(plan_of(Self::OP, &plan, baud, class))
    }

    fn run(&self, cx: &mut RunCx<'_, '_>) -> R<Report<Self::Row, ()>> {
        let (plan, _) = self.steps()?;
        run_steps(cx, Self::OP, self.bus(), "set", &plan, ParamRow::of)
    }
}
