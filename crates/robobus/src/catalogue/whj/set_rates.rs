//! `whj.set-rates`: joints' CAN FD bit rates changed, read back and saved, with what to do
//! next; [`ops`] runs it.

use robobus_wck::BaudRate;
use robobus_whj::JointId;
use robobus_whj::timing::BitRates;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::{R, plan_of};
use crate::catalogue::args::Ids;
use crate::catalogue::bounds::ConfirmClass;
use crate::catalogue::operation::{Confirm, OpDoc, Operation, Report, RunCx};
use crate::catalogue::plan::WhjSteps;
use crate::catalogue::wck::request;
use crate::catalogue::{Effect, Family, Plan};
use crate::ops::whj::rates::{self as ops, RatesReport};
use crate::ops::{DeviceResult, OpError};

request!(cli
    /// `whj.set-rates`: sets joints' CAN FD bit rates (registers 0x08 / 0x09), reads them
    /// back and saves them. The joints keep the old rates until they are power-cycled and
    /// answer only at the new ones after that: the adapter must follow (the report's
    /// summary says how, and how to find a joint that is lost).
    SetRates {
        /// Joint IDs, e.g. `1-6`: every joint on a bus must be at the bus's rates.
        #[cfg_attr(feature = "cli", arg(value_parser = crate::catalogue::whj::cli::joints))]
        joints: Ids,
        /// Arbitration bit rate, bit/s: 250000, 500000 or 1000000.
        #[cfg_attr(feature = "cli", arg(long))]
        bitrate: u32,
        /// Data bit rate, bit/s: 250000, 500000, 1000000, 2000000, 4000000 or 5000000, at
        /// least the arbitration rate.
        #[cfg_attr(feature = "cli", arg(long))]
        dbitrate: u32,
        /// Confirms the change (the joints must then be reached at the new rates).
        #[serde(default)]
        #[cfg_attr(feature = "cli", arg(skip))]
        confirm: bool,
    }
);

/// What to do after the change (present only when a joint saved the new rates).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, JsonSchema)]
pub struct SetRatesSummary {
    /// Power-cycle the joints, set the adapter to the new rates (the command), and how to
    /// find a joint that is lost; naming the joints that saved when some did not.
    pub next: String,
}

/// What a bit-rate change needs confirmed.
pub(crate) const SET_RATES_CONFIRM: &str = "This changes the joints' CAN FD bit rates in \
     flash: after their next power cycle they answer only on a bus at the new rates.";

impl SetRates {
    fn parsed(&self) -> R<(Vec<JointId>, BitRates)> {
        let ids = self.joints.parse_sorted::<JointId>("<JOINTS>")?;
        Ok((ids, ops::check_rates(self.bitrate, self.dbitrate)?))
    }
}

impl Operation for SetRates {
    const OP: &'static str = "whj.set-rates";
    const FAMILY: Family = Family::Whj;
    const DOC: OpDoc = OpDoc {
        args: "`joints`, `bitrate` (250000 / 500000 / 1000000), `dbitrate` (250000 / 500000 / \
               1000000 / 2000000 / 4000000 / 5000000, at least `bitrate`), `confirm`",
        report: "per joint: `before` and `after` ([arbitration, data] bit/s; written, read \
                 back), `saved`; an enabled joint is refused; `summary.next`, only when a \
                 joint saved (naming the joints that did when some did not): power-cycle the \
                 joints, set the adapter to the new rates (the command), and how to find a \
                 joint that is lost",
        confirm: "register",
    };
    type Row = DeviceResult<u8, RatesReport>;
    type Summary = SetRatesSummary;

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
        self.parsed()
            .map(|_| Confirm::of(ConfirmClass::Register, SET_RATES_CONFIRM))
    }

    /// Each joint's frames, the confirmation, the next steps.
    fn plan(&self, _baud: BaudRate) -> R<Plan> {
        let (ids, rates) = self.parsed()?;
        let mut p = WhjSteps::default();
        for &j in &ids {
            for f in ops::plan_set_rates(j, rates)? {
                p.push(f);
            }
        }
        p.notes.push(format!(
            "per joint (refused while it is enabled): write 0x08 and 0x09, read them back, \
             save to flash; then {}",
            ops::next_steps("<BUS>", rates)
        ));
        Ok(plan_of(Self::OP, p, true, self.check()?))
    }

    fn run(&self, cx: &mut RunCx<'_, '_>) -> Result<Report<Self::Row, SetRatesSummary>, OpError> {
        let (ids, rates) = self.parsed()?;
        let port = cx.station.whj(self.bus())?;
        let results = ops::set_rates(port.bus(), &ids, rates)?;
        // Next steps only for joints that saved new rates: a refused run changed none.
        let next = ops::next_steps_after(port.name(), port.can_interface(), rates, &results);
        let mut report = Report::devices_with(Self::OP, port.name(), results);
        report.summary = next.map(|next| SetRatesSummary { next });
        Ok(report)
    }
}
