//! Seeded, reproducible fault injection for byte links and frame links.
//!
//! [`FaultyByteLink`] and [`FaultyFrameLink`] wrap any link and implement the same trait.
//! Every random decision comes from `ChaCha8` streams seeded by [`FaultConfig::seed`], so
//! the same seed and the same traffic give the same faults, run after run: one stream per
//! direction for the per-byte / per-frame decisions, and one each for the per-call ones
//! (delay; cutting a write short). The faults a byte meets therefore depend only on its
//! place in its direction's traffic, not on how the operating system happened to split
//! that traffic into reads and writes, nor on how the two directions interleaved.
//!
//! Units: on a byte link `drop`, `corrupt` and `duplicate` apply per byte, `truncate` and
//! `delay` per write (or read) call; on a frame link everything applies per frame
//! (corrupt = one bit flipped in the payload, truncate = payload cut to a shorter legal
//! length). `disconnect_after` counts successful calls (writes + reads, or sends +
//! receives); after that many the link reports `Closed` forever.

use std::collections::VecDeque;
use std::time::{Duration, Instant};

use rand_chacha::ChaCha8Rng;
use rand_chacha::rand_core::{Rng as RngCore, SeedableRng};
use robobus_whj::frame::{CanFrame, dlc_to_len};

use crate::byte::{ByteLink, LinkError};
use crate::frame_link::{FrameLink, FrameLinkError, IdFilter, Received};

/// Which faults to inject, how often, and the seed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FaultConfig {
    /// Seed of the random stream.
    pub seed: u64,
    /// Probability of losing a byte / frame.
    pub drop: f64,
    /// Probability of flipping one random bit of a byte / frame payload.
    pub corrupt: f64,
    /// Probability of sending a byte / frame twice.
    pub duplicate: f64,
    /// Probability of cutting a write (at a random point) / a frame payload (to a shorter
    /// legal length).
    pub truncate: f64,
    /// Probability of holding a write / read / frame back by [`FaultConfig::delay_by`].
    pub delay: f64,
    /// How long a delayed operation waits.
    pub delay_by: Duration,
    /// After this many successful calls the link reports `Closed`.
    pub disconnect_after: Option<u64>,
    /// Inject into outgoing traffic (writes / sends).
    pub tx: bool,
    /// Inject into incoming traffic (reads / receives).
    pub rx: bool,
}

impl FaultConfig {
    /// No faults at all, both directions enabled, the given seed: a base for
    /// `FaultConfig { corrupt: 0.01, ..FaultConfig::seeded(7) }`.
    pub const fn seeded(seed: u64) -> Self {
        Self {
            seed,
            drop: 0.0,
            corrupt: 0.0,
            duplicate: 0.0,
            truncate: 0.0,
            delay: 0.0,
            delay_by: Duration::from_millis(1),
            disconnect_after: None,
            tx: true,
            rx: true,
        }
    }
}

/// How many faults were injected so far.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct FaultStats {
    /// Bytes / frames lost.
    pub dropped: u64,
    /// Bytes / frames with a flipped bit.
    pub corrupted: u64,
    /// Bytes / frames sent twice.
    pub duplicated: u64,
    /// Writes / frames cut short.
    pub truncated: u64,
    /// Operations delayed.
    pub delayed: u64,
}

/// Which random stream a decision draws from (see the [module docs](self)).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Stream {
    /// Per byte / frame, outgoing.
    Tx = 0,
    /// Per byte / frame, incoming.
    Rx = 1,
    /// Per call: delay.
    Delay = 2,
    /// Per write: cutting it short.
    Cut = 3,
}

/// The shared random decision maker.
#[derive(Debug)]
struct Dice {
    streams: [ChaCha8Rng; 4],
    cfg: FaultConfig,
    calls: u64,
    stats: FaultStats,
}

impl Dice {
    fn new(cfg: FaultConfig) -> Self {
        // The outgoing stream is the seed's own stream (as before the streams were split).
        let stream = |salt: u64| ChaCha8Rng::seed_from_u64(cfg.seed ^ salt);
        Self {
            streams: [
                stream(0),
                stream(0x5258_5f72_785f_5258),
                stream(0x4445_4c41_595f_646c),
                stream(0x4355_545f_6375_745f),
            ],
            cfg,
            calls: 0,
            stats: FaultStats::default(),
        }
    }

    fn next(&mut self, s: Stream) -> u64 {
        self.streams
            .get_mut(s as usize)
            .map_or(0, RngCore::next_u64)
    }

    /// True with probability `p` (always consumes one draw, so decisions stay aligned).
    fn chance(&mut self, s: Stream, p: f64) -> bool {
        let x = (self.next(s) >> 11) as f64 / (1u64 << 53) as f64;
        x < p
    }

    /// A uniform number in `0..n` (`n` > 0).
    fn below(&mut self, s: Stream, n: usize) -> usize {
        let n64 = n as u64;
        usize::try_from(self.next(s) % n64.max(1)).unwrap_or(0)
    }

    fn disconnected(&self) -> bool {
        self.cfg.disconnect_after.is_some_and(|n| self.calls >= n)
    }

    fn maybe_delay(&mut self) {
        if let Some(d) = self.delay_due() {
            std::thread::sleep(d);
        }
    }

    /// Whether this call is delayed, and by how much.
    fn delay_due(&mut self) -> Option<Duration> {
        self.chance(Stream::Delay, self.cfg.delay).then(|| {
            self.stats.delayed += 1;
            self.cfg.delay_by
        })
    }

    /// Applies the per-byte faults to `bytes` travelling in direction `s`.
    fn mangle_bytes(&mut self, s: Stream, bytes: &[u8]) -> Vec<u8> {
        let mut out = Vec::with_capacity(bytes.len() + 4);
        for &b in bytes {
            if self.chance(s, self.cfg.drop) {
                self.stats.dropped += 1;
                continue;
            }
            let mut b = b;
            if self.chance(s, self.cfg.corrupt) {
                self.stats.corrupted += 1;
                b ^= 1 << self.below(s, 8);
            }
            out.push(b);
            if self.chance(s, self.cfg.duplicate) {
                self.stats.duplicated += 1;
                out.push(b);
            }
        }
        out
    }

    /// Applies the per-frame faults to a frame travelling in direction `s`; returns the
    /// frames to deliver (0, 1 or 2).
    fn mangle_frame(&mut self, s: Stream, frame: &CanFrame) -> Vec<CanFrame> {
        if self.chance(s, self.cfg.drop) {
            self.stats.dropped += 1;
            return Vec::new();
        }
        let mut data = [0u8; 64];
        let len = frame.len();
        data[..len].copy_from_slice(frame.data());
        let mut new_len = len;
        if self.chance(s, self.cfg.corrupt) && len > 0 {
            self.stats.corrupted += 1;
            let bit = self.below(s, len * 8);
            if let Some(b) = data.get_mut(bit / 8) {
                *b ^= 1 << (bit % 8);
            }
        }
        if self.chance(s, self.cfg.truncate) && len > 0 {
            self.stats.truncated += 1;
            // A shorter legal length for the frame's kind.
            let shorter: Vec<usize> = if frame.is_fd() {
                (0u8..16)
                    .filter_map(dlc_to_len)
                    .filter(|l| *l < len)
                    .collect()
            } else {
                (0..len).collect()
            };
            new_len = shorter
                .get(self.below(s, shorter.len()))
                .copied()
                .unwrap_or(0);
        }
        let payload = data.get(..new_len).unwrap_or_default();
        let rebuilt = if frame.is_fd() {
            CanFrame::new_fd(frame.id(), payload)
                .map(|f| f.with_brs(frame.brs()).with_esi(frame.esi()))
        } else {
            CanFrame::new_classic(frame.id(), payload)
        };
        // The lengths chosen above are always legal; keep the original if not.
        let out = rebuilt.unwrap_or(*frame);
        if self.chance(s, self.cfg.duplicate) {
            self.stats.duplicated += 1;
            vec![out, out]
        } else {
            vec![out]
        }
    }
}

/// A byte link that injects faults (see the [module docs](self)).
#[derive(Debug)]
pub struct FaultyByteLink<L> {
    inner: L,
    dice: Dice,
    pending: VecDeque<u8>,
}

impl<L: ByteLink> FaultyByteLink<L> {
    /// Wraps `inner`.
    pub fn new(inner: L, config: FaultConfig) -> Self {
        Self {
            inner,
            dice: Dice::new(config),
            pending: VecDeque::new(),
        }
    }

    /// Faults injected so far.
    pub const fn stats(&self) -> FaultStats {
        self.dice.stats
    }

    /// The wrapped link.
    pub fn into_inner(self) -> L {
        self.inner
    }

    fn closed() -> LinkError {
        LinkError::Closed {
            context: "fault injection: disconnected after the configured number of calls".into(),
        }
    }
}

impl<L: ByteLink> ByteLink for FaultyByteLink<L> {
    fn write_all(&mut self, bytes: &[u8]) -> Result<(), LinkError> {
        if self.dice.disconnected() {
            return Err(Self::closed());
        }
        if !self.dice.cfg.tx {
            self.dice.calls += 1;
            return self.inner.write_all(bytes);
        }
        self.delay();
        let mut out = self.dice.mangle_bytes(Stream::Tx, bytes);
        if self.dice.chance(Stream::Cut, self.dice.cfg.truncate) && !out.is_empty() {
            self.dice.stats.truncated += 1;
            let keep = self.dice.below(Stream::Cut, out.len());
            out.truncate(keep);
        }
        self.dice.calls += 1;
        self.inner.write_all(&out)
    }

    fn read_some(&mut self, buf: &mut [u8], deadline: Instant) -> Result<usize, LinkError> {
        if self.dice.disconnected() {
            return Err(Self::closed());
        }
        if buf.is_empty() {
            return Ok(0);
        }
        loop {
            if !self.pending.is_empty() {
                let n = buf.len().min(self.pending.len());
                for (slot, b) in buf.iter_mut().zip(self.pending.drain(..n)) {
                    *slot = b;
                }
                self.dice.calls += 1;
                return Ok(n);
            }
            let mut tmp = vec![0u8; buf.len()];
            let n = self.inner.read_some(&mut tmp, deadline)?;
            let got = tmp.get(..n).unwrap_or_default();
            if self.dice.cfg.rx {
                self.delay();
                self.pending.extend(self.dice.mangle_bytes(Stream::Rx, got));
            } else {
                self.pending.extend(got);
            }
        }
    }

    fn discard_input(&mut self) -> Result<(), LinkError> {
        self.pending.clear();
        self.inner.discard_input()
    }

    crate::forward_byte_link_rate_and_clock!(inner);
}

impl<L: ByteLink> FaultyByteLink<L> {
    /// An injected delay, on the inner link's clock.
    fn delay(&mut self) {
        if let Some(d) = self.dice.delay_due() {
            let until = self.inner.now() + d;
            self.inner.sleep_until(until);
        }
    }
}

/// A frame link that injects faults (see the [module docs](self)).
#[derive(Debug)]
pub struct FaultyFrameLink<L> {
    inner: L,
    dice: Dice,
    pending: VecDeque<Received>,
}

impl<L: FrameLink> FaultyFrameLink<L> {
    /// Wraps `inner`.
    pub fn new(inner: L, config: FaultConfig) -> Self {
        Self {
            inner,
            dice: Dice::new(config),
            pending: VecDeque::new(),
        }
    }

    /// Faults injected so far.
    pub const fn stats(&self) -> FaultStats {
        self.dice.stats
    }

    /// The wrapped link.
    pub fn into_inner(self) -> L {
        self.inner
    }

    fn closed() -> FrameLinkError {
        FrameLinkError::Closed {
            context: "fault injection: disconnected after the configured number of calls".into(),
        }
    }
}

impl<L: FrameLink> FrameLink for FaultyFrameLink<L> {
    fn send(&mut self, frame: &CanFrame) -> Result<(), FrameLinkError> {
        if self.dice.disconnected() {
            return Err(Self::closed());
        }
        self.dice.calls += 1;
        if !self.dice.cfg.tx {
            return self.inner.send(frame);
        }
        self.dice.maybe_delay();
        for f in self.dice.mangle_frame(Stream::Tx, frame) {
            self.inner.send(&f)?;
        }
        Ok(())
    }

    fn recv(&mut self, deadline: Instant) -> Result<Received, FrameLinkError> {
        if self.dice.disconnected() {
            return Err(Self::closed());
        }
        loop {
            if let Some(r) = self.pending.pop_front() {
                self.dice.calls += 1;
                return Ok(r);
            }
            let r = self.inner.recv(deadline)?;
            if self.dice.cfg.rx {
                self.dice.maybe_delay();
                for frame in self.dice.mangle_frame(Stream::Rx, &r.frame) {
                    self.pending.push_back(Received {
                        frame,
                        timestamp: r.timestamp,
                    });
                }
            } else {
                self.pending.push_back(r);
            }
        }
    }

    fn set_filters(&mut self, filters: &[IdFilter]) -> Result<(), FrameLinkError> {
        self.inner.set_filters(filters)
    }

    crate::forward_frame_link_clock!(inner);
}
