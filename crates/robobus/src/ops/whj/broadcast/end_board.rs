//! The end-effector board's typed operations, on what the vendor documents of it (its
//! field of the 0x0F broadcast register frame, its reply on 0xF7 and its own register
//! map): its state (model, version, tool power, the digital channels' direction and
//! level, the teach and replay buttons, the gripper's and the hand's "in position"), the
//! tool power (0, 12 or 24 V), a digital channel's direction (input or output), and the
//! force sensor's six raw values. Each operation is one frame (a write is followed by a
//! read-back); the board's silence is a no-device failure.

use robobus_whj::broadcast::{BroadcastRegister, EndBoardOp, EndBoardReply, ReplyMask};
use robobus_whj::{Address, CanFrame, Request};
use serde::Serialize;

use super::{EndBoardStatus, Slot, collect, silent};
use crate::ops::OpError;
use crate::ops::whj::whj;
use crate::whj::JointBus;

/// The board's model register.
const MODEL: u8 = 0x02;
/// Its tool power register: 0 = 0 V, 2 = 12 V, 3 = 24 V.
pub const TOOL_POWER: u8 = 0x07;
/// Digital channel 1's direction (channel 2's is the next): 0 input, 1 output.
pub const IO1_MODE: u8 = 0x1D;
/// The force sensor's first register (Fx low word); Fx..Mz as six low / high pairs.
pub const FORCE: u8 = 0x33;

/// Tool power.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum ToolPower {
    /// Off.
    Off,
    /// 12 V.
    V12,
    /// 24 V.
    V24,
}

impl ToolPower {
    /// The power of `volts` (0, 12 or 24).
    pub fn of_volts(volts: u8) -> Result<Self, OpError> {
        match volts {
            0 => Ok(Self::Off),
            12 => Ok(Self::V12),
            24 => Ok(Self::V24),
            v => Err(OpError::invalid("--volts", v, "0, 12 or 24")),
        }
    }

    /// Its code in the tool power register.
    pub const fn code(self) -> u16 {
        match self {
            Self::Off => 0,
            Self::V12 => 2,
            Self::V24 => 3,
        }
    }

    /// Volts.
    pub const fn volts(self) -> u8 {
        match self {
            Self::Off => 0,
            Self::V12 => 12,
            Self::V24 => 24,
        }
    }

    fn of_code(code: u16) -> Option<Self> {
        match code {
            0 => Some(Self::Off),
            2 => Some(Self::V12),
            3 => Some(Self::V24),
            _ => None,
        }
    }
}

/// The frame of one end-board operation (no joint has an operation in it).
pub fn frame(op: EndBoardOp) -> Result<Request, OpError> {
    let mut f = BroadcastRegister::new(ReplyMask::END_BOARD);
    if !op.encode_into(&mut f.end_board, 0xFF) {
        return Err(OpError::invalid(
            "end board",
            format!("{op:?}"),
            "does not fit the 13-byte end-board field",
        ));
    }
    Ok(Request::BroadcastRegister(f))
}

/// A read of `count` registers from `index`.
pub fn read_op(index: u8, count: u8) -> Result<EndBoardOp, OpError> {
    EndBoardOp::read(index, count).map_err(|e| OpError::invalid("end board", index, e.to_string()))
}

/// A write of one register.
pub fn write_op(index: u8, value: u16) -> Result<EndBoardOp, OpError> {
    EndBoardOp::write(index, &value.to_le_bytes())
        .map_err(|e| OpError::invalid("end board", index, e.to_string()))
}

/// Sends `op` and waits for the board's answer to it.
fn exchange(bus: &JointBus, op: EndBoardOp, what: &str) -> Result<EndBoardReply, OpError> {
    let sent = bus.send_broadcast(frame(op)?).map_err(whj)?;
    let (cmd, index) = match op {
        EndBoardOp::Read { index, .. } => (robobus_whj::broadcast::END_BOARD_READ, index),
        EndBoardOp::Write { index, .. } => (robobus_whj::broadcast::END_BOARD_WRITE, index),
    };
    let credit = |_: Slot, f: &CanFrame| {
        (f.standard_raw_id().map(Address::from_raw) == Some(Address::EndBoardRegisterReply))
            .then(|| EndBoardReply::decode(f.data()))
            .flatten()
            .filter(|r| r.cmd == cmd && r.index == index)
    };
    match collect(bus, sent, &[Slot::EndBoard], credit).pop() {
        Some(Ok(Some(r))) => Ok(r),
        Some(Err(f)) => Err(OpError::Device(f.error)),
        _ => Err(OpError::NoDevice(silent(Slot::EndBoard, what, bus).error)),
    }
}

fn words(r: &EndBoardReply) -> Vec<u16> {
    r.data()
        .chunks_exact(2)
        .map(|p| u16::from_le_bytes([p[0], p[1]]))
        .collect()
}

/// The board's state.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, schemars::JsonSchema)]
pub struct EndBoardState {
    /// Model register.
    pub model: u16,
    /// Software version, major.minor.
    pub version: String,
    /// Tool power, volts (`None`: a code the vendor does not document).
    pub tool_volts: Option<u8>,
    /// The status bits of its answer.
    #[serde(flatten)]
    pub status: EndBoardStatus,
}

/// Reads the board's state: registers 0x02..=0x07 and the status of its answer.
pub fn state(bus: &JointBus) -> Result<EndBoardState, OpError> {
    let r = exchange(bus, read_op(MODEL, 6)?, "end-board read")?;
    let w = words(&r);
    let at = |a: u8| w.get(usize::from(a - MODEL)).copied();
    let version = at(0x03).unwrap_or(0).to_be_bytes();
    Ok(EndBoardState {
        model: at(MODEL).unwrap_or(0),
        version: format!("{}.{}", version[0], version[1]),
        tool_volts: at(TOOL_POWER)
            .and_then(ToolPower::of_code)
            .map(ToolPower::volts),
        status: EndBoardStatus::of(&r),
    })
}

/// Writes one register and reads it back: the value read.
fn write_verified(bus: &JointBus, index: u8, value: u16, what: &str) -> Result<u16, OpError> {
    let ack = exchange(bus, write_op(index, value)?, what)?;
    if ack.data().first() != Some(&1) {
        return Err(OpError::Device(format!(
            "end board: refused the write of {value} to register 0x{index:02X} ({what})"
        )));
    }
    let back = exchange(bus, read_op(index, 1)?, "end-board read-back")?;
    let got = words(&back).first().copied().ok_or_else(|| {
        OpError::Device(format!("end board: no data read back from 0x{index:02X}"))
    })?;
    if got != value {
        return Err(OpError::Device(format!(
            "end board: register 0x{index:02X} reads back {got} after writing {value} ({what})"
        )));
    }
    Ok(got)
}

/// What a write did.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, schemars::JsonSchema)]
pub struct EndBoardSet {
    /// The register written.
    pub register: String,
    /// The value read back.
    pub read_back: u16,
    /// What it means.
    pub meaning: String,
}

/// Switches the tool power, verified.
pub fn set_power(bus: &JointBus, power: ToolPower) -> Result<EndBoardSet, OpError> {
    let got = write_verified(bus, TOOL_POWER, power.code(), "tool power")?;
    Ok(EndBoardSet {
        register: "EB_VOLTAGE_OUTPUT".into(),
        read_back: got,
        meaning: format!("tool power {} V", power.volts()),
    })
}

/// Sets digital channel `channel` (1 or 2) to output (`true`) or input, verified.
pub fn set_io(bus: &JointBus, channel: u8, output: bool) -> Result<EndBoardSet, OpError> {
    let index = io_register(channel)?;
    let got = write_verified(bus, index, u16::from(output), "channel direction")?;
    Ok(EndBoardSet {
        register: format!("EB_IO{channel}_MODE"),
        read_back: got,
        meaning: format!(
            "digital channel {channel}: {}",
            if output { "output" } else { "input" }
        ),
    })
}

/// The register of digital channel `channel`'s direction.
pub fn io_register(channel: u8) -> Result<u8, OpError> {
    match channel {
        1 | 2 => Ok(IO1_MODE + channel - 1),
        c => Err(OpError::invalid("--channel", c, "1 or 2")),
    }
}

/// The force sensor's six values, raw (the vendor documents the registers, not their
/// unit).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, schemars::JsonSchema)]
pub struct Force {
    /// Fx, raw.
    pub fx: i32,
    /// Fy, raw.
    pub fy: i32,
    /// Fz, raw.
    pub fz: i32,
    /// Mx, raw.
    pub mx: i32,
    /// My, raw.
    pub my: i32,
    /// Mz, raw.
    pub mz: i32,
}

/// Reads the force sensor (registers 0x33..=0x3E, six low / high pairs).
pub fn force(bus: &JointBus) -> Result<Force, OpError> {
    let r = exchange(bus, read_op(FORCE, 12)?, "end-board force read")?;
    let w = words(&r);
    let v = |k: usize| {
        let lo = u32::from(w.get(2 * k).copied().unwrap_or(0));
        let hi = u32::from(w.get(2 * k + 1).copied().unwrap_or(0));
        (hi << 16 | lo).cast_signed()
    };
    if w.len() < 12 {
        return Err(OpError::Device(format!(
            "end board: the force read gave {} of 12 registers",
            w.len()
        )));
    }
    Ok(Force {
        fx: v(0),
        fy: v(1),
        fz: v(2),
        mx: v(3),
        my: v(4),
        mz: v(5),
    })
}
