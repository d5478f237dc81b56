//! `wck.tune`: the same position step with each gain set, the responses measured and the
//! best set found (and kept on request).

use robobus_wck::{BaudRate, Command, DGain, PGain};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::{R, confirm_of, moved, plan_of, sid, torque};
use crate::catalogue::args::byte;
use crate::catalogue::bounds::ConfirmClass;
use crate::catalogue::operation::{Confirm, OpDoc, Operation, Report, RunCx};
use crate::catalogue::{Effect, Family, Moved, Plan};
use crate::ops::OpError;
use crate::ops::wck::WckPlan;
use crate::ops::wck::tune::{self as wtune, Keep, TuneArgs, TuneReport};

const fn d20() -> u32 {
    20
}
const fn d1000() -> u32 {
    1000
}

request!(cli
    /// `wck.tune`: the same position step with each gain set (runtime gains), the
    /// responses measured (rise, overshoot, settling, steady-state error) and the best
    /// one found; kept in runtime or EEPROM (`confirm`) on request.
    Tune {
        /// Servo ID, 0..=30.
        #[cfg_attr(feature = "cli", arg(value_parser = crate::catalogue::wck::cli::servo_id))]
        id: u32,
        /// The gain sets, each `P,D` (1..=8 sets; in JSON `[[P, D], ...]`), e.g.
        /// `--gains 20,30 --gains 40,20`.
        #[cfg_attr(feature = "cli", arg(long, required = true, value_name = "P,D", value_parser = crate::catalogue::wck::cli::gains))]
        gains: Vec<[u32; 2]>,
        /// The step, position steps (2..=60), away from the nearer boundary.
        #[serde(default = "d20")]
        #[cfg_attr(feature = "cli", arg(long, default_value_t = 20, value_parser = crate::catalogue::wck::cli::small))]
        amplitude: u32,
        /// How long each step is recorded, ms (100..=5000).
        #[serde(default = "d1000")]
        #[cfg_attr(feature = "cli", arg(long, default_value_t = 1000))]
        hold_ms: u32,
        /// Torque level of the moves, 0 (strongest)..=4.
        #[serde(default)]
        #[cfg_attr(feature = "cli", arg(long, default_value = "0", value_parser = crate::catalogue::wck::cli::torque))]
        torque: u32,
        /// Keep the best set: none (the runtime gains go back to the EEPROM's), runtime
        /// (until power-off) or eeprom (needs confirming).
        #[serde(default)]
        #[cfg_attr(feature = "cli", arg(long, value_enum, default_value = "none"))]
        keep: KeepArg,
        /// Confirms an EEPROM keep.
        #[serde(default)]
        #[cfg_attr(feature = "cli", arg(skip))]
        confirm: bool,
    }
);

/// What `wck.tune` keeps.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, JsonSchema)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
#[serde(rename_all = "kebab-case")]
pub enum KeepArg {
    /// Nothing.
    #[default]
    None,
    /// The runtime gains.
    Runtime,
    /// The EEPROM gains.
    Eeprom,
}

/// One gain set's response (its trace is in the summary's `responses`).
#[derive(Debug, Clone, PartialEq, Serialize, JsonSchema)]
pub struct TuneRow {
    /// The servo.
    pub id: u8,
    /// P gain.
    pub p: u8,
    /// D gain.
    pub d: u8,
    /// Rise time (10 % to 90 % of the step), ms; `null` if it never got to 90 %.
    pub rise_ms: Option<f64>,
    /// Overshoot, % of the step.
    pub overshoot_pct: f64,
    /// Settling time (2 % band), ms; `null` if it never settled.
    pub settling_ms: Option<f64>,
    /// Mean error over the last 10 % of the hold, position steps.
    pub steady_state_error: f64,
}

impl Tune {
    /// The run's arguments, validated.
    fn args(&self) -> R<TuneArgs> {
        let mut gains = Vec::new();
        for &[p, d] in &self.gains {
            gains.push(crate::wck::Gains {
                p: byte("--gains P", p, PGain::new)?,
                d: byte("--gains D", d, DGain::new)?,
            });
        }
        let args = TuneArgs {
            id: sid(self.id)?,
            amplitude: u8::try_from(self.amplitude).unwrap_or(u8::MAX),
            gains,
            hold_ms: self.hold_ms,
            torque: torque(self.torque)?,
            keep: match self.keep {
                KeepArg::None => Keep::None,
                KeepArg::Runtime => Keep::Runtime,
                KeepArg::Eeprom => Keep::Eeprom,
            },
        };
        args.validate()?;
        Ok(args)
    }

    /// What it needs confirmed: an EEPROM keep.
    const fn class(&self) -> ConfirmClass {
        match self.keep {
            KeepArg::Eeprom => ConfirmClass::NonVolatile,
            KeepArg::None | KeepArg::Runtime => ConfirmClass::None,
        }
    }
}

impl Operation for Tune {
    const OP: &'static str = "wck.tune";
    const FAMILY: Family = Family::Wck;
    const DOC: OpDoc = OpDoc {
        args: "`id`, `gains` (`[[P, D], ...]`), `amplitude`=20, `hold_ms`=1000, `torque`, \
               `keep` (`none`, `runtime`, `eeprom`)",
        report: "one row per gain set: `p`, `d`, `rise_ms`, `overshoot_pct`, `settling_ms`, \
                 `steady_state_error`; `summary`: `start`, `target`, `best` (`null` on a \
                 tie), `tied` (the sets whose responses differ by no more than the \
                 measurement's resolution: a reading in settling time, a position step in \
                 overshoot), `kept` (a tie keeps the first tied set) and each set's trace \
                 (`responses`); every step starts with the servo at rest at the start, and \
                 the run returns with it back there",
        confirm: "EEPROM with `keep: eeprom`",
    };
    type Row = TuneRow;
    type Summary = TuneReport;

    fn bus(&self) -> Option<&str> {
        self.bus.as_deref()
    }

    fn effect(&self) -> Effect {
        Effect::Motion
    }

    fn moved(&self) -> Result<Option<Moved>, OpError> {
        let args = self.args()?;
        Ok(Some(moved(self.bus(), vec![args.id.get()])))
    }

    fn confirmed(&self) -> bool {
        self.confirm
    }

    fn confirm(&mut self) {
        self.confirm = true;
    }

    fn check(&self) -> Result<Confirm, OpError> {
        self.args()?;
        Ok(confirm_of(self.class()))
    }

    fn plan(&self, baud: BaudRate) -> Result<Plan, OpError> {
        let args = self.args()?;
        let id = args.id;
        let mut plan = WckPlan::default();
        plan.push(Command::GainRead { id });
        plan.push(Command::BoundaryRead { id });
        plan.push(Command::StatusRead { id });
        plan.notes.push(format!(
            "then for each of the {} gain sets: runtime gains (A-1 (12)), a move to the \
             present position and 0.5 s of status reads to settle, a step of {} \
             positions away from the nearer boundary and {} ms of status reads; then \
             back to the start, runtime gains {}",
            args.gains.len(),
            args.amplitude,
            args.hold_ms,
            match args.keep {
                Keep::None => "as in EEPROM",
                Keep::Runtime => "the best set's",
                Keep::Eeprom => "and EEPROM gains the best set's",
            }
        ));
        Ok(plan_of(Self::OP, &plan, baud, self.class()))
    }

    fn run(&self, cx: &mut RunCx<'_, '_>) -> Result<Report<TuneRow, TuneReport>, OpError> {
        let args = self.args()?;
        let port = cx.station.wck(self.bus())?;
        let r = wtune::tune(&mut *port.lock(), &args, self.confirm, cx.control)?;
        let rows = r
            .responses
            .iter()
            .map(|x| TuneRow {
                id: args.id.get(),
                p: x.p,
                d: x.d,
                rise_ms: x.rise_ms,
                overshoot_pct: x.overshoot_pct,
                settling_ms: x.settling_ms,
                steady_state_error: x.steady_state_error,
            })
            .collect();
        Ok(Report::with_rows(Self::OP, port.name(), rows).summary(r))
    }
}
