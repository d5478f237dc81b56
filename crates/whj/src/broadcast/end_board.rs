//! The end-effector board's side of the broadcast frames (§8.10): its slot operation, its
//! reply and its own register map.

/// End-board command byte: read registers.
pub const END_BOARD_READ: u8 = 0x01;
/// End-board command byte: write registers.
pub const END_BOARD_WRITE: u8 = 0x02;
/// Largest number of data bytes an end-board write carries (the 13-byte 0x0F slot less
/// its 3-byte header).
pub const END_BOARD_WRITE_MAX: usize = 10;
/// Largest register count of an end-board read (the 64-byte reply less its 8-byte header
/// holds 28 words; the client asks for far fewer).
pub const END_BOARD_READ_MAX: u8 = 16;

/// One operation in the end board's slot of a broadcast frame (§8.10):
/// `[cmd, index, len, data…]`, without the leading length byte of a joint slot.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum EndBoardOp {
    /// `[01, index, count]`: read `count` 16-bit registers from `index`; the reply's
    /// length byte counts bytes (2 per register).
    Read {
        /// First register of the end board's own map.
        index: u8,
        /// Registers, 1..=[`END_BOARD_READ_MAX`].
        count: u8,
    },
    /// `[02, index, len, data…]`: write `len` bytes (little-endian, 2 per register) from
    /// `index`; the reply's data byte is 1 on success.
    Write {
        /// First register of the end board's own map.
        index: u8,
        /// Data bytes used, 1..=[`END_BOARD_WRITE_MAX`].
        len: u8,
        /// The data (`len` bytes used).
        data: [u8; END_BOARD_WRITE_MAX],
    },
}

/// An end-board operation that does not fit its field.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum EndBoardOpError {
    /// A read count outside 1..=[`END_BOARD_READ_MAX`].
    #[error("end-board read of {count} registers (allowed: 1..={END_BOARD_READ_MAX})")]
    Count {
        /// The count given.
        count: u8,
    },
    /// Write data of a length outside 1..=[`END_BOARD_WRITE_MAX`] bytes.
    #[error("end-board write of {len} bytes (allowed: 1..={END_BOARD_WRITE_MAX})")]
    Length {
        /// The length given.
        len: usize,
    },
}

impl EndBoardOp {
    /// A read of `count` registers from `index`.
    pub const fn read(index: u8, count: u8) -> Result<Self, EndBoardOpError> {
        if count == 0 || count > END_BOARD_READ_MAX {
            return Err(EndBoardOpError::Count { count });
        }
        Ok(Self::Read { index, count })
    }

    /// A write of `bytes` from `index`.
    pub fn write(index: u8, bytes: &[u8]) -> Result<Self, EndBoardOpError> {
        let len = bytes.len();
        if len == 0 || len > END_BOARD_WRITE_MAX {
            return Err(EndBoardOpError::Length { len });
        }
        let mut data = [0u8; END_BOARD_WRITE_MAX];
        data[..len].copy_from_slice(bytes);
        #[allow(clippy::cast_possible_truncation)] // len <= 10
        Ok(Self::Write {
            index,
            len: len as u8,
            data,
        })
    }

    /// The first register.
    pub const fn index(&self) -> u8 {
        match self {
            Self::Read { index, .. } | Self::Write { index, .. } => *index,
        }
    }

    /// Writes the operation into an end-board field padded with `fill`; `false` (and the
    /// field unchanged) when it does not fit.
    pub fn encode_into(&self, field: &mut [u8], fill: u8) -> bool {
        let bytes: &[u8] = match self {
            Self::Read { .. } => &[],
            Self::Write { len, data, .. } => &data[..usize::from(*len)],
        };
        if field.len() < 3 + bytes.len() {
            return false;
        }
        field.fill(fill);
        match self {
            Self::Read { index, count } => {
                field[..3].copy_from_slice(&[END_BOARD_READ, *index, *count]);
            }
            Self::Write { index, len, .. } => {
                field[..3].copy_from_slice(&[END_BOARD_WRITE, *index, *len]);
                field[3..3 + bytes.len()].copy_from_slice(bytes);
            }
        }
        true
    }

    /// Parses an end-board field: `None` when its command byte is neither read nor write
    /// (0x00 / 0xFF padding: no operation) or the operation does not fit.
    pub fn decode(field: &[u8]) -> Option<Self> {
        match *field {
            [END_BOARD_READ, index, count, ..] => Self::read(index, count).ok(),
            [END_BOARD_WRITE, index, len, ref rest @ ..] => {
                Self::write(index, rest.get(..usize::from(len))?).ok()
            }
            _ => None,
        }
    }
}

/// Header length of an end-board reply (0x87 / 0xF7).
pub const END_BOARD_REPLY_HEADER: usize = 8;

/// The end board's answer (0xF7 to 0x0F, 0x87 to the other broadcast frames, §8.10):
/// `D0` broadcast counter · `D1` status0 · `D2` status1 · `D3` Modbus read length ·
/// `D4` system error · `D5` cmd · `D6` index · `D7` len · `D8…` data.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct EndBoardReply {
    /// Broadcast frames received (wraps 255 → 0).
    pub counter: u8,
    /// Status bits, 7→0: DIO1 mode, DIO2 mode, teach button, replay button, DIO1 state,
    /// gripper in position, hand in position, DIO2 state.
    pub status0: u8,
    /// Reserved.
    pub status1: u8,
    /// Modbus bytes read.
    pub modbus_read_len: u8,
    /// System error.
    pub sys_error: u8,
    /// The command answered (1 read, 2 write; 0 when the slot held none).
    pub cmd: u8,
    /// The register answered.
    pub index: u8,
    /// Length byte: data bytes of a read; of a write, the length written.
    pub len: u8,
    data: [u8; 64 - END_BOARD_REPLY_HEADER],
    data_len: u8,
}

impl EndBoardReply {
    /// A reply (simulator side); `data` beyond 56 bytes is cut.
    pub fn new(header: [u8; END_BOARD_REPLY_HEADER], data: &[u8]) -> Self {
        let n = data.len().min(64 - END_BOARD_REPLY_HEADER);
        let mut d = [0u8; 64 - END_BOARD_REPLY_HEADER];
        d[..n].copy_from_slice(&data[..n]);
        #[allow(clippy::cast_possible_truncation)] // n <= 56
        Self {
            counter: header[0],
            status0: header[1],
            status1: header[2],
            modbus_read_len: header[3],
            sys_error: header[4],
            cmd: header[5],
            index: header[6],
            len: header[7],
            data: d,
            data_len: n as u8,
        }
    }

    /// Parses a reply payload (at least the 8-byte header).
    pub fn decode(payload: &[u8]) -> Option<Self> {
        let header: [u8; END_BOARD_REPLY_HEADER] =
            payload.get(..END_BOARD_REPLY_HEADER)?.try_into().ok()?;
        Some(Self::new(header, &payload[END_BOARD_REPLY_HEADER..]))
    }

    /// The data bytes after the header (a frame's padding included).
    pub fn data(&self) -> &[u8] {
        &self.data[..usize::from(self.data_len)]
    }

    /// The payload (header, then data).
    pub fn encode(&self, out: &mut [u8; 64]) -> usize {
        out[..END_BOARD_REPLY_HEADER].copy_from_slice(&[
            self.counter,
            self.status0,
            self.status1,
            self.modbus_read_len,
            self.sys_error,
            self.cmd,
            self.index,
            self.len,
        ]);
        let n = usize::from(self.data_len);
        out[END_BOARD_REPLY_HEADER..END_BOARD_REPLY_HEADER + n].copy_from_slice(self.data());
        END_BOARD_REPLY_HEADER + n
    }

    /// Whether this answers `op`: the same command and register, and a read's length
    /// byte covers the registers asked for.
    pub fn answers(&self, op: &EndBoardOp) -> bool {
        match op {
            EndBoardOp::Read { index, count } => {
                self.cmd == END_BOARD_READ
                    && self.index == *index
                    && usize::from(self.len) >= 2 * usize::from(*count)
                    && self.data().len() >= 2 * usize::from(*count)
            }
            EndBoardOp::Write { index, .. } => {
                self.cmd == END_BOARD_WRITE && self.index == *index && !self.data().is_empty()
            }
        }
    }

    /// The `i`-th 16-bit word of a read reply.
    pub fn word(&self, i: usize) -> Option<u16> {
        let d = self.data();
        Some(u16::from_le_bytes([*d.get(2 * i)?, *d.get(2 * i + 1)?]))
    }

    /// Whether a write reply says it succeeded (data byte 1).
    pub fn write_ok(&self) -> bool {
        self.cmd == END_BOARD_WRITE && self.data().first() == Some(&1)
    }
}

/// One register of the end board's own map (§8.10; unrelated to a joint's table).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct EndBoardRegister {
    /// Address.
    pub addr: u8,
    /// Name.
    pub name: &'static str,
    /// Whether the host may write it.
    pub writable: bool,
    /// What it is.
    pub meaning: &'static str,
}

const fn eb(
    addr: u8,
    name: &'static str,
    writable: bool,
    meaning: &'static str,
) -> EndBoardRegister {
    EndBoardRegister {
        addr,
        name,
        writable,
        meaning,
    }
}

/// The end board's registers (0x60..=0x6F write and 0x70..=0x7F read buffers of the Modbus
/// bridge are listed by their first address).
pub const END_BOARD_REGISTERS: [EndBoardRegister; 17] = [
    eb(0x02, "EB_MODEL_TYPE", false, "end board model"),
    eb(
        0x03,
        "EB_SW_VERSION",
        false,
        "software version, major byte then minor byte",
    ),
    eb(
        0x07,
        "EB_VOLTAGE_OUTPUT",
        true,
        "tool power: 0 = 0 V, 2 = 12 V, 3 = 24 V",
    ),
    eb(
        0x0C,
        "EB_SAVE_TO_FLASH",
        true,
        "1 = save 0x00..=0x0B to flash",
    ),
    eb(
        0x0F,
        "EB_MODBUS_RTU",
        true,
        "RS-485 Modbus RTU: 0 off, 1 = 9600, 2 = 115200, 3 = 460800 baud",
    ),
    eb(0x10, "EB_TEACH_IO", false, "teach button: 1 = pressed"),
    eb(
        0x11,
        "EB_TRAJECTORY_RECORD",
        false,
        "replay button: 1 = pressed and released",
    ),
    eb(
        0x1D,
        "EB_IO1_MODE",
        true,
        "digital channel 1: 0 = input, 1 = output",
    ),
    eb(
        0x1E,
        "EB_IO2_MODE",
        true,
        "digital channel 2: 0 = input, 1 = output",
    ),
    eb(
        0x1F,
        "EB_ON_DELAY",
        true,
        "0 = delayed power-up, 1 = no delay",
    ),
    eb(
        0x33,
        "EB_FORCE_FX_L",
        false,
        "force/torque sensor Fx..Mz, L/H pairs 0x33..=0x3E",
    ),
    eb(
        0x5C,
        "EB_MODBUS_WRITE_LEN",
        true,
        "bytes in the Modbus write buffer",
    ),
    eb(
        0x5D,
        "EB_MODBUS_READ_LEN",
        true,
        "bytes read into the Modbus read buffer",
    ),
    eb(
        0x60,
        "EB_MODBUS_WRITE",
        true,
        "Modbus write buffer 0x60..=0x6F (32 bytes)",
    ),
    eb(
        0x70,
        "EB_MODBUS_READ",
        false,
        "Modbus read buffer 0x70..=0x7F",
    ),
    eb(0x78, "EB_ERROR", false, "error code"),
    eb(
        0x79,
        "EB_END_BOARD_MODE",
        true,
        "0 = the end board is not a joint, 1 = it acts as one",
    ),
];

impl EndBoardRegister {
    /// The register at `addr` (the Modbus buffers and the sensor pairs by any of their
    /// addresses).
    pub fn by_addr(addr: u8) -> Option<&'static Self> {
        let base = match addr {
            0x34..=0x3E => 0x33,
            0x61..=0x6F => 0x60,
            0x71..=0x7F => 0x70,
            a => a,
        };
        END_BOARD_REGISTERS.iter().find(|r| r.addr == base)
    }

    /// The register named `name` (case-insensitive, with or without `EB_`).
    pub fn by_name(name: &str) -> Option<&'static Self> {
        END_BOARD_REGISTERS.iter().find(|r| {
            r.name.eq_ignore_ascii_case(name)
                || r.name
                    .get(3..)
                    .is_some_and(|n| n.eq_ignore_ascii_case(name))
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn end_board_ops_and_replies_follow_the_worked_examples() {
        // 0x0F with D50..: `02 1D 01 01` (IO1 := output), padded with 0xFF.
        let op = EndBoardOp::write(0x1D, &[1]).unwrap();
        let mut field = [0u8; 13];
        assert!(op.encode_into(&mut field, 0xFF));
        assert_eq!(field[..5], [2, 0x1D, 1, 1, 0xFF]);
        assert_eq!(EndBoardOp::decode(&field), Some(op));
        // 0x7F `02 07 01 03 00…` (tool power := 24 V) -> 0x87 `B8 09 00 00 00 02 07 01 01`.
        let reply = EndBoardReply::decode(&[0xB8, 9, 0, 0, 0, 2, 7, 1, 1]).unwrap();
        assert!(reply.answers(&EndBoardOp::write(7, &[3]).unwrap()) && reply.write_ok());
        assert_eq!(reply.counter, 0xB8);
        // A read of 7 registers is answered with 14 data bytes.
        let read = EndBoardOp::read(0x70, 7).unwrap();
        let mut r = [0u8; 22];
        r[..8].copy_from_slice(&[0xC7, 9, 0, 0x0D, 0, 1, 0x70, 0x0E]);
        r[8..10].copy_from_slice(&[0x02, 0x03]);
        let reply = EndBoardReply::decode(&r).unwrap();
        assert!(reply.answers(&read));
        assert_eq!(reply.word(0), Some(0x0302));
        assert!(!reply.answers(&EndBoardOp::read(0x71, 7).unwrap()));
        // Too long for the 7-byte field of 0x2F; bounds.
        let long = EndBoardOp::write(0x60, &[0; 5]).unwrap();
        let mut seven = [0xAA; 7];
        assert!(!long.encode_into(&mut seven, 0xFF));
        assert_eq!(seven, [0xAA; 7]);
        assert_eq!(
            EndBoardOp::read(1, 0),
            Err(EndBoardOpError::Count { count: 0 })
        );
        assert_eq!(
            EndBoardOp::write(1, &[0; 11]),
            Err(EndBoardOpError::Length { len: 11 })
        );
        assert_eq!(EndBoardOp::decode(&[0; 13]), None);
        assert_eq!(EndBoardRegister::by_name("io1_mode").unwrap().addr, 0x1D);
        assert_eq!(
            EndBoardRegister::by_addr(0x65).unwrap().name,
            "EB_MODBUS_WRITE"
        );
    }
}
