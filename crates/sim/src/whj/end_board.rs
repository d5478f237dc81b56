//! The end-effector board's broadcast side (§8.10 of the WHJ joint protocol reference):
//! its own small register map, read and written through the end-board field of the
//! broadcast frames, answered on 0xF7 (to 0x0F) or 0x87 (to 0x2F, 0x4F, 0x7F) when the
//! reply mask selects it.
//!
//! Simulator choices where the protocol says nothing: a selected end board whose field
//! holds no operation answers with the 8-byte header only (cmd, index and len 0); a
//! write to a read-only register is answered with status 0 and changes nothing.

use core::time::Duration;

use robobus_whj::broadcast::{
    END_BOARD_READ, END_BOARD_REPLY_HEADER, END_BOARD_WRITE, EndBoardOp, EndBoardRegister,
    EndBoardReply,
};
use robobus_whj::id::{END_BOARD_FEEDBACK_ID, END_BOARD_REGISTER_REPLY_ID};
use robobus_whj::{CanFrame, Request};

use super::joint::Reply;

/// How long the end board takes to answer (a joint's default processing delay).
const PROCESSING_DELAY: Duration = Duration::from_micros(20);

/// A simulated end board.
#[derive(Debug, Clone)]
pub struct SimEndBoard {
    registers: [u16; 0x80],
    counter: u8,
    silent: bool,
}

impl Default for SimEndBoard {
    fn default() -> Self {
        Self::new()
    }
}

impl SimEndBoard {
    /// An end board with software version 2.3 and everything else 0.
    pub fn new() -> Self {
        let mut registers = [0u16; 0x80];
        registers[0x02] = 1;
        registers[0x03] = 0x0203;
        Self {
            registers,
            counter: 0,
            silent: false,
        }
    }

    /// The register at `addr` (0 beyond the map).
    pub fn register(&self, addr: u8) -> u16 {
        self.registers.get(usize::from(addr)).copied().unwrap_or(0)
    }

    /// Broadcast frames received (wraps 255 → 0).
    pub const fn counter(&self) -> u8 {
        self.counter
    }

    /// Unplug (`true`) or plug in the board.
    pub fn set_silent(&mut self, silent: bool) {
        self.silent = silent;
    }

    fn status0(&self) -> u8 {
        u8::from(self.registers[0x1D] != 0) << 7 | u8::from(self.registers[0x1E] != 0) << 6
    }

    /// A frame whose last bit arrived at `now`: act on a broadcast frame's end-board field
    /// and answer if the mask selects the end board.
    pub fn handle(&mut self, frame: &CanFrame, now: Duration) -> Option<Reply> {
        if self.silent || !frame.is_fd() {
            return None;
        }
        let (field, mask, reply_id): (Vec<u8>, _, _) = match Request::from_frame(frame).ok()? {
            Request::BroadcastRegister(b) => {
                (b.end_board.to_vec(), b.mask, END_BOARD_REGISTER_REPLY_ID)
            }
            Request::BroadcastPosition(b) => (b.end_board.to_vec(), b.mask, END_BOARD_FEEDBACK_ID),
            Request::BroadcastCurrent(b) => (b.end_board.to_vec(), b.mask, END_BOARD_FEEDBACK_ID),
            Request::BroadcastStatus(b) => (b.end_board.to_vec(), b.mask, END_BOARD_FEEDBACK_ID),
            _ => return None,
        };
        self.counter = self.counter.wrapping_add(1);
        let op = EndBoardOp::decode(&field);
        let (cmd, index, len, data) = match op {
            Some(EndBoardOp::Read { index, count }) => {
                let data: Vec<u8> = (0..count)
                    .flat_map(|k| self.register(index.wrapping_add(k)).to_le_bytes())
                    .collect();
                (END_BOARD_READ, index, 2 * count, data)
            }
            Some(EndBoardOp::Write { index, len, data }) => {
                let ok = self.write(index, &data[..usize::from(len)]);
                (END_BOARD_WRITE, index, len, vec![u8::from(ok)])
            }
            None => (0, 0, 0, Vec::new()),
        };
        if !mask.selects_end_board() {
            return None;
        }
        let reply = EndBoardReply::new(
            [self.counter, self.status0(), 0, 0, 0, cmd, index, len],
            &data,
        );
        let mut out = [0u8; 64];
        let n = reply.encode(&mut out);
        debug_assert!(n >= END_BOARD_REPLY_HEADER);
        let frame =
            CanFrame::new_fd_padded(CanFrame::standard_id(reply_id).ok()?, &out[..n]).ok()?;
        Some(Reply {
            ready_at: now + PROCESSING_DELAY,
            frame,
        })
    }

    /// Writes `bytes` (2 per register, little-endian) from `index`; `false` (nothing
    /// written) if any register touched is read-only or unknown.
    fn write(&mut self, index: u8, bytes: &[u8]) -> bool {
        let regs = bytes.len().div_ceil(2);
        let writable = (0..regs).all(|k| {
            u8::try_from(usize::from(index) + k)
                .ok()
                .and_then(EndBoardRegister::by_addr)
                .is_some_and(|r| r.writable)
        });
        if !writable {
            return false;
        }
        for (k, pair) in bytes.chunks(2).enumerate() {
            let w = u16::from_le_bytes([pair[0], pair.get(1).copied().unwrap_or(0)]);
            if let Some(r) = self.registers.get_mut(usize::from(index) + k) {
                *r = w;
            }
        }
        true
    }
}
