//! Device side: turning the byte stream a module hears into commands.
//!
//! [`StreamDecoder`] takes bytes one at a time (or a slice through
//! [`StreamDecoder::feed`]) and yields one event per completed or abandoned packet. It
//! resynchronises on `0xFF` (the header never occurs inside a packet), learns each packet's
//! length from its first bytes, checks the checksum of its family, and checks every field
//! against its range. It never panics and never allocates; errors are values.

use crate::command::{
    BREAK_D2, Command, HEADER, MAX_PACKET_LEN, SyncMove, checksum_range, code, xor7,
};
use crate::program::{InstructionError, Program, ProgramError};
use crate::values::{
    Accel, BaudRate, Boundaries, DGain, DataByte, ExtServoId, IGain, IoBits, Overload, PGain,
    Position, Position10, RangeError, Rotation, ServoId, Speed, TorqueLevel, ValueError,
    WheelSpeed,
};

/// Why bytes on the wire did not make a command.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, thiserror::Error)]
pub enum DecodeError {
    /// The checksum byte differs from the one computed over the packet's family range.
    #[error("bad checksum: computed {computed:#04x}, received {received:#04x}")]
    BadChecksum {
        /// Checksum computed from the packet.
        computed: u8,
        /// Checksum byte received.
        received: u8,
    },
    /// A mode-7 packet with a code that is not in the protocol table (A-6).
    #[error("unknown command code {code:#04x}")]
    UnknownCode {
        /// The code byte.
        code: u8,
    },
    /// A 4-byte packet whose mode/ID/data combination means nothing (for example a status
    /// read to the broadcast ID, or a passive command with mode nibble 7).
    #[error("unknown operation: data1 {d1:#04x}, data2 {d2:#04x}")]
    UnknownOperation {
        /// Data byte 1 (mode and ID).
        d1: u8,
        /// Data byte 2.
        d2: u8,
    },
    /// A header (`0xFF`) arrived before the packet in progress was complete; decoding
    /// restarts at the new header.
    #[error("truncated packet: new header after {received} bytes{}", OfLen(*.expected))]
    Truncated {
        /// Bytes of the abandoned packet, header included.
        received: usize,
        /// Its length, if it was already known.
        expected: Option<usize>,
    },
    /// A field holds a value outside its range.
    #[error("{command}: {error}")]
    InvalidField {
        /// The command.
        command: &'static str,
        /// The range violation.
        error: ValueError,
    },
    /// A value the packet carries twice (data 3 = data 4) differs between its copies.
    #[error("{command}: data 3 and data 4 must be equal, got {first} and {second}")]
    Mismatch {
        /// The command.
        command: &'static str,
        /// Data byte 3.
        first: u8,
        /// Data byte 4.
        second: u8,
    },
    /// An instruction of a motion data write is invalid.
    #[error("motion data write: instruction {index}: {error}")]
    BadInstruction {
        /// Zero-based instruction index.
        index: usize,
        /// What is wrong with it.
        error: InstructionError,
    },
}

/// Formats " of N" when the length is known.
struct OfLen(Option<usize>);

impl core::fmt::Display for OfLen {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self.0 {
            Some(n) => write!(f, " of {n}"),
            None => Ok(()),
        }
    }
}

/// Counters kept by a [`StreamDecoder`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct DecoderStats {
    /// Commands decoded.
    pub commands: u64,
    /// Errors reported.
    pub errors: u64,
    /// Bytes discarded while waiting for a header.
    pub skipped: u64,
}

/// Streaming device-side decoder.
///
/// It resynchronises on `0xFF` (the header never occurs inside a packet: data bytes are
/// 0..=254 and checksums 7-bit), so a `0xFF` arriving mid-packet abandons that packet with
/// [`DecodeError::Truncated`] and starts a new one. Bytes outside a packet are counted in
/// [`DecoderStats::skipped`]. The packet length comes from its first bytes (data 1, the code,
/// the count); the checksum is checked per family (sync move: positions only; everything
/// else: bytes 2..N); then every field is checked against its range. Unknown codes and
/// counts out of range are reported as soon as they are seen.
///
/// ```
/// use robobus_wck::{Command, DecodeError, StreamDecoder};
/// let mut decoder = StreamDecoder::new();
/// // Noise, a status read of servo 0, then a packet with a bad checksum.
/// let events: Vec<_> = decoder.feed(&[0x12, 0xFF, 0xA0, 0x00, 0x20, 0xFF, 0xA0, 0x00, 0x21]).collect();
/// assert_eq!(events.len(), 2);
/// assert!(matches!(events[0], Ok(Command::StatusRead { .. })));
/// assert_eq!(events[1], Err(DecodeError::BadChecksum { computed: 0x20, received: 0x21 }));
/// assert_eq!(decoder.stats().skipped, 1);
/// ```
#[derive(Debug, Clone)]
pub struct StreamDecoder {
    buf: [u8; MAX_PACKET_LEN],
    /// Bytes of the packet in progress (0 = waiting for a header).
    len: u8,
    /// Length of the packet in progress once known (0 = not yet known).
    expected: u8,
    /// Length of the packet just completed, for [`StreamDecoder::last_packet`].
    done: u8,
    stats: DecoderStats,
}

impl Default for StreamDecoder {
    fn default() -> Self {
        Self::new()
    }
}

/// What the bytes so far say about the packet length.
enum Length {
    Unknown,
    Known(usize),
}

impl StreamDecoder {
    /// A decoder waiting for a header.
    pub const fn new() -> Self {
        Self {
            buf: [0; MAX_PACKET_LEN],
            len: 0,
            expected: 0,
            done: 0,
            stats: DecoderStats {
                commands: 0,
                errors: 0,
                skipped: 0,
            },
        }
    }

    /// Drops any packet in progress.
    pub fn reset(&mut self) {
        self.len = 0;
        self.expected = 0;
        self.done = 0;
    }

    /// Whether no packet is in progress.
    pub const fn is_idle(&self) -> bool {
        self.len == 0
    }

    /// The counters.
    pub const fn stats(&self) -> DecoderStats {
        self.stats
    }

    /// The raw bytes of the packet that produced the last event (empty after a
    /// [`DecodeError::Truncated`] or before any event). Valid until the next push.
    pub fn last_packet(&self) -> &[u8] {
        self.buf.get(..usize::from(self.done)).unwrap_or(&[])
    }

    /// Pushes one byte; returns an event when a packet completes or is abandoned.
    #[inline]
    pub fn push(&mut self, byte: u8) -> Option<Result<Command, DecodeError>> {
        // Fast path: a data byte in the middle of a packet whose length is known.
        if byte != HEADER
            && self.len + 1 < self.expected
            && let Some(slot) = self.buf.get_mut(usize::from(self.len))
        {
            *slot = byte;
            self.len += 1;
            self.done = 0;
            return None;
        }
        self.push_slow(byte)
    }

    /// Every other byte: headers, the first bytes of a packet, the last byte.
    #[inline(never)]
    fn push_slow(&mut self, byte: u8) -> Option<Result<Command, DecodeError>> {
        self.done = 0;
        if byte == HEADER {
            let received = usize::from(self.len);
            let expected = (self.expected > 0).then_some(usize::from(self.expected));
            self.buf[0] = HEADER;
            self.len = 1;
            self.expected = 0;
            if received > 0 {
                return Some(self.error(DecodeError::Truncated { received, expected }));
            }
            return None;
        }
        if self.len == 0 {
            self.stats.skipped += 1;
            return None;
        }
        let Some(slot) = self.buf.get_mut(usize::from(self.len)) else {
            // Cannot happen: every length is checked against MAX_PACKET_LEN below.
            self.len = 0;
            return None;
        };
        *slot = byte;
        self.len += 1;
        let length = if self.expected > 0 {
            Ok(Length::Known(usize::from(self.expected)))
        } else {
            self.length()
        };
        match length {
            Err(e) => {
                self.done = self.len;
                self.len = 0;
                self.expected = 0;
                Some(self.error(e))
            }
            Ok(Length::Known(n)) if usize::from(self.len) >= n => {
                self.done = self.len;
                self.len = 0;
                self.expected = 0;
                let result = decode_complete(self.last_packet());
                match result {
                    Ok(_) => self.stats.commands += 1,
                    Err(_) => self.stats.errors += 1,
                }
                Some(result)
            }
            Ok(Length::Known(n)) => {
                // n <= MAX_PACKET_LEN (35), so it fits.
                self.expected = u8::try_from(n).unwrap_or(0);
                None
            }
            Ok(Length::Unknown) => None,
        }
    }

    /// Pushes a slice; the iterator yields the events (consume it to push every byte).
    pub fn feed<'d, 'b>(&'d mut self, bytes: &'b [u8]) -> Feed<'d, 'b> {
        Feed {
            decoder: self,
            bytes: bytes.iter(),
        }
    }

    fn error(&mut self, e: DecodeError) -> Result<Command, DecodeError> {
        self.stats.errors += 1;
        Err(e)
    }

    /// The packet length as far as the bytes so far tell it.
    fn length(&self) -> Result<Length, DecodeError> {
        let bytes = self.buf.get(..usize::from(self.len)).unwrap_or(&[]);
        packet_length(bytes)
    }
}

/// The events of [`StreamDecoder::feed`].
#[derive(Debug)]
pub struct Feed<'d, 'b> {
    decoder: &'d mut StreamDecoder,
    bytes: core::slice::Iter<'b, u8>,
}

impl Iterator for Feed<'_, '_> {
    type Item = Result<Command, DecodeError>;
    fn next(&mut self) -> Option<Self::Item> {
        for &byte in self.bytes.by_ref() {
            if let Some(event) = self.decoder.push(byte) {
                return Some(event);
            }
        }
        None
    }
}

/// Decodes one complete packet (header first). Convenience over [`StreamDecoder`]: returns
/// the first event, or [`DecodeError::Truncated`] if the bytes end mid-packet.
pub fn decode_packet(bytes: &[u8]) -> Result<Command, DecodeError> {
    let mut decoder = StreamDecoder::new();
    if let Some(event) = decoder.feed(bytes).next() {
        return event;
    }
    Err(DecodeError::Truncated {
        received: usize::from(decoder.len),
        expected: match decoder.length() {
            Ok(Length::Known(n)) => Some(n),
            _ => None,
        },
    })
}

const SYNC: &str = "synchronized position move";
const MOTION_WRITE: &str = "motion data write";

fn is_sync(d1: u8) -> bool {
    d1 & 0x1F == ServoId::BROADCAST_RAW && d1 >> 5 <= 4
}

fn packet_length(bytes: &[u8]) -> Result<Length, DecodeError> {
    let Some(&d1) = bytes.get(1) else {
        return Ok(Length::Unknown);
    };
    if is_sync(d1) {
        let Some(&d2) = bytes.get(2) else {
            return Ok(Length::Unknown);
        };
        let n = d2 & 0x1F;
        if n == 0 {
            return Err(DecodeError::InvalidField {
                command: SYNC,
                error: ValueError::Range(RangeError {
                    what: "servo count (last ID + 1)",
                    value: 0,
                    min: 1,
                    max: 31,
                }),
            });
        }
        return Ok(Length::Known(4 + usize::from(n)));
    }
    if d1 >> 5 < 7 {
        return Ok(Length::Known(4));
    }
    let Some(&code) = bytes.get(2) else {
        return Ok(Length::Unknown);
    };
    Ok(Length::Known(match code {
        code::MOVE10 => 8,
        code::MOTION_WRITE => {
            let Some(&n) = bytes.get(3) else {
                return Ok(Length::Unknown);
            };
            if n > 8 {
                return Err(DecodeError::InvalidField {
                    command: MOTION_WRITE,
                    error: ValueError::Range(RangeError {
                        what: "motion instruction count",
                        value: u32::from(n),
                        min: 0,
                        max: 8,
                    }),
                });
            }
            5 + 2 * usize::from(n)
        }
        code::BAUD_SET
        | code::GAIN_SET
        | code::GAIN_READ
        | code::RUNTIME_GAIN_SET
        | code::ID_SET
        | code::SPEED_SET
        | code::SPEED_READ
        | code::OVERLOAD_SET
        | code::OVERLOAD_READ
        | code::BOUNDARY_SET
        | code::BOUNDARY_READ
        | code::I_GAIN_SET
        | code::I_GAIN_READ
        | code::RUNTIME_SPEED_SET
        | code::RUNTIME_I_GAIN_SET
        | code::IO_WRITE
        | code::IO_READ
        | code::MOTION_READ
        | code::READ10 => 6,
        code => return Err(DecodeError::UnknownCode { code }),
    }))
}

/// Checks the checksum and decodes the fields of a complete packet.
fn decode_complete(packet: &[u8]) -> Result<Command, DecodeError> {
    let Some((&received, _)) = packet.split_last() else {
        return Err(DecodeError::Truncated {
            received: 0,
            expected: None,
        });
    };
    let computed = xor7(packet.get(checksum_range(packet)).unwrap_or(&[]));
    if computed != received {
        return Err(DecodeError::BadChecksum { computed, received });
    }
    decode_fields(packet)
}

fn field<T>(command: &'static str, r: Result<T, RangeError>) -> Result<T, DecodeError> {
    r.map_err(|e| DecodeError::InvalidField {
        command,
        error: ValueError::Range(e),
    })
}

fn same(command: &'static str, d3: u8, d4: u8) -> Result<u8, DecodeError> {
    if d3 == d4 {
        Ok(d3)
    } else {
        Err(DecodeError::Mismatch {
            command,
            first: d3,
            second: d4,
        })
    }
}

#[allow(clippy::too_many_lines)] // one flat arm per command code reads best
fn decode_fields(p: &[u8]) -> Result<Command, DecodeError> {
    let byte = |i: usize| p.get(i).copied().unwrap_or(0);
    let d1 = byte(1);
    let d2 = byte(2);
    let mode = d1 >> 5;
    let id5 = d1 & 0x1F;

    if is_sync(d1) {
        let n = usize::from(d2 & 0x1F);
        let mut positions = [Position::MIN; 31];
        for (slot, &raw) in positions.iter_mut().zip(p.get(3..3 + n).unwrap_or(&[])) {
            *slot = field(SYNC, Position::new(raw))?;
        }
        let torque = field(SYNC, TorqueLevel::new(mode))?;
        let positions = positions.get(..n).unwrap_or(&[]);
        return Ok(Command::SyncMove(field(
            SYNC,
            SyncMove::new(torque, positions),
        )?));
    }
    if mode < 7 {
        let unknown = DecodeError::UnknownOperation { d1, d2 };
        // ID 31 with mode 0..=4 is the synchronized move, handled above.
        let broadcast = id5 == ServoId::BROADCAST_RAW;
        if broadcast {
            return if mode == 6 && d2 >> 4 == BREAK_D2 >> 4 {
                Ok(Command::Break)
            } else {
                Err(unknown)
            };
        }
        let id = field("position move", ServoId::new(id5))?;
        return match mode {
            0..=4 => Ok(Command::Move {
                id,
                torque: field("position move", TorqueLevel::new(mode))?,
                position: field("position move", Position::new(d2))?,
            }),
            5 => Ok(Command::StatusRead { id }),
            _ => match d2 >> 4 {
                1 => Ok(Command::Passive { id }),
                3 | 4 => Ok(Command::Wheel {
                    id,
                    rotation: if d2 >> 4 == 3 {
                        Rotation::Ccw
                    } else {
                        Rotation::Cw
                    },
                    speed: field("wheel", WheelSpeed::new(d2 & 0x0F))?,
                }),
                _ => Err(unknown),
            },
        };
    }

    let code = d2;
    let d3 = byte(3);
    let d4 = byte(4);
    // d1 is 0xE0..=0xFE here, so the ID is 0..=30.
    let id = field("set command", ServoId::new(id5))?;
    let cmd = match code {
        code::BAUD_SET => {
            let c = "baud rate set";
            let baud = BaudRate::from_code(same(c, d3, d4)?)
                .map_err(|error| DecodeError::InvalidField { command: c, error })?;
            Command::BaudSet { id, baud }
        }
        code::GAIN_SET => Command::GainSet {
            id,
            p: field("P, D gain set", PGain::new(d3))?,
            d: field("P, D gain set", DGain::new(d4))?,
        },
        code::GAIN_READ => Command::GainRead { id },
        code::RUNTIME_GAIN_SET => Command::RuntimeGainSet {
            id,
            p: field("runtime P, D gain set", PGain::new(d3))?,
            d: field("runtime P, D gain set", DGain::new(d4))?,
        },
        code::ID_SET => {
            let c = "ID set";
            Command::IdSet {
                id,
                new_id: field(c, ExtServoId::new(same(c, d3, d4)?))?,
            }
        }
        code::SPEED_SET => Command::SpeedSet {
            id,
            speed: field("speed set", Speed::new(d3))?,
            accel: field("speed set", Accel::new(d4))?,
        },
        code::SPEED_READ => Command::SpeedRead { id },
        code::OVERLOAD_SET => {
            let c = "over-load set";
            Command::OverloadSet {
                id,
                overload: field(c, Overload::new(same(c, d3, d4)?))?,
            }
        }
        code::OVERLOAD_READ => Command::OverloadRead { id },
        code::BOUNDARY_SET => Command::BoundarySet {
            id,
            bounds: Boundaries::from_raw(d3, d4).map_err(|error| DecodeError::InvalidField {
                command: "boundary set",
                error,
            })?,
        },
        code::BOUNDARY_READ => Command::BoundaryRead { id },
        code::I_GAIN_SET => {
            let c = "I gain set";
            Command::IGainSet {
                id,
                i: field(c, IGain::new(same(c, d3, d4)?))?,
            }
        }
        code::I_GAIN_READ => Command::IGainRead { id },
        code::RUNTIME_SPEED_SET => Command::RuntimeSpeedSet {
            id,
            speed: field("runtime speed set", Speed::new(d3))?,
            accel: field("runtime speed set", Accel::new(d4))?,
        },
        code::RUNTIME_I_GAIN_SET => {
            let c = "runtime I gain set";
            Command::RuntimeIGainSet {
                id,
                i: field(c, IGain::new(same(c, d3, d4)?))?,
            }
        }
        // Data 3 holds the outputs in bits 0..=1; the other bits are "arbitrary" (A-1 (22)).
        code::IO_WRITE => Command::IoWrite {
            id,
            outputs: IoBits::from_masked(same("I/O write", d3, d4)?),
        },
        code::IO_READ => Command::IoRead { id },
        code::MOTION_WRITE => {
            let n = usize::from(d3);
            let body = p.get(4..4 + 2 * n).unwrap_or(&[]);
            let program = Program::from_bytes(body).map_err(|e| match e {
                ProgramError::Count(error) => DecodeError::InvalidField {
                    command: MOTION_WRITE,
                    error: ValueError::Range(error),
                },
                ProgramError::Instruction { index, error } => {
                    DecodeError::BadInstruction { index, error }
                }
            })?;
            Command::MotionWrite { id, program }
        }
        code::MOTION_READ => Command::MotionRead { id },
        code::MOVE10 => {
            let c = "10-bit position move";
            Command::Move10 {
                id: field(c, ExtServoId::new(d3))?,
                torque: field(c, DataByte::new(d4))?,
                // Bits outside H3 and L7 are "X" in the manual.
                position: Position10::from_wire(byte(5), byte(6)),
            }
        }
        code::READ10 => {
            let c = "10-bit position read";
            Command::Read10 {
                id: field(c, ExtServoId::new(same(c, d3, d4)?))?,
            }
        }
        code => return Err(DecodeError::UnknownCode { code }),
    };
    Ok(cmd)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stats_and_last_packet_follow_the_events() {
        let mut d = StreamDecoder::new();
        // Noise, a passive command, a truncated packet, a complete break command.
        let stream = [
            0x01, 0x02, 0xFF, 0xC0, 0x10, 0x50, 0xFF, 0xE0, 0xFF, 0xDF, 0x20, 0x7F,
        ];
        let mut events = 0;
        for &b in &stream {
            if let Some(event) = d.push(b) {
                events += 1;
                match event {
                    Ok(Command::Passive { .. }) => {
                        assert_eq!(d.last_packet(), [0xFF, 0xC0, 0x10, 0x50]);
                    }
                    Err(DecodeError::Truncated {
                        received: 2,
                        expected: None,
                    }) => {
                        assert!(d.last_packet().is_empty());
                    }
                    Ok(Command::Break) => assert_eq!(d.last_packet(), [0xFF, 0xDF, 0x20, 0x7F]),
                    other => panic!("unexpected {other:?}"),
                }
            } else {
                assert!(d.last_packet().is_empty());
            }
        }
        assert_eq!(events, 3);
        assert_eq!(
            d.stats(),
            DecoderStats {
                commands: 2,
                errors: 1,
                skipped: 2
            }
        );
        assert!(d.is_idle());
    }

    #[test]
    fn a_header_in_a_data_position_restarts_the_packet() {
        // A sync move to 3 servos whose second position byte is 0xFF.
        let mut d = StreamDecoder::new();
        let events: Vec<_> = d
            .feed(&[0xFF, 0x1F, 0x03, 0x10, 0xFF, 0xA0, 0x00, 0x20])
            .collect();
        assert_eq!(
            events,
            [
                Err(DecodeError::Truncated {
                    received: 4,
                    expected: Some(7)
                }),
                Ok(Command::StatusRead {
                    id: ServoId::new(0).unwrap()
                }),
            ]
        );
    }

    #[test]
    fn decode_packet_reports_an_incomplete_packet() {
        assert_eq!(
            decode_packet(&[0xFF, 0xE0, 0x96, 0x02, 0x10]),
            Err(DecodeError::Truncated {
                received: 5,
                expected: Some(9)
            })
        );
        assert_eq!(
            decode_packet(&[]),
            Err(DecodeError::Truncated {
                received: 0,
                expected: None
            })
        );
    }
}
