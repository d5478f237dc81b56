//! Writes verified after the fact: EEPROM settings by reading them back, ID and baud
//! changes by talking to the module at its new ID or rate.

use robobus_link::ByteLink;
use robobus_wck::{BaudRate, Command, ExtServoId, Reply, ServoId};

use super::{Failure, WckBus};
use crate::wck::error::{Hex, WckError};
use crate::wck::policy::{RetryClass, read_back, retry_class};

impl<L: ByteLink> WckBus<L> {
    /// An EEPROM write verified by reading it back; resent only if the read-back shows
    /// it did not take (and only for [`RetryClass::VerifiedWrite`], not for the motion
    /// data write, which restarts the program).
    pub(super) fn write_verified(&mut self, command: &Command) -> Result<Reply, WckError> {
        let Some(read) = read_back(command) else {
            return self.once(command);
        };
        let expected = expected_reply(command);
        let resend = retry_class(command) == RetryClass::VerifiedWrite;
        let writes = if resend {
            self.config.retries.saturating_add(1)
        } else {
            1
        };
        let mut write = 1;
        loop {
            let outcome = self.attempt(command);
            let write_failure = match outcome {
                Ok(_) => None,
                Err(Failure::Link(source)) => return Err(self.link_error(command.name(), source)),
                Err(f) => {
                    self.settle();
                    Some(f)
                }
            };
            let found = match self.run(&read) {
                Ok(found) => found,
                Err(read_error) => {
                    return Err(match write_failure {
                        Some(f) => self.failure_error(command, f, write),
                        None => read_error,
                    });
                }
            };
            if Some(found) == expected {
                return Ok(found);
            }
            if write >= writes {
                return Err(WckError::NotApplied {
                    device: self.device.clone(),
                    target: command.target(),
                    command: command.name(),
                    expected: expected.map_or_else(|| command.to_string(), |e| e.to_string()),
                    found: found.to_string(),
                });
            }
            write += 1;
            self.stats.retries += 1;
        }
    }

    /// (14) ID set, verified at the new ID (see
    /// [`Servo::set_id`](crate::wck::Servo::set_id)).
    pub(crate) fn set_id(&mut self, id: ServoId, new_id: ExtServoId) -> Result<(), WckError> {
        self.stats.commands += 1;
        let command = Command::IdSet { id, new_id };
        let probe_new = probe_command(new_id);
        if ExtServoId::from(id) != new_id {
            match self.exchange(&probe_new) {
                Err(Failure::Timeout { received, .. }) if received.is_empty() => {}
                Err(Failure::Link(source)) => return Err(self.link_error(command.name(), source)),
                _ => {
                    self.settle();
                    return Err(WckError::IdInUse {
                        device: self.device.clone(),
                        target: command.target(),
                        new_id: new_id.get(),
                    });
                }
            }
        }
        let write = self.attempt(&command);
        if let Err(Failure::Link(source)) = write {
            return Err(self.link_error(command.name(), source));
        }
        if write.is_err() {
            self.settle();
        }
        let Err(at_new) = self.run(&probe_new) else {
            return Ok(());
        };
        match self.run(&Command::StatusRead { id }) {
            Ok(_) => Err(WckError::NotApplied {
                device: self.device.clone(),
                target: command.target(),
                command: command.name(),
                expected: format!("an answer at ID {new_id}"),
                found: format!("it still answers at ID {id} ({})", describe(&write)),
            }),
            Err(_) => Err(WckError::NotVerified {
                device: self.device.clone(),
                target: command.target(),
                command: command.name(),
                detail: format!(
                    "{}; nothing answers at the new ID {new_id} ({at_new}) nor at the old ID {id}",
                    describe(&write)
                ),
            }),
        }
    }

    /// (7) Baud rate set, verified at the new rate (see
    /// [`Servo::set_baud`](crate::wck::Servo::set_baud)).
    pub(crate) fn set_module_baud(&mut self, id: ServoId, baud: BaudRate) -> Result<(), WckError> {
        self.stats.commands += 1;
        let command = Command::BaudSet { id, baud };
        let old = self.baud;
        let write = self.attempt(&command);
        if let Err(Failure::Link(source)) = write {
            return Err(self.link_error(command.name(), source));
        }
        if write.is_err() {
            self.settle();
        }
        self.set_host_baud(baud)?;
        let status = Command::StatusRead { id };
        let Err(at_new) = self.run(&status) else {
            return Ok(());
        };
        self.set_host_baud(old)?;
        match self.run(&status) {
            Ok(_) => Err(WckError::NotApplied {
                device: self.device.clone(),
                target: command.target(),
                command: command.name(),
                expected: format!("an answer at {baud}"),
                found: format!("it still answers at {old} ({})", describe(&write)),
            }),
            Err(_) => Err(WckError::NotVerified {
                device: self.device.clone(),
                target: command.target(),
                command: command.name(),
                detail: format!(
                    "{}; no answer at the new rate {baud} ({at_new}) nor at the old rate {old}; \
                     the bus stays at {old}",
                    describe(&write)
                ),
            }),
        }
    }
}

/// The reply a setting's read-back gives when the setting took.
fn expected_reply(command: &Command) -> Option<Reply> {
    Some(match *command {
        Command::GainSet { p, d, .. } => Reply::Gains { p, d },
        Command::IGainSet { i, .. } => Reply::IGain(i),
        Command::SpeedSet { speed, accel, .. } => Reply::SpeedAccel { speed, accel },
        Command::OverloadSet { overload, .. } => Reply::Overload(overload),
        Command::BoundarySet { bounds, .. } => Reply::Boundaries(bounds),
        Command::MotionWrite { ref program, .. } => Reply::MotionCount(program.count()),
        _ => return None,
    })
}

/// The read that shows whether a module answers at `id`: a status read for IDs 0..=30,
/// a 10-bit position read above.
pub(crate) fn probe_command(id: ExtServoId) -> Command {
    match ServoId::new(id.get()) {
        Ok(id) => Command::StatusRead { id },
        Err(_) => Command::Read10 { id },
    }
}

fn describe(write: &Result<Reply, Failure>) -> String {
    match write {
        Ok(reply) => format!("the module acknowledged ({reply})"),
        Err(Failure::Timeout { received, .. }) => format!(
            "its reply did not arrive ({} bytes: {})",
            received.len(),
            Hex(received)
        ),
        Err(Failure::Bad { bytes, reason }) => {
            format!("its reply was implausible ({}: {reason})", Hex(bytes))
        }
        Err(Failure::Unattributable { bytes, anomaly }) => format!(
            "its reply could not be attributed ({})",
            anomaly.describe(bytes, 2)
        ),
        Err(Failure::Link(e)) => format!("link error: {e}"),
    }
}
