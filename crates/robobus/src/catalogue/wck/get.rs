//! `wck.get`: read a parameter of a servo (gains, I gain, speed, over-load, boundaries,
//! I/O).

use robobus_wck::{BaudRate, Command};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::common::{ParamRow, run_steps};
use super::{Param, R, plan_of, sid};
use crate::catalogue::bounds::ConfirmClass;
use crate::catalogue::operation::{Confirm, OpDoc, Operation, Report, RunCx};
use crate::catalogue::{Effect, Family, Plan};
use crate::ops::DeviceResult;
use crate::ops::wck::WckPlan;

request!(
    /// `wck.get`: read a parameter of a servo.
    Get {
        /// The parameter: `gains`, `i-gain`, `speed`, `overload`, `bounds`, `io`.
        param: Param,
        /// Servo ID, 0..=30.
        id: u32,
    }
);

impl Get {
    /// The read's packet.
    fn steps(&self) -> R<WckPlan> {
        let id = sid(self.id)?;
        Ok(WckPlan::one(match self.param {
            Param::Gains => Command::GainRead { id },
            Param::IGain => Command::IGainRead { id },
            Param::Speed => Command::SpeedRead { id },
            Param::Overload => Command::OverloadRead { id },
            Param::Bounds => Command::BoundaryRead { id },
            Param::Io => Command::IoRead { id },
        }))
    }
}

impl Operation for Get {
    const OP: &'static str = "wck.get";
    const FAMILY: Family = Family::Wck;
    const DOC: OpDoc = OpDoc {
        args: "`param` (gains, i-gain, speed, overload, bounds, io), `id`",
        report: "the parameter: `p_gain` `d_gain` / `i_gain` / `speed` `accel` / \
                 `milliamps` `overload_code` / `lower` `lower_degrees` `upper` \
                 `upper_degrees` / `outputs` `do1` `do2` `adc` `adc_volts`",
        confirm: "-",
    };
    type Row = DeviceResult<u8, ParamRow>;
    type Summary = ();

    fn bus(&self) -> Option<&str> {
        self.bus.as_deref()
    }

    fn effect(&self) -> Effect {
        Effect::Read
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
            "get",
            &self.steps()?,
            ParamRow::of,
        )
    }
}
