//! Exact frame duration on the wire, bit stuffing counted from the frame's real bits
//! (ISO 11898-1:2015; the numbers are pinned by `tests/timing_golden.rs`).
//!
//! A CAN FD base frame with BRS costs `(28 + s_arb)` nominal bits (SOF, 11 ID bits, RRS,
//! IDE, FDF, res, ACK slot and delimiter, 7 EOF, 3 IFS), one nominal plus one data bit for
//! the BRS bit and the CRC delimiter together (the switch happens at the sample points),
//! and `5 + 8n + s_dat + crc` data bits (ESI, DLC, data, dynamic stuff bits, and the CRC
//! field with its stuff count and fixed stuff bits: 27 bits for n ≤ 16, 32 above).
//! `s_arb` and `s_dat` are the dynamic stuff bits inserted after a run of five equal bits
//! from SOF through the last data bit; a run that ends on the last data bit counts.
//! Without BRS every bit is nominal. Classic CAN frames are counted with their real
//! CRC-15, since classic stuffing covers the CRC.

use core::num::NonZeroU32;
use core::time::Duration;

use crate::frame::{CanFrame, Id};

/// Nominal (arbitration) and data bit rates.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct BitRates {
    /// Arbitration-phase bit rate in bit/s.
    pub nominal: NonZeroU32,
    /// Data-phase bit rate in bit/s (used when BRS is set).
    pub data: NonZeroU32,
}

impl BitRates {
    /// The WHJ bus: 1 Mbit/s nominal, 5 Mbit/s data.
    pub const WHJ: Self = match (NonZeroU32::new(1_000_000), NonZeroU32::new(5_000_000)) {
        (Some(nominal), Some(data)) => Self { nominal, data },
        _ => panic!("nonzero literals"),
    };

    /// Rates in bit/s; `None` if either is 0.
    pub const fn new(nominal: u32, data: u32) -> Option<Self> {
        match (NonZeroU32::new(nominal), NonZeroU32::new(data)) {
            (Some(nominal), Some(data)) => Some(Self { nominal, data }),
            _ => None,
        }
    }
}

/// The arbitration bit rates a joint can be set to, by their code in register 0x08
/// (`SYS_BPS_CANFD_BRT`): 0 = 250 kbit/s, 1 = 500 kbit/s, 2 = 1 Mbit/s.
pub const ARBITRATION_RATES: [u32; 3] = [250_000, 500_000, 1_000_000];
/// The data bit rates a joint can be set to, by their code in register 0x09
/// (`SYS_BPS_CANFD_DATA`): 0 = 250k, 1 = 500k, 2 = 1M, 3 = 2M, 4 = 4M, 5 = 5M.
pub const DATA_RATES: [u32; 6] = [250_000, 500_000, 1_000_000, 2_000_000, 4_000_000, 5_000_000];

impl BitRates {
    /// The rates of the codes in registers 0x08 / 0x09; `None` for a code no rate has.
    pub fn of_codes(arbitration: u16, data: u16) -> Option<Self> {
        let nominal = *ARBITRATION_RATES.get(usize::from(arbitration))?;
        let data = *DATA_RATES.get(usize::from(data))?;
        Self::new(nominal, data)
    }

    /// The codes of these rates in registers 0x08 / 0x09; `None` for rates a joint
    /// cannot be set to.
    pub fn codes(self) -> Option<(u16, u16)> {
        let a = ARBITRATION_RATES
            .iter()
            .position(|&r| r == self.nominal.get())?;
        let d = DATA_RATES.iter().position(|&r| r == self.data.get())?;
        Some((u16::try_from(a).ok()?, u16::try_from(d).ok()?))
    }
}

impl Default for BitRates {
    fn default() -> Self {
        Self::WHJ
    }
}

/// The bit counts of one frame on the wire.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct FrameBits {
    /// Bits sent at the nominal rate (stuff bits included).
    pub nominal_bits: u32,
    /// Bits sent at the data rate (stuff bits included; 0 without BRS).
    pub data_bits: u32,
    /// Whether the BRS bit / CRC delimiter pair (one nominal + one data bit) is present.
    pub switched: bool,
    /// Dynamic stuff bits in the arbitration phase (`s_arb`).
    pub stuff_arb: u32,
    /// Dynamic stuff bits from BRS through the data field (`s_dat`; classic: through CRC).
    pub stuff_data: u32,
}

impl FrameBits {
    /// The frame's duration at `rates`, rounded to the nearest nanosecond.
    pub fn duration(&self, rates: BitRates) -> Duration {
        let (n, d) = (
            u128::from(rates.nominal.get()),
            u128::from(rates.data.get()),
        );
        let mut nominal = u128::from(self.nominal_bits);
        let mut data = u128::from(self.data_bits);
        if self.switched {
            nominal += 1;
            data += 1;
        }
        // ns = nominal·1e9/n + data·1e9/d, computed over a common denominator.
        let num = (nominal * d + data * n) * 1_000_000_000;
        let den = n * d;
        let ns = (num + den / 2) / den;
        Duration::from_nanos(u64::try_from(ns).unwrap_or(u64::MAX))
    }

    /// The duration in microseconds as `f64` (for reports and tables).
    pub fn micros(&self, rates: BitRates) -> f64 {
        self.duration(rates).as_nanos() as f64 / 1000.0
    }
}

/// Counts dynamic stuff bits over a bit stream.
#[derive(Debug, Clone, Copy)]
struct Stuffer {
    last: bool,
    run: u32,
    count: u32,
}

impl Stuffer {
    const fn new() -> Self {
        // SOF is dominant (0); start "before" it with a recessive idle bus.
        Self {
            last: true,
            run: 0,
            count: 0,
        }
    }

    fn push(&mut self, bit: bool) {
        if bit == self.last {
            self.run += 1;
        } else {
            self.last = bit;
            self.run = 1;
        }
        if self.run == 5 {
            self.count += 1;
            self.last = !bit;
            self.run = 1;
        }
    }

    fn push_bits(&mut self, value: u32, width: u32) {
        for i in (0..width).rev() {
            self.push(value >> i & 1 == 1);
        }
    }
}

/// Count a frame's bits.
pub fn frame_bits(frame: &CanFrame) -> FrameBits {
    if frame.is_fd() {
        fd_bits(frame.id(), frame.data(), frame.brs(), frame.esi())
    } else {
        classic_bits(frame.id(), frame.data())
    }
}

/// The frame's duration at `rates`.
pub fn frame_duration(frame: &CanFrame, rates: BitRates) -> Duration {
    frame_bits(frame).duration(rates)
}

fn push_arbitration_fd(s: &mut Stuffer, id: Id) -> u32 {
    s.push(false); // SOF
    match id {
        Id::Standard(id) => {
            s.push_bits(u32::from(id.as_raw()), 11);
            s.push_bits(0b0010, 4); // RRS 0, IDE 0, FDF 1, res 0
            16
        }
        Id::Extended(id) => {
            let raw = id.as_raw();
            s.push_bits(raw >> 18, 11);
            s.push_bits(0b11, 2); // SRR 1, IDE 1
            s.push_bits(raw & 0x3_FFFF, 18);
            s.push_bits(0b010, 3); // RRS 0, FDF 1, res 0
            35
        }
    }
}

#[allow(clippy::cast_possible_truncation)] // payload <= 64 bytes
fn fd_bits(id: Id, data: &[u8], brs: bool, esi: bool) -> FrameBits {
    let mut s = Stuffer::new();
    let arb_bits = push_arbitration_fd(&mut s, id);
    let stuff_arb = s.count;
    s.push(brs);
    s.push(esi);
    let dlc = crate::frame::len_to_dlc(data.len()).unwrap_or(15);
    s.push_bits(u32::from(dlc), 4);
    for b in data {
        s.push_bits(u32::from(*b), 8);
    }
    let stuff_data = s.count - stuff_arb;
    let crc_field = if data.len() <= 16 { 27 } else { 32 };
    let data_phase = 5 + 8 * data.len() as u32 + stuff_data + crc_field;
    // ACK slot, ACK delimiter, 7 EOF, 3 IFS.
    let tail = 12;
    if brs {
        FrameBits {
            nominal_bits: arb_bits + tail + stuff_arb,
            data_bits: data_phase,
            switched: true,
            stuff_arb,
            stuff_data,
        }
    } else {
        FrameBits {
            // BRS bit and CRC delimiter at the nominal rate too.
            nominal_bits: arb_bits + tail + stuff_arb + 2 + data_phase,
            data_bits: 0,
            switched: false,
            stuff_arb,
            stuff_data,
        }
    }
}

/// CRC-15 of classic CAN (polynomial 0x4599) over a bit sequence.
#[derive(Debug, Clone, Copy)]
struct Crc15(u16);

const UNREACHED: (u32, u32) = (u32::MAX, 0);

impl Crc15 {
    fn push(&mut self, bit: bool) {
        let top = (self.0 >> 14) & 1 == 1;
        self.0 = (self.0 << 1) & 0x7FFF;
        if top ^ bit {
            self.0 ^= 0x4599;
        }
    }
}

#[allow(clippy::cast_possible_truncation)] // payload <= 8 bytes
fn classic_bits(id: Id, data: &[u8]) -> FrameBits {
    // Collect the unstuffed bits SOF..data into a fixed buffer (at most 1+32+6+64 = 103).
    let mut bits = [false; 128];
    let mut n = 0usize;
    let mut put = |value: u32, width: u32, bits: &mut [bool; 128]| {
        for i in (0..width).rev() {
            if let Some(slot) = bits.get_mut(n) {
                *slot = value >> i & 1 == 1;
            }
            n += 1;
        }
    };
    put(0, 1, &mut bits); // SOF
    let arb_len = match id {
        Id::Standard(id) => {
            put(u32::from(id.as_raw()), 11, &mut bits);
            put(0, 1, &mut bits); // RTR
            13
        }
        Id::Extended(id) => {
            let raw = id.as_raw();
            put(raw >> 18, 11, &mut bits);
            put(0b11, 2, &mut bits); // SRR, IDE
            put(raw & 0x3_FFFF, 18, &mut bits);
            put(0, 1, &mut bits); // RTR
            33
        }
    };
    put(0, 2, &mut bits); // IDE + r0 (standard) or r1 + r0 (extended), all dominant
    put(data.len().min(8) as u32, 4, &mut bits);
    for b in data {
        put(u32::from(*b), 8, &mut bits);
    }
    let used = n.min(bits.len());
    let mut crc = Crc15(0);
    let mut s = Stuffer::new();
    let mut stuff_arb = 0;
    for (i, bit) in bits[..used].iter().enumerate() {
        crc.push(*bit);
        s.push(*bit);
        if i + 1 == arb_len {
            stuff_arb = s.count;
        }
    }
    s.push_bits(u32::from(crc.0), 15);
    let stuff_data = s.count - stuff_arb;
    // CRC delimiter, ACK slot, ACK delimiter, 7 EOF, 3 IFS.
    let nominal_bits = used as u32 + 15 + s.count + 13;
    FrameBits {
        nominal_bits,
        data_bits: 0,
        switched: false,
        stuff_arb,
        stuff_data,
    }
}

/// The fewest and most dynamic stuff bits any `len`-byte payload can add after the given
/// prefix of a standard-ID CAN FD frame with BRS (exact, by dynamic programming over the
/// data bits). Returns `(min, max)` of `s_dat`, or `None` for an illegal length.
pub fn fd_data_stuff_bounds(id: u16, len: usize, esi: bool) -> Option<(u32, u32)> {
    let dlc = crate::frame::len_to_dlc(len)?;
    let std_id = embedded_can::StandardId::new(id)?;
    let mut s = Stuffer::new();
    push_arbitration_fd(&mut s, Id::Standard(std_id));
    let before = s.count;
    s.push(true); // BRS
    s.push(esi);
    s.push_bits(u32::from(dlc), 4);
    let base = s.count - before;
    // DP over (last bit, run length 1..=5): (min, max) extra stuff bits so far.
    let mut dp = [[UNREACHED; 6]; 2];
    let run0 = usize::try_from(s.run).unwrap_or(1).clamp(1, 5);
    dp[usize::from(s.last)][run0] = (0, 0);
    let mut reachable = [[false; 6]; 2];
    reachable[usize::from(s.last)][run0] = true;
    for _ in 0..len * 8 {
        let mut next = [[UNREACHED; 6]; 2];
        let mut next_reach = [[false; 6]; 2];
        for last in 0..2 {
            for run in 1..6 {
                if !reachable[last][run] {
                    continue;
                }
                let (lo, hi) = dp[last][run];
                for bit in 0..2 {
                    let (mut nl, mut nr, mut add) = if bit == last {
                        (last, run + 1, 0)
                    } else {
                        (bit, 1, 0)
                    };
                    if nr == 5 {
                        add = 1;
                        nl = 1 - bit;
                        nr = 1;
                    }
                    let cell = &mut next[nl][nr];
                    cell.0 = cell.0.min(lo + add);
                    cell.1 = cell.1.max(hi + add);
                    next_reach[nl][nr] = true;
                }
            }
        }
        dp = next;
        reachable = next_reach;
    }
    let mut lo = u32::MAX;
    let mut hi = 0;
    for last in 0..2 {
        for run in 1..6 {
            if reachable[last][run] {
                lo = lo.min(dp[last][run].0);
                hi = hi.max(dp[last][run].1);
            }
        }
    }
    Some((base + lo, base + hi))
}
