//! Wire time on a wCK bus (8N1 UART), as pure functions.
//!
//! The model is the one in robobus' wire-timing notes, fitted to the manual's section 2-3
//! (Communication, "Command Response Time"):
//!
//! - one byte costs 10 bit times: `10 / baud`;
//! - a module answers an operation or read command [`T_PROC`] (1006.6 µs) after the last
//!   command byte (the manual's 1180 µs at 115200 and 1354 µs at 57600 both fit
//!   `T_PROC + reply wire time`), and an EEPROM write about [`T_EEPROM`] (121 ms) after it;
//!   above 115200 the manual gives no figures and the same values are used;
//! - a transaction is command wire time + turnaround + reply wire time;
//! - a synchronized move to N servos is `(N + 4)` bytes with no reply.
//!
//! ```
//! use core::time::Duration;
//! use robobus_wck::{BaudRate, timing};
//! // 4-byte command + 2-byte reply at 115200 bit/s: 520.8 µs on the wire.
//! assert_eq!(timing::wire_time(6, BaudRate::B115200), Duration::from_nanos(520_833));
//! ```

use core::time::Duration;

use crate::command::Command;
use crate::values::BaudRate;

/// Bits per byte on the wire: start bit, 8 data bits, stop bit (8N1).
pub const BITS_PER_BYTE: u64 = 10;

/// Module turnaround for operation, read and runtime commands: 1006.6 µs.
pub const T_PROC: Duration = Duration::from_nanos(1_006_600);

/// Module turnaround for EEPROM writes: about 121 ms (manual: 121145 µs response at
/// 115200, 121492 µs at 57600).
pub const T_EEPROM: Duration = Duration::from_millis(121);

/// A module ignores everything for 65 ms after power-up (section 2-3).
pub const POWER_UP_DEAF: Duration = Duration::from_millis(65);

/// Time of `bytes` bytes on the wire, rounded to the nearest nanosecond.
pub const fn wire_time(bytes: usize, baud: BaudRate) -> Duration {
    let bps = baud.bits_per_second() as u64;
    let bits = bytes as u64 * BITS_PER_BYTE;
    Duration::from_nanos((bits * 1_000_000_000 + bps / 2) / bps)
}

/// Time of one byte on the wire: `10 / baud`.
pub const fn byte_time(baud: BaudRate) -> Duration {
    wire_time(1, baud)
}

/// Wire time of a command and its reply together (no turnaround).
pub const fn command_wire_time(command: &Command, baud: BaudRate) -> Duration {
    wire_time(command.encoded_len() + command.reply_len(), baud)
}

/// How long the module takes between the last command byte and the first reply byte:
/// [`T_EEPROM`] for EEPROM writes, [`T_PROC`] otherwise.
pub const fn turnaround(command: &Command) -> Duration {
    if command.writes_eeprom() {
        T_EEPROM
    } else {
        T_PROC
    }
}

/// Time from the last command byte until the last reply byte (what the manual's "Command
/// Response Time" table measures): turnaround + reply wire time. Zero for commands without
/// a reply.
///
/// This fits the manual's operation commands (1180 µs at 115200, 1354 µs at 57600). Its
/// figures for 6-byte reads are exactly two byte times longer (1354 µs and 1701 µs), which
/// suggests it timed those from the fourth command byte; the model keeps one `T_PROC`.
pub const fn response_time(command: &Command, baud: BaudRate) -> Duration {
    if command.reply_len() == 0 {
        return Duration::ZERO;
    }
    turnaround(command).saturating_add(wire_time(command.reply_len(), baud))
}

/// The earliest instant, counted from the first command bit, at which a module's reply
/// can begin: the command's wire time plus the module's [`turnaround`]. A byte the host
/// receives before then cannot belong to the reply (its first byte is complete one byte
/// time later still): it is a stray byte (line noise, an earlier reply, a duplicate).
/// Zero for commands without a reply.
///
/// ```
/// use core::time::Duration;
/// use robobus_wck::{BaudRate, Command, ServoId, timing};
/// let status = Command::StatusRead { id: ServoId::new(0).unwrap() };
/// // 4 command bytes at 115200 bit/s (347.2 µs) + 1006.6 µs.
/// assert_eq!(timing::earliest_reply(&status, BaudRate::B115200), Duration::from_nanos(1_353_822));
/// ```
pub const fn earliest_reply(command: &Command, baud: BaudRate) -> Duration {
    if command.reply_len() == 0 {
        return Duration::ZERO;
    }
    wire_time(command.encoded_len(), baud).saturating_add(turnaround(command))
}

/// Modelled time of a whole transaction: command wire time + turnaround + reply wire time
/// (just the command wire time when there is no reply).
pub const fn transaction_time(command: &Command, baud: BaudRate) -> Duration {
    if command.reply_len() == 0 {
        return wire_time(command.encoded_len(), baud);
    }
    // Rounded once over all bytes, so it equals `operation_transaction_time` exactly.
    command_wire_time(command, baud).saturating_add(turnaround(command))
}

/// Wire time of a synchronized move to `servos` servos: `(servos + 4)` bytes.
pub const fn sync_move_time(servos: usize, baud: BaudRate) -> Duration {
    wire_time(servos + 4, baud)
}

/// Modelled transaction time of a 4-byte operation command with its 2-byte reply:
/// `60 / baud + T_PROC`.
pub const fn operation_transaction_time(baud: BaudRate) -> Duration {
    wire_time(6, baud).saturating_add(T_PROC)
}

/// Rate of polling `servos` servos one after the other with operation commands, in Hz:
/// `1 / (servos · (60 / baud + T_PROC))`. Zero servos gives 0.
pub fn polling_rate_hz(servos: usize, baud: BaudRate) -> f64 {
    if servos == 0 {
        return 0.0;
    }
    1.0 / (servos as f64 * operation_transaction_time(baud).as_secs_f64())
}

/// Wire-only bound of polling `servos` servos (no turnaround): `baud / (60 · servos)`.
pub fn wire_polling_rate_hz(servos: usize, baud: BaudRate) -> f64 {
    if servos == 0 {
        return 0.0;
    }
    f64::from(baud.bits_per_second()) / (60.0 * servos as f64)
}
