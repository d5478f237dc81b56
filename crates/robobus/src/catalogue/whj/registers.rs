//! `whj.registers`: the register table, as the library knows it (nothing is sent).

use robobus_wck::BaudRate;
use robobus_whj::REGISTERS;
use robobus_whj::registers::{SafetyClass, safety_class};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::{R, plan_of};
use crate::catalogue::operation::{Confirm, OpDoc, Operation, Report, RunCx};
use crate::catalogue::plan::WhjSteps;
use crate::catalogue::wck::request;
use crate::catalogue::{Effect, Family, Plan};
use crate::ops::OpError;

request!(cli
    /// `whj.registers`: the register table (nothing sent).
    Registers {}
);

/// One register of the table.
#[derive(Debug, Clone, PartialEq, Serialize, JsonSchema)]
pub struct RegisterRow {
    /// Its address.
    pub id: u8,
    /// Its name (`SYS_ID`, `cur_position`).
    pub name: &'static str,
    /// The unit symbol of its value (empty: a plain number).
    pub unit: &'static str,
    /// Units per count, where the unit has a fixed scale.
    pub scale: Option<f64>,
    /// The documented range, raw, `[min, max]`.
    pub range: Option<[i32; 2]>,
    /// Whether it can be written.
    pub writable: bool,
    /// What it holds.
    pub meaning: &'static str,
    /// Its safety class: `plain`, `confirm`, `motion` or `never`.
    pub safety: &'static str,
    /// What a write of it does, unless `plain`.
    pub safety_note: Option<&'static str>,
}

impl Operation for Registers {
    const OP: &'static str = "whj.registers";
    const FAMILY: Family = Family::Whj;
    const DOC: OpDoc = OpDoc {
        args: "-",
        report: "the register table (nothing sent)",
        confirm: "-",
    };
    type Row = RegisterRow;
    type Summary = ();

    fn bus(&self) -> Option<&str> {
        self.bus.as_deref()
    }

    fn effect(&self) -> Effect {
        Effect::Read
    }

    fn check(&self) -> R<Confirm> {
        Ok(Confirm::NONE)
    }

    fn plan(&self, _baud: BaudRate) -> R<Plan> {
        Ok(plan_of(Self::OP, WhjSteps::default(), false, Confirm::NONE))
    }

    fn run(&self, _cx: &mut RunCx<'_, '_>) -> Result<Report<RegisterRow, ()>, OpError> {
        let rows = REGISTERS
            .iter()
            .map(|r| {
                let safety = safety_class(r.addr);
                RegisterRow {
                    id: r.addr.get(),
                    name: r.name,
                    unit: r.unit.symbol(),
                    scale: r.unit.scale(),
                    range: r.range.map(|(a, b)| [a, b]),
                    writable: r.access.is_writable(),
                    meaning: r.meaning,
                    safety: safety.keyword(),
                    safety_note: match safety {
                        SafetyClass::Plain => None,
                        SafetyClass::Confirm(t)
                        | SafetyClass::Motion(t)
                        | SafetyClass::Never(t) => Some(t),
                    },
                }
            })
            .collect();
        Ok(Report::with_rows(Self::OP, "(none)", rows))
    }
}
