//! Which commands may be sent again after a lost or garbled reply: the one place the
//! client decides it.

use robobus_wck::Command;

/// How the client handles a failed attempt of a command (see [`retry_class`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum RetryClass {
    /// A read: sending it again changes nothing. Resent on a timeout or an implausible
    /// reply, up to [`WckConfig::retries`](super::WckConfig::retries) times.
    Read,
    /// An operation whose repetition leaves the module in the same state as one
    /// execution. Resent like a read.
    Idempotent,
    /// An EEPROM setting that can be read back: sent once; if its reply is lost or
    /// garbled, the value is read back, and the write is resent (it is idempotent) only if
    /// the read-back shows it did not take. A successful write is verified by read-back too.
    VerifiedWrite,
    /// Not idempotent, or a repetition has side effects: sent exactly once, never resent.
    /// The outcome is established by talking to the module afterwards (at its new ID or
    /// baud rate, or by reading back the program count).
    Once,
    /// No reply exists: sent once; nothing can tell whether it arrived.
    NoReply,
}

impl RetryClass {
    /// Whether a failed attempt may simply be sent again.
    pub const fn resend_on_failure(self) -> bool {
        matches!(self, Self::Read | Self::Idempotent)
    }
}

/// The retry classification of every wCK command.
///
/// | command | class | why |
/// |---|---|---|
/// | status read, P/D gain read, I gain read, speed read, over-load read, boundary read, I/O read, motion data read, 10-bit position read | [`Read`](RetryClass::Read) | reads change nothing |
/// | position move, 10-bit position move | [`Idempotent`](RetryClass::Idempotent) | a second identical move ends at the same target. The reply is the status *before* the move, so the reply of a resent move is the status at the moment of the attempt that succeeded (the shaft may already have moved a little on the first, lost attempt): still a true reading, of a slightly later instant |
/// | passive, wheel | [`Idempotent`](RetryClass::Idempotent) | the mode (and wheel speed) end the same; the reply is a reading at the succeeding attempt |
/// | break | [`Idempotent`](RetryClass::Idempotent) | every module enters break mode; resent only when nothing at all came back (see [`WckBus::break_all`](super::WckBus::break_all)) |
/// | runtime P/D gain set, runtime I gain set, I/O write | [`Idempotent`](RetryClass::Idempotent) | set to a value, no EEPROM wear; the reply echoes the value |
/// | P/D gain set, I gain set, speed set, over-load set, boundary set | [`VerifiedWrite`](RetryClass::VerifiedWrite) | idempotent, but each write costs 121 ms and EEPROM wear: resent only when a read-back shows it did not take |
/// | ID set | [`Once`](RetryClass::Once) | after it took, the old ID no longer answers (and a resend could rename a second module that took the old ID meanwhile); verified at the new ID |
/// | baud rate set | [`Once`](RetryClass::Once) | after it took, the module no longer understands the old rate; verified at the new rate |
/// | motion data write | [`Once`](RetryClass::Once) | every write restarts the self-running program (a visible side effect); verified by reading back the instruction count |
/// | synchronized position move, runtime speed set | [`NoReply`](RetryClass::NoReply) | no reply exists, so no failure can be seen |
pub const fn retry_class(command: &Command) -> RetryClass {
    match command {
        Command::StatusRead { .. }
        | Command::GainRead { .. }
        | Command::IGainRead { .. }
        | Command::SpeedRead { .. }
        | Command::OverloadRead { .. }
        | Command::BoundaryRead { .. }
        | Command::IoRead { .. }
        | Command::MotionRead { .. }
        | Command::Read10 { .. } => RetryClass::Read,
        Command::Move { .. }
        | Command::Move10 { .. }
        | Command::Passive { .. }
        | Command::Wheel { .. }
        | Command::Break
        | Command::RuntimeGainSet { .. }
        | Command::RuntimeIGainSet { .. }
        | Command::IoWrite { .. } => RetryClass::Idempotent,
        Command::GainSet { .. }
        | Command::IGainSet { .. }
        | Command::SpeedSet { .. }
        | Command::OverloadSet { .. }
        | Command::BoundarySet { .. } => RetryClass::VerifiedWrite,
        Command::IdSet { .. } | Command::BaudSet { .. } | Command::MotionWrite { .. } => {
            RetryClass::Once
        }
        Command::SyncMove(_) | Command::RuntimeSpeedSet { .. } => RetryClass::NoReply,
    }
}

/// The read that shows the value an EEPROM setting stored, for the
/// [`VerifiedWrite`](RetryClass::VerifiedWrite) commands and the motion data write;
/// `None` for every other command. Its reply equals the setting's own reply when the
/// setting took.
pub const fn read_back(command: &Command) -> Option<Command> {
    Some(match *command {
        Command::GainSet { id, .. } => Command::GainRead { id },
        Command::IGainSet { id, .. } => Command::IGainRead { id },
        Command::SpeedSet { id, .. } => Command::SpeedRead { id },
        Command::OverloadSet { id, .. } => Command::OverloadRead { id },
        Command::BoundarySet { id, .. } => Command::BoundaryRead { id },
        Command::MotionWrite { id, .. } => Command::MotionRead { id },
        _ => return None,
    })
}

/// Whether a read's reply carries no redundancy at all (no repeated byte, no echo), so a
/// single corrupted bit can turn it into another plausible value. With
/// [`WckConfig::confirm_reads`](super::WckConfig::confirm_reads) `n`, these reads need
/// `n` equal replies in a row; the I gain, over-load and motion count reads, which repeat
/// their value in both bytes, need `n - 1`.
pub const fn needs_confirmation(command: &Command) -> bool {
    matches!(
        command,
        Command::StatusRead { .. }
            | Command::GainRead { .. }
            | Command::SpeedRead { .. }
            | Command::BoundaryRead { .. }
            | Command::IoRead { .. }
            | Command::Read10 { .. }
    )
}
