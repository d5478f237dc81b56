//! The UART line at bit level: characters as 8N1 waveforms, wired-AND of every
//! transmitter, and receivers that sample the waveform at their own baud rate.
//!
//! This is how the simulator models a baud mismatch and colliding replies faithfully:
//!
//! * A transmitted character is a [`Frame`]: a start bit (low), eight data bits LSB first
//!   and a stop bit (high), each `1 / baud` long. The idle line is high.
//! * Several transmitters drive the same wire (two servos with one ID): the line is low
//!   whenever any of them drives it low (open-collector wired-AND), bit by bit.
//! * A [`Receiver`] works as an AVR USART does: it waits for a high→low edge, checks the
//!   start bit in its middle, samples each data bit in its middle and the stop bit in its
//!   middle (a low stop bit is a framing error; the byte is still delivered, as firmware
//!   that does not check the flag would take it), then looks for the next edge from the
//!   middle of the stop bit. Its own bit time comes from its own baud rate, so a receiver at
//!   another baud than the transmitter reads the bytes a real one would read.
//! * A received byte is released at `edge + 10 bit times` of the receiver: for matching
//!   baud rates that is the instant the last bit of the character leaves the wire.
//!
//! Times are integer nanoseconds since the start of the simulation.

use std::collections::VecDeque;

/// Nanoseconds in a second.
const NS: u64 = 1_000_000_000;

/// Bits in one 8N1 character.
const BITS: u64 = 10;

/// The longest character any supported baud rate produces (10 bits at 4800 bit/s), plus
/// slack: frames that started longer ago than this before `t` cannot cover `t`.
const MAX_FRAME_NS: u64 = BITS * NS / 4800 + 1;

/// Start of bit `k` (0 = start bit, 10 = end of the stop bit) of a character that starts
/// at `start` at `baud`.
pub(crate) const fn bit_boundary(start: u64, baud: u32, k: u64) -> u64 {
    start + k * NS / baud as u64
}

/// Middle of bit `k` at `baud`, for a character whose start edge is at `edge`.
const fn bit_middle(edge: u64, baud: u32, k: u64) -> u64 {
    edge + (2 * k + 1) * NS / (2 * baud as u64)
}

/// Duration of one character (10 bits) at `baud`, in nanoseconds.
pub(crate) const fn char_ns(baud: u32) -> u64 {
    BITS * NS / baud as u64
}

/// One character on the wire.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Frame {
    /// When the start bit begins.
    pub(crate) start: u64,
    /// The transmitter's baud rate.
    pub(crate) baud: u32,
    /// The byte sent.
    pub(crate) byte: u8,
}

impl Frame {
    /// When the stop bit ends.
    pub(crate) const fn end(&self) -> u64 {
        bit_boundary(self.start, self.baud, BITS)
    }

    /// Line level this frame drives at `t` (true = high / idle).
    fn level(&self, t: u64) -> bool {
        if t < self.start || t >= self.end() {
            return true;
        }
        let baud = u64::from(self.baud);
        let mut k = ((t - self.start) * baud) / NS;
        if k < BITS && bit_boundary(self.start, self.baud, k + 1) <= t {
            k += 1;
        }
        match k {
            0 => false,
            1..=8 => (self.byte >> (k - 1)) & 1 == 1,
            _ => true,
        }
    }
}

/// A wire with any number of transmitters, as a time-ordered list of frames.
#[derive(Debug, Clone)]
pub(crate) struct Line {
    frames: VecDeque<Frame>,
    /// Longest frame on the line (bounds how far back a frame can cover a given time).
    max_len: u64,
}

impl Default for Line {
    fn default() -> Self {
        Self {
            frames: VecDeque::new(),
            max_len: 1,
        }
    }
}

impl Line {
    /// Adds a character (frames arrive mostly in time order; an earlier one is inserted in
    /// place).
    pub(crate) fn push(&mut self, frame: Frame) {
        self.max_len = self.max_len.max(frame.end() - frame.start + 1);
        if self.frames.back().is_none_or(|f| f.start <= frame.start) {
            self.frames.push_back(frame);
        } else {
            let at = self.frames.partition_point(|f| f.start <= frame.start);
            self.frames.insert(at, frame);
        }
    }

    /// Forgets frames that ended at or before `t`.
    pub(crate) fn prune(&mut self, t: u64) {
        // Frames are ordered by start, not end, but all have a bounded length.
        while let Some(f) = self.frames.front() {
            if f.end() <= t && f.start + MAX_FRAME_NS <= t {
                self.frames.pop_front();
            } else {
                break;
            }
        }
        if self.frames.is_empty() {
            self.max_len = 1;
        }
    }

    /// Number of frames still held (for tests and diagnostics).
    #[cfg(test)]
    pub(crate) fn len(&self) -> usize {
        self.frames.len()
    }

    /// The wired-AND level of the line at `t` (true = high).
    pub(crate) fn level(&self, t: u64) -> bool {
        let upto = self.frames.partition_point(|f| f.start <= t);
        let mut i = upto;
        while i > 0 {
            i -= 1;
            let Some(f) = self.frames.get(i) else { break };
            if f.start + self.max_len <= t {
                break;
            }
            if !f.level(t) {
                return false;
            }
        }
        true
    }

    /// Whether `frame` (at index `i`) is alone on the line for its whole duration.
    fn is_alone(&self, i: usize) -> bool {
        let Some(f) = self.frames.get(i) else {
            return false;
        };
        let before_ok = i == 0
            || (0..i)
                .rev()
                .map_while(|j| self.frames.get(j))
                .take_while(|p| p.start + self.max_len > f.start)
                .all(|p| p.end() <= f.start);
        let after_ok = self.frames.get(i + 1).is_none_or(|n| n.start >= f.end());
        before_ok && after_ok
    }

    /// The first high→low edge at or after `from`, with the index of the frame it belongs
    /// to.
    fn find_edge(&self, from: u64) -> Option<(u64, usize)> {
        let mut best: Option<(u64, usize)> = None;
        // Frames that can still produce an edge at or after `from`.
        let first = self
            .frames
            .partition_point(|f| f.start + self.max_len <= from);
        for (i, f) in self.frames.iter().enumerate().skip(first) {
            if let Some((b, _)) = best
                && f.start > b
            {
                break;
            }
            if f.end() <= from {
                continue;
            }
            for k in 0..BITS {
                let b = bit_boundary(f.start, f.baud, k);
                if b < from {
                    continue;
                }
                if best.is_some_and(|(bb, _)| b >= bb) {
                    break;
                }
                // A bit that is low in this frame starts a low level only if the line was
                // high just before.
                if !f.level(b) && (b == 0 || self.level(b - 1)) && !self.level(b) {
                    best = Some((b, i));
                    break;
                }
            }
        }
        best
    }
}

/// A byte as a receiver read it off the line.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct RxByte {
    /// When the receiver has it: the end of its stop bit at the receiver's baud.
    pub(crate) at: u64,
    /// The sampled bits.
    pub(crate) byte: u8,
    /// Whether the stop bit was high (false: framing error).
    pub(crate) framing_ok: bool,
}

/// A UART receiver at its own baud rate.
#[derive(Debug, Clone)]
pub(crate) struct Receiver {
    baud: u32,
    /// Look for the next start edge from here.
    resume: u64,
}

impl Receiver {
    /// A receiver at `baud` that listens from `from` on.
    pub(crate) const fn new(baud: u32, from: u64) -> Self {
        Self { baud, resume: from }
    }

    /// The receiver's state: two receivers with the same key read the same bytes.
    pub(crate) const fn key(&self) -> (u32, u64) {
        (self.baud, self.resume)
    }

    /// Changes the baud rate from `at` on (bytes in flight before are abandoned).
    pub(crate) fn set_baud(&mut self, baud: u32, at: u64) {
        self.baud = baud;
        self.resume = self.resume.max(at);
    }

    /// Earliest time the next byte could be complete, given the frames known now.
    pub(crate) fn next_ready(&self, line: &Line) -> Option<u64> {
        line.find_edge(self.resume)
            .map(|(e, _)| e + char_ns(self.baud))
    }

    /// Reads the next byte if it is complete by `now`. Only call this once every frame
    /// that starts before `now` is on the line.
    pub(crate) fn poll(&mut self, line: &Line, now: u64) -> Option<RxByte> {
        loop {
            let (edge, idx) = line.find_edge(self.resume)?;
            let done = edge + char_ns(self.baud);
            if done > now {
                return None;
            }
            // Fast path: an undisturbed character at our own baud reads as sent.
            if let Some(f) = line.frames.get(idx)
                && f.start == edge
                && f.baud == self.baud
                && line.is_alone(idx)
            {
                self.resume = bit_middle(edge, self.baud, 9);
                return Some(RxByte {
                    at: done,
                    byte: f.byte,
                    framing_ok: true,
                });
            }
            let start_mid = bit_middle(edge, self.baud, 0);
            if line.level(start_mid) {
                // Glitch, not a start bit: look again after it.
                self.resume = start_mid;
                continue;
            }
            let mut byte = 0u8;
            for k in 1..=8u64 {
                if line.level(bit_middle(edge, self.baud, k)) {
                    byte |= 1 << (k - 1);
                }
            }
            let stop_mid = bit_middle(edge, self.baud, 9);
            let framing_ok = line.level(stop_mid);
            self.resume = stop_mid;
            return Some(RxByte {
                at: done,
                byte,
                framing_ok,
            });
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn send(line: &mut Line, start: u64, baud: u32, bytes: &[u8]) -> u64 {
        let mut t = start;
        for &b in bytes {
            line.push(Frame {
                start: t,
                baud,
                byte: b,
            });
            t = bit_boundary(t, baud, BITS);
        }
        t
    }

    fn receive_all(rx: &mut Receiver, line: &Line) -> Vec<RxByte> {
        let mut out = Vec::new();
        while let Some(b) = rx.poll(line, u64::MAX / 2) {
            out.push(b);
        }
        out
    }

    #[test]
    fn same_baud_reads_every_byte_at_its_last_bit() {
        for baud in [
            4800, 9600, 38_400, 57_600, 115_200, 230_400, 460_800, 921_600,
        ] {
            let bytes: Vec<u8> = (0..=255).collect();
            let mut line = Line::default();
            send(&mut line, 1000, baud, &bytes);
            let mut rx = Receiver::new(baud, 0);
            let got = receive_all(&mut rx, &line);
            assert_eq!(got.len(), 256, "baud {baud}");
            let mut start = 1000;
            for (i, b) in got.iter().enumerate() {
                assert_eq!(usize::from(b.byte), i);
                assert!(b.framing_ok);
                start += char_ns(baud);
                assert_eq!(b.at, start);
            }
        }
    }

    #[test]
    fn slow_path_matches_fast_path_for_same_baud() {
        // A collision with an all-ones byte (only its start bit is low) leaves the other
        // byte readable when both start together: the slow path must agree with the data.
        let mut line = Line::default();
        line.push(Frame {
            start: 0,
            baud: 115_200,
            byte: 0x5A,
        });
        line.push(Frame {
            start: 0,
            baud: 115_200,
            byte: 0xFF,
        });
        let mut rx = Receiver::new(115_200, 0);
        let got = receive_all(&mut rx, &line);
        assert_eq!(got.len(), 1);
        assert_eq!(got[0].byte, 0x5A);
        assert!(got[0].framing_ok);
    }

    #[test]
    fn aligned_collision_is_wired_and() {
        let mut line = Line::default();
        send(&mut line, 0, 115_200, &[0x12, 0x7F]);
        send(&mut line, 0, 115_200, &[0x30, 0x9F]);
        let mut rx = Receiver::new(115_200, 0);
        let got: Vec<u8> = receive_all(&mut rx, &line).iter().map(|b| b.byte).collect();
        assert_eq!(got, vec![0x12 & 0x30, 0x7F & 0x9F]);
    }

    #[test]
    fn skewed_collision_garbles() {
        let mut line = Line::default();
        send(&mut line, 0, 115_200, &[0x55, 0x80]);
        // Two thirds of a bit later.
        send(&mut line, 6000, 115_200, &[0x55, 0x80]);
        let mut rx = Receiver::new(115_200, 0);
        let got: Vec<u8> = receive_all(&mut rx, &line).iter().map(|b| b.byte).collect();
        assert_ne!(got, vec![0x55, 0x80]);
    }

    #[test]
    fn baud_mismatch_garbles_both_ways() {
        let cmd = [0xFF, 0xA0, 0x00, 0x20];
        for (tx, rxb) in [
            (115_200, 57_600),
            (57_600, 115_200),
            (115_200, 9600),
            (9600, 921_600),
        ] {
            let mut line = Line::default();
            send(&mut line, 0, tx, &cmd);
            let mut rx = Receiver::new(rxb, 0);
            let got: Vec<u8> = receive_all(&mut rx, &line).iter().map(|b| b.byte).collect();
            assert_ne!(got, cmd.to_vec(), "{tx} -> {rxb}");
        }
    }

    #[test]
    fn double_speed_receiver_sees_known_pattern() {
        // 0x00 at 57600 is 9 low bit-times of 17.36 us: a 115200 receiver sees a start bit
        // and eight low data bits, then a low stop sample: 0x00 with a framing error.
        let mut line = Line::default();
        send(&mut line, 0, 57_600, &[0x00]);
        let mut rx = Receiver::new(115_200, 0);
        let got = receive_all(&mut rx, &line);
        assert_eq!(got[0].byte, 0x00);
        assert!(!got[0].framing_ok);
    }

    #[test]
    fn waits_until_byte_is_complete() {
        let mut line = Line::default();
        send(&mut line, 0, 115_200, &[0x42]);
        let mut rx = Receiver::new(115_200, 0);
        let end = char_ns(115_200);
        assert_eq!(rx.next_ready(&line), Some(end));
        assert_eq!(rx.poll(&line, end - 1), None);
        assert_eq!(rx.poll(&line, end).map(|b| b.byte), Some(0x42));
        assert_eq!(rx.next_ready(&line), None);
    }

    #[test]
    fn prune_drops_old_frames() {
        let mut line = Line::default();
        let end = send(&mut line, 0, 115_200, &[1, 2, 3]);
        line.prune(end + MAX_FRAME_NS);
        assert_eq!(line.len(), 0);
    }
}
