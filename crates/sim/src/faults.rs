//! Device faults on a schedule, for both simulators: a device that falls silent, is
//! power-cycled (a brown-out) or latches error bits at a given simulation time.
//!
//! A [`FaultSchedule`] is plain data: the simulator that owns the devices asks it which
//! faults are due at its current time ([`FaultSchedule::take_due`]) and applies them
//! (`robobus_sim::wck::Bus::apply_fault`, `robobus_sim::whj::WhjBus::apply_fault`), so a
//! schedule gives the same outcome on the virtual clock and behind an endpoint on the wall
//! clock. The CLI parses `ID@SECONDS` and `JOINT:BITS@SECONDS` with [`DeviceFault::parse`].

use core::fmt;
use core::time::Duration;

/// The longest fault time accepted from text, seconds (one day).
pub const MAX_FAULT_SECONDS: f64 = 86_400.0;

/// What happens to the device.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DeviceFaultKind {
    /// It stops answering (wCK: powered off; WHJ: answers nothing until power-cycled).
    Silent,
    /// Its supply drops and comes back (brown-out): RAM state lost, power-up again.
    PowerCycle,
    /// WHJ only: it latches these error bits (as its firmware does on a fault).
    Error(u16),
}

/// One scheduled fault.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DeviceFault {
    /// Simulation time at which it happens.
    pub at: Duration,
    /// The device (wCK servo ID or WHJ joint ID; every device with that ID).
    pub id: u8,
    /// What happens.
    pub kind: DeviceFaultKind,
}

/// Why a fault given as text was refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{option} {value:?}: {reason}")]
pub struct FaultParseError {
    /// The option (for the message), e.g. `--fault-silent`.
    pub option: String,
    /// The text given.
    pub value: String,
    /// What is wrong and what is allowed.
    pub reason: String,
}

impl DeviceFault {
    /// Parses `ID@SECONDS` (for [`DeviceFaultKind::Silent`] / [`DeviceFaultKind::PowerCycle`])
    /// or `ID:BITS@SECONDS` (for [`DeviceFaultKind::Error`]; `BITS` decimal or `0x` hex,
    /// 1..=0xFFFF). `ids` is the allowed ID range and `option` names the option in errors.
    pub fn parse(
        text: &str,
        kind: DeviceFaultKind,
        ids: core::ops::RangeInclusive<u8>,
        option: &str,
    ) -> Result<Self, FaultParseError> {
        let err = |reason: String| FaultParseError {
            option: option.to_owned(),
            value: text.to_owned(),
            reason,
        };
        let with_bits = matches!(kind, DeviceFaultKind::Error(_));
        let shape = if with_bits {
            "ID:BITS@SECONDS"
        } else {
            "ID@SECONDS"
        };
        let (who, secs) = text
            .split_once('@')
            .ok_or_else(|| err(format!("expected {shape}, e.g. {}", example(with_bits))))?;
        let (id_text, bits) = if with_bits {
            let (i, b) = who
                .split_once(':')
                .ok_or_else(|| err(format!("expected {shape}, e.g. {}", example(true))))?;
            (i, Some(b.trim()))
        } else {
            (who, None)
        };
        let id: u8 = id_text.trim().parse().map_err(|_| {
            err(format!(
                "ID `{}` is not a number (allowed: {}..={})",
                id_text.trim(),
                ids.start(),
                ids.end()
            ))
        })?;
        if !ids.contains(&id) {
            return Err(err(format!(
                "ID {id} out of range (allowed: {}..={})",
                ids.start(),
                ids.end()
            )));
        }
        let seconds: f64 = secs.trim().parse().map_err(|_| {
            err(format!(
                "time `{}` is not a number of seconds (allowed: 0..={MAX_FAULT_SECONDS})",
                secs.trim()
            ))
        })?;
        if !(0.0..=MAX_FAULT_SECONDS).contains(&seconds) {
            return Err(err(format!(
                "time {seconds} s out of range (allowed: 0..={MAX_FAULT_SECONDS})"
            )));
        }
        let kind = match bits {
            Some(b) => {
                // Error bits are a mask, written in hex as the documents write them: a
                // bare `4000` would be read as decimal 4000 = 0x0FA0, six unrelated bits.
                let Some(hex) = b.strip_prefix("0x").or_else(|| b.strip_prefix("0X")) else {
                    return Err(err(format!(
                        "error bits `{b}` need the 0x prefix: they are a hex mask \
                         (allowed: 0x0001..=0xFFFF, for example 0x4000)"
                    )));
                };
                let parsed = u32::from_str_radix(hex, 16).ok();
                match parsed
                    .and_then(|v| u16::try_from(v).ok())
                    .filter(|v| *v != 0)
                {
                    Some(v) => DeviceFaultKind::Error(v),
                    None => {
                        return Err(err(format!(
                            "error bits `{b}` out of range (allowed: 0x0001..=0xFFFF)"
                        )));
                    }
                }
            }
            None => kind,
        };
        Ok(Self {
            at: Duration::from_secs_f64(seconds),
            id,
            kind,
        })
    }
}

fn example(with_bits: bool) -> &'static str {
    if with_bits { "1:0x4000@2.5" } else { "3@2.5" }
}

impl fmt::Display for DeviceFault {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let t = self.at.as_secs_f64();
        match self.kind {
            DeviceFaultKind::Silent => write!(f, "{} falls silent at {t} s", self.id),
            DeviceFaultKind::PowerCycle => write!(f, "{} is power-cycled at {t} s", self.id),
            DeviceFaultKind::Error(bits) => {
                write!(f, "{} latches error {bits:#06x} at {t} s", self.id)
            }
        }
    }
}

/// Faults in time order, handed out once each.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct FaultSchedule {
    faults: Vec<DeviceFault>,
    next: usize,
}

impl FaultSchedule {
    /// A schedule of `faults` (any order; same-time faults keep their order).
    pub fn new(mut faults: Vec<DeviceFault>) -> Self {
        faults.sort_by_key(|f| f.at);
        Self { faults, next: 0 }
    }

    /// Every fault shifted by `offset` (a simulator whose clock does not start at zero).
    #[must_use]
    pub fn shifted(mut self, offset: Duration) -> Self {
        for f in &mut self.faults {
            f.at = f.at.saturating_add(offset);
        }
        self
    }

    /// When the next fault is due, if any is left.
    pub fn next_due(&self) -> Option<Duration> {
        self.faults.get(self.next).map(|f| f.at)
    }

    /// The faults due at `now` that were not handed out yet, in time order.
    pub fn take_due(&mut self, now: Duration) -> &[DeviceFault] {
        let start = self.next;
        while self.faults.get(self.next).is_some_and(|f| f.at <= now) {
            self.next += 1;
        }
        self.faults.get(start..self.next).unwrap_or_default()
    }

    /// Whether no fault is scheduled at all.
    pub fn is_empty(&self) -> bool {
        self.faults.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn faults_parse_with_their_ranges_named() {
        let f = DeviceFault::parse("3@2.5", DeviceFaultKind::Silent, 0..=253, "--fault-silent")
            .unwrap();
        assert_eq!(
            f,
            DeviceFault {
                at: Duration::from_millis(2500),
                id: 3,
                kind: DeviceFaultKind::Silent
            }
        );
        let f = DeviceFault::parse(
            "7:0x4000@1",
            DeviceFaultKind::Error(0),
            1..=30,
            "--fault-error",
        )
        .unwrap();
        assert_eq!(f.kind, DeviceFaultKind::Error(0x4000));
        assert_eq!(f.id, 7);
        for (text, want) in [
            ("31:0x1@1", "ID 31 out of range (allowed: 1..=30)"),
            ("1:0x0@1", "allowed: 0x0001..=0xFFFF"),
            ("1:0x10000@1", "allowed: 0x0001..=0xFFFF"),
            ("1:0x1@-1", "out of range (allowed: 0..=86400)"),
            ("1:0x1@NaN", "out of range"),
            ("1:0x1", "expected ID:BITS@SECONDS"),
            ("1@1", "expected ID:BITS@SECONDS"),
            ("x:0x1@1", "`x` is not a number"),
            ("2:4000@1", "need the 0x prefix"),
        ] {
            let e = DeviceFault::parse(text, DeviceFaultKind::Error(0), 1..=30, "--fault-error")
                .unwrap_err();
            let msg = e.to_string();
            assert!(
                msg.contains(want) && msg.contains("--fault-error") && msg.contains(text),
                "{msg}"
            );
        }
        let e = DeviceFault::parse(
            "254@1",
            DeviceFaultKind::PowerCycle,
            0..=253,
            "--fault-power-cycle",
        )
        .unwrap_err();
        assert!(e.to_string().contains("allowed: 0..=253"), "{e}");
    }

    #[test]
    fn a_schedule_hands_out_each_fault_once_in_time_order() {
        let at = |ms, id| DeviceFault {
            at: Duration::from_millis(ms),
            id,
            kind: DeviceFaultKind::Silent,
        };
        let mut s = FaultSchedule::new(vec![at(30, 3), at(10, 1), at(20, 2)]);
        assert_eq!(s.next_due(), Some(Duration::from_millis(10)));
        assert!(s.take_due(Duration::from_millis(5)).is_empty());
        assert_eq!(
            s.take_due(Duration::from_millis(20)),
            &[at(10, 1), at(20, 2)]
        );
        assert!(s.take_due(Duration::from_millis(25)).is_empty());
        assert_eq!(s.take_due(Duration::from_secs(1)), &[at(30, 3)]);
        assert_eq!(s.next_due(), None);
        let s = FaultSchedule::new(vec![at(10, 1)]).shifted(Duration::from_millis(65));
        assert_eq!(s.next_due(), Some(Duration::from_millis(75)));
    }
}
