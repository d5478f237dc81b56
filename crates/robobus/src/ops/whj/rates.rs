//! A joint's CAN FD bit rates (registers 0x08 / 0x09, kept in flash): changed with
//! read-back and save, and what to do next. The joint keeps talking at its old rates until
//! it is power-cycled (the rates are taken at power-up); from then on it answers only on a
//! bus at the new rates, so the adapter must follow. A joint that is lost answers only at
//! the rates it saved.

use robobus_whj::registers::addr::{SYS_BPS_CANFD_BRT, SYS_BPS_CANFD_DATA};
use robobus_whj::timing::{ARBITRATION_RATES, BitRates, DATA_RATES};
use robobus_whj::{JointId, ReadRange, Request};
use serde::Serialize;

use super::whj;
use crate::ops::{DeviceResult, Failure, OpError};
use crate::whj::JointBus;

/// Checks a rate pair a joint can be set to: the arbitration rate one of
/// [`ARBITRATION_RATES`], the data rate one of [`DATA_RATES`] and no slower.
pub fn check_rates(bitrate: u32, dbitrate: u32) -> Result<BitRates, OpError> {
    let list = |r: &[u32]| r.iter().map(u32::to_string).collect::<Vec<_>>().join(", ");
    if !ARBITRATION_RATES.contains(&bitrate) {
        return Err(OpError::invalid(
            "--bitrate",
            bitrate,
            format!("one of {} bit/s", list(&ARBITRATION_RATES)),
        ));
    }
    if !DATA_RATES.contains(&dbitrate) {
        return Err(OpError::invalid(
            "--dbitrate",
            dbitrate,
            format!("one of {} bit/s", list(&DATA_RATES)),
        ));
    }
    if dbitrate < bitrate {
        return Err(OpError::invalid(
            "--dbitrate",
            dbitrate,
            format!("at least the arbitration rate {bitrate} bit/s"),
        ));
    }
    BitRates::new(bitrate, dbitrate)
        .ok_or_else(|| OpError::invalid("--bitrate", bitrate, "a rate above 0"))
}

fn codes(rates: BitRates) -> Result<(u16, u16), OpError> {
    rates.codes().ok_or_else(|| {
        OpError::invalid(
            "--bitrate",
            rates.nominal.get(),
            "rates a joint can be set to",
        )
    })
}

/// The frames of one joint's change: write both codes, read them back, save.
pub fn plan_set_rates(id: JointId, rates: BitRates) -> Result<Vec<Request>, OpError> {
    let (a, d) = codes(rates)?;
    let bad = |e: &dyn std::fmt::Display| OpError::invalid("<JOINT>", id.get(), e.to_string());
    Ok(vec![
        Request::write(id, SYS_BPS_CANFD_BRT, a).map_err(|e| bad(&e))?,
        Request::write(id, SYS_BPS_CANFD_DATA, d).map_err(|e| bad(&e))?,
        Request::Read {
            joint: id,
            range: ReadRange::new(SYS_BPS_CANFD_BRT, 2).map_err(|e| bad(&e))?,
        },
        Request::save_to_flash(id),
    ])
}

/// What to do after the change on bus `bus` (a SocketCAN interface's name, or a UDP /
/// simulated bus's address) for the new `rates`.
#[must_use]
pub fn next_steps(bus: &str, rates: BitRates) -> String {
    match bus.parse::<robobus_link::FrameLinkSpec>() {
        Ok(robobus_link::FrameLinkSpec::SocketCan(iface)) => {
            next_steps_on(bus, Some(&iface), rates)
        }
        _ => next_steps_on(bus, None, rates),
    }
}

/// What to do after the change on the bus named `bus`, which runs on the SocketCAN
/// interface `iface` (`None`: a UDP or simulated bus), for the new `rates`.
#[must_use]
pub fn next_steps_on(bus: &str, iface: Option<&str>, rates: BitRates) -> String {
    let (b, d) = (rates.nominal.get(), rates.data.get());
    let adapter = match iface {
        Some(iface) => format!(
            "set the adapter to the new rates (`sudo ip link set {iface} down && sudo ip link \
             set {iface} type can bitrate {b} sample-point 0.8 dbitrate {d} dsample-point 0.75 \
             fd on && sudo ip link set {iface} up`)"
        ),
        _ => format!(
            "set the bus to the new rates (a simulator: `robobus sim whj --bitrate {b} \
             --dbitrate {d}`)"
        ),
    };
    format!(
        "the joints answer at the old rates until they are power-cycled, and from then on \
         only at {b} / {d} bit/s: power-cycle them, then {adapter}, and `robobus whj --bus \
         {bus} scan` finds them. Every joint on a bus must be at the bus's rates. A joint that \
         is lost answers only at the rates it saved: set the bus to each pair in turn \
         (arbitration {}; data {}) and scan",
        join(&ARBITRATION_RATES),
        join(&DATA_RATES)
    )
}

/// What to do after a run on the bus `bus` (on the SocketCAN interface `iface`, if any)
/// whose per-joint `results` these are: [`next_steps_on`] when every
/// joint saved the new rates, naming the joints that did when only some did, and nothing
/// when none did (a refused or failed run changed no joint: there is nothing to power-cycle
/// or to set the adapter for).
#[must_use]
pub fn next_steps_after(
    bus: &str,
    iface: Option<&str>,
    rates: BitRates,
    results: &[DeviceResult<u8, RatesReport>],
) -> Option<String> {
    let saved: Vec<String> = results
        .iter()
        .filter(|r| matches!(&r.outcome, crate::ops::Outcome::Ok(x) if x.saved))
        .map(|r| r.id.to_string())
        .collect();
    if saved.is_empty() {
        return None;
    }
    let next = next_steps_on(bus, iface, rates);
    Some(if saved.len() == results.len() {
        next
    } else {
        format!(
            "only joint{} {} saved the new rates (the others kept theirs): for {}, {next}",
            if saved.len() == 1 { "" } else { "s" },
            saved.join(", "),
            if saved.len() == 1 { "it" } else { "them" }
        )
    })
}

fn join(r: &[u32]) -> String {
    r.iter().map(u32::to_string).collect::<Vec<_>>().join(" / ")
}

/// One joint's change.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, schemars::JsonSchema)]
pub struct RatesReport {
    /// The rates it had saved, bit/s (`None`: codes no rate has).
    pub before: Option<[u32; 2]>,
    /// The rates it reads back, bit/s.
    pub after: [u32; 2],
    /// Saved to flash.
    pub saved: bool,
}

/// Sets joints `ids` to `rates`: each must be disabled (flash is written only then);
/// writes both codes, reads them back and saves. A joint that does not answer, or is
/// enabled, is its own failure; the others carry on.
pub fn set_rates(
    bus: &JointBus,
    ids: &[JointId],
    rates: BitRates,
) -> Result<Vec<DeviceResult<u8, RatesReport>>, OpError> {
    let codes = codes(rates)?;
    Ok(ids
        .iter()
        .map(|&id| match set_one(bus, id, codes, rates) {
            Ok(r) => DeviceResult::ok(id.get(), r),
            Err(e) => DeviceResult::failed(id.get(), Failure::from(&e)),
        })
        .collect())
}

fn set_one(
    bus: &JointBus,
    id: JointId,
    (arbitration, data): (u16, u16),
    rates: BitRates,
) -> Result<RatesReport, OpError> {
    let j = bus.joint(id).map_err(whj)?;
    if j.is_enabled().map_err(whj)? {
        return Err(OpError::Refused(format!(
            "joint {}: enabled; its flash is written only while it is disabled (`whj \
             disable {}` first); nothing was written",
            id.get(),
            id.get()
        )));
    }
    let old = j.read_words(SYS_BPS_CANFD_BRT, 2).map_err(whj)?;
    let before = match old.as_slice() {
        [x, y] => BitRates::of_codes(*x, *y).map(|r| [r.nominal.get(), r.data.get()]),
        _ => None,
    };
    j.write_register_raw("SYS_BPS_CANFD_BRT", i32::from(arbitration))
        .map_err(whj)?;
    j.write_register_raw("SYS_BPS_CANFD_DATA", i32::from(data))
        .map_err(whj)?;
    let back = j.read_words(SYS_BPS_CANFD_BRT, 2).map_err(whj)?;
    if back != [arbitration, data] {
        return Err(OpError::Device(format!(
            "joint {}: the bit-rate registers read back {back:?} after writing [{arbitration}, \
             {data}]; not saved (the old rates stay after a power cycle)",
            id.get()
        )));
    }
    j.save_to_flash().map_err(whj)?;
    Ok(RatesReport {
        before,
        after: [rates.nominal.get(), rates.data.get()],
        saved: true,
    })
}
