//! `whj.set-rates`: joints' CAN FD bit rates changed, read back and saved, with what to do
//! next; [`ops::rates`] runs it.

use robobus_whj::JointId;

use super::{Job, Prepared, R, prepared};
use crate::catalogue::args::Ids;
use crate::catalogue::bounds::ConfirmClass;
use crate::catalogue::plan::WhjSteps;
use crate::catalogue::wck::request;
use crate::ops::whj::rates as ops;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

request!(
    /// `whj.set-rates`: sets joints' CAN FD bit rates (registers 0x08 / 0x09), reads them
    /// back and saves them. The joints keep the old rates until they are power-cycled and
    /// answer only at the new ones after that: the adapter must follow (the report's
    /// summary says how, and how to find a joint that is lost).
    SetRates {
        /// Joint IDs (`"1-6"`): every joint on a bus must be at the bus's rates.
        joints: Ids,
        /// Arbitration bit rate, bit/s: 250000, 500000 or 1000000.
        bitrate: u32,
        /// Data bit rate, bit/s: 250000, 500000, 1000000, 2000000, 4000000 or 5000000, at
        /// least the arbitration rate.
        dbitrate: u32,
        /// Confirms the change (the joints must then be reached at the new rates).
        #[serde(default)]
        confirm: bool,
    }
);

/// What a bit-rate change needs confirmed.
pub(crate) const SET_RATES_CONFIRM: &str = "This changes the joints' CAN FD bit rates in \
     flash: after their next power cycle they answer only on a bus at the new rates.";

/// `whj.set-rates`: each joint's frames, the confirmation, the next steps.
pub(super) fn set_rates(r: &SetRates) -> R<Prepared> {
    let ids: Vec<JointId> = r.joints.parse_sorted::<JointId>("<JOINTS>")?;
    let rates = ops::check_rates(r.bitrate, r.dbitrate)?;
    let mut p = WhjSteps::default();
    for &j in &ids {
        for f in ops::plan_set_rates(j, rates)? {
            p.push(f);
        }
    }
    p.notes.push(format!(
        "per joint (refused while it is enabled): write 0x08 and 0x09, read them back, save \
         to flash; then {}",
        ops::next_steps("<BUS>", rates)
    ));
    let mut pr = prepared(p, Job::SetRates(ids, rates));
    pr.confirm = ConfirmClass::Register;
    pr.confirm_text = SET_RATES_CONFIRM.into();
    pr.confirmed = r.confirm;
    Ok(pr)
}

request!(
    /// `whj.can-health`: the bus's CAN interface as the kernel reports it (netlink): the
    /// controller's state (error-active, error-warning, error-passive, bus-off), its error
    /// counters, its state changes and restarts, and the advice for bus-off and
    /// error-passive. Nothing is sent on the bus; a UDP or simulated bus is a row without
    /// a controller.
    /// A telemetry stream can take it.
    CanHealth {}
);
