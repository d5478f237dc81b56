//! The multi-drop wCK bus: every host byte reaches every servo, replies share one wire.

use core::time::Duration;
use std::collections::VecDeque;
use std::path::Path;

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use robobus_wck::{BaudRate, StreamDecoder};

use super::model::Model;
use super::params::{Eeprom, EepromFileError};
use super::servo::{Servo, Timing};
use super::uart::{Frame, Line, Receiver, RxByte, bit_boundary};
use crate::faults::{DeviceFault, DeviceFaultKind};

/// Seeded, reproducible faults on the wire.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Faults {
    /// Probability that a host byte never reaches the bus.
    pub drop_host: f64,
    /// Probability that a host byte has one bit flipped on the wire.
    pub flip_host: f64,
    /// Probability that a reply byte never reaches the host.
    pub drop_reply: f64,
    /// Probability that a reply byte has one bit flipped on the way to the host.
    pub flip_reply: f64,
    /// Probability that a module answers a command twice: the same reply again,
    /// [`Faults::double_gap`] after the first one's last stop bit.
    pub double_reply: f64,
    /// Quiet time between the two answers of a doubled reply.
    pub double_gap: Duration,
    /// Probability that a reply leaves [`Faults::late_by`] later than the module's
    /// turnaround says (held up on its way: a slow adapter, a module that hiccups).
    pub late_reply: f64,
    /// How much later a late reply leaves.
    pub late_by: Duration,
}

/// How a bus is set up.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BusConfig {
    /// The host's line rate (the endpoint follows the client's termios setting).
    pub host_baud: BaudRate,
    /// Module timing used by [`Bus::add`].
    pub timing: Timing,
    /// Seed of everything random (turnaround spread, faults).
    pub seed: u64,
    /// Modules differ slightly in turnaround (firmware and clock spread): each gets a fixed
    /// extra delay in `0..=max_skew`, drawn from the seed. Two modules with one ID
    /// therefore answer slightly apart and their bits interfere. Default 3 µs.
    pub max_skew: Duration,
    /// Wire faults.
    pub faults: Faults,
}

impl Default for BusConfig {
    fn default() -> Self {
        Self {
            host_baud: BaudRate::DEFAULT,
            timing: Timing::MANUAL,
            seed: 0,
            max_skew: Duration::from_micros(3),
            faults: Faults::default(),
        }
    }
}

/// Counters of what happened on the bus.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct BusStats {
    /// Bytes the host put on the wire.
    pub host_bytes: u64,
    /// Commands decoded by some module (counted once per module).
    pub commands: u64,
    /// Packets a module rejected (bad checksum, unknown code, invalid field, truncated).
    pub decode_errors: u64,
    /// Bytes a module ignored (deaf after power-up, busy, unplugged).
    pub ignored_bytes: u64,
    /// Replies the modules sent.
    pub replies: u64,
    /// Bytes delivered to the host.
    pub received_bytes: u64,
    /// Replies sent twice ([`Faults::double_reply`]).
    pub doubled_replies: u64,
    /// Replies sent late ([`Faults::late_reply`]).
    pub late_replies: u64,
    /// Stray bytes put on the reply line by [`Bus::inject_to_host`].
    pub stray_bytes: u64,
}

#[derive(Debug, Clone)]
struct Slot {
    servo: Servo,
    rx: Receiver,
    decoder: StreamDecoder,
    busy_until: u64,
    plugged: bool,
    skew: u64,
    /// Answers every command twice, this long (ns) apart ([`Bus::set_answers_twice`]).
    double: Option<u64>,
}

/// A simulated wCK bus: servos on one UART wire, with exact wire timing.
///
/// Time is a [`Duration`] since the start of the simulation and only moves forward, by
/// [`Bus::advance`]. The host side writes bytes with [`Bus::host_send`] (they go on the
/// wire back to back at the host's baud rate) and takes what it received with
/// [`Bus::pop_received`], each byte stamped with the instant its stop bit ended.
#[derive(Debug, Clone)]
pub struct Bus {
    config: BusConfig,
    slots: Vec<Slot>,
    down: Line,
    down_free: u64,
    up: Line,
    host_rx: Receiver,
    host_bps: u32,
    received: VecDeque<(Duration, u8)>,
    now: u64,
    rng: ChaCha8Rng,
    fault_rng: ChaCha8Rng,
    stats: BusStats,
}

fn ns(d: Duration) -> u64 {
    u64::try_from(d.as_nanos()).unwrap_or(u64::MAX)
}

const fn dur(ns: u64) -> Duration {
    Duration::from_nanos(ns)
}

/// How far back the lines keep frames (longer than any character being received).
const KEEP_NS: u64 = 5_000_000;

impl Bus {
    /// An empty bus.
    pub fn new(config: BusConfig) -> Self {
        Self {
            config,
            slots: Vec::new(),
            down: Line::default(),
            down_free: 0,
            up: Line::default(),
            host_rx: Receiver::new(config.host_baud.bits_per_second(), 0),
            host_bps: config.host_baud.bits_per_second(),
            received: VecDeque::new(),
            now: 0,
            rng: ChaCha8Rng::seed_from_u64(config.seed),
            fault_rng: ChaCha8Rng::seed_from_u64(config.seed ^ 0x5EED_FA17),
            stats: BusStats::default(),
        }
    }

    /// A bus with one module per ID in `ids`, all of `model`, factory defaults otherwise,
    /// shafts at position 127.
    pub fn with_servos(config: BusConfig, model: Model, ids: impl IntoIterator<Item = u8>) -> Self {
        let mut bus = Self::new(config);
        for id in ids {
            let e = Eeprom {
                id: robobus_wck::ExtServoId::new(id).unwrap_or(robobus_wck::ExtServoId::MAX),
                baud: config.host_baud,
                ..Eeprom::default()
            };
            bus.add(model, e, 127.0 * super::mechanics::DEG_PER_STEP8);
        }
        bus
    }

    /// The configuration.
    pub const fn config(&self) -> &BusConfig {
        &self.config
    }

    /// Adds a module with `eeprom`, its shaft at `angle` degrees, powered on now, with
    /// the bus's timing. Returns its slot index.
    pub fn add(&mut self, model: Model, eeprom: Eeprom, angle: f64) -> usize {
        let servo = Servo::new(model, eeprom, angle, self.config.timing, dur(self.now));
        self.add_servo(servo)
    }

    /// Adds a module. Returns its slot index.
    pub fn add_servo(&mut self, servo: Servo) -> usize {
        let max = ns(self.config.max_skew);
        let skew = if max == 0 {
            0
        } else {
            self.rng.random_range(0..=max)
        };
        let rx = Receiver::new(servo.baud().bits_per_second(), self.now);
        self.slots.push(Slot {
            servo,
            rx,
            decoder: StreamDecoder::new(),
            busy_until: 0,
            plugged: true,
            skew,
            double: None,
        });
        self.slots.len() - 1
    }

    /// Number of modules (slots).
    pub fn len(&self) -> usize {
        self.slots.len()
    }

    /// Whether the bus has no modules.
    pub fn is_empty(&self) -> bool {
        self.slots.is_empty()
    }

    /// The module in slot `i`.
    pub fn servo(&self, i: usize) -> Option<&Servo> {
        self.slots.get(i).map(|s| &s.servo)
    }

    /// The module in slot `i`, to change (the test API: push, hold, set the angle, set
    /// the A/D input). Advance the bus to the moment first.
    pub fn servo_mut(&mut self, i: usize) -> Option<&mut Servo> {
        self.slots.get_mut(i).map(|s| &mut s.servo)
    }

    /// Every module, in slot order.
    pub fn servos(&self) -> impl Iterator<Item = &Servo> {
        self.slots.iter().map(|s| &s.servo)
    }

    /// The slot of the first module with ID `id`.
    pub fn slot_of(&self, id: u8) -> Option<usize> {
        self.slots.iter().position(|s| s.servo.id().get() == id)
    }

    /// Current simulation time.
    pub const fn now(&self) -> Duration {
        dur(self.now)
    }

    /// Counters.
    pub const fn stats(&self) -> BusStats {
        self.stats
    }

    /// The host's line rate in bit/s.
    pub const fn host_bps(&self) -> u32 {
        self.host_bps
    }

    /// Changes the host's line rate from now on.
    pub fn set_host_baud(&mut self, baud: BaudRate) {
        self.set_host_bps(baud.bits_per_second());
    }

    /// Changes the host's line rate from now on, to any rate in bit/s (a client may pick
    /// one no module supports; the modules then read garbage). 0 is ignored.
    pub fn set_host_bps(&mut self, bps: u32) {
        if bps != self.host_bps && bps > 0 {
            self.host_bps = bps;
            self.host_rx.set_baud(bps, self.now);
        }
    }

    /// Puts `bytes` on the wire at the host's baud rate, starting at `at` (or now, or when
    /// the previous host byte is out, whichever is latest). Returns when the last stop bit
    /// ends.
    pub fn host_send(&mut self, at: Duration, bytes: &[u8]) -> Duration {
        let baud = self.host_bps;
        let burst = ns(at).max(self.now).max(self.down_free);
        let f = self.config.faults;
        let mut k = 0;
        for &b in bytes {
            self.stats.host_bytes += 1;
            if f.drop_host > 0.0 && self.fault_rng.random_bool(f.drop_host.min(1.0)) {
                continue;
            }
            let mut byte = b;
            if f.flip_host > 0.0 && self.fault_rng.random_bool(f.flip_host.min(1.0)) {
                byte ^= 1 << self.fault_rng.random_range(0..8u8);
            }
            self.down.push(Frame {
                start: bit_boundary(burst, baud, 10 * k),
                baud,
                byte,
            });
            k += 1;
        }
        self.down_free = bit_boundary(burst, baud, 10 * k);
        dur(self.down_free)
    }

    /// When the next byte completes at a module or at the host, if any is on its way.
    pub fn next_event(&self) -> Option<Duration> {
        let mut next = self.host_rx.next_ready(&self.up);
        // Modules at the same baud rate that listen from the same instant (the usual
        // case) see the same bytes: work it out once.
        let mut seen: Vec<((u32, u64), Option<u64>)> = Vec::new();
        for s in &self.slots {
            let key = s.rx.key();
            let ready = if let Some((_, r)) = seen.iter().find(|(k, _)| *k == key) {
                *r
            } else {
                let r = s.rx.next_ready(&self.down);
                seen.push((key, r));
                r
            };
            if let Some(t) = ready {
                next = Some(next.map_or(t, |n| n.min(t)));
            }
        }
        next.map(dur)
    }

    /// Runs the bus up to `to`: modules decode and answer every byte that completes by
    /// then, mechanics and motion programs advance, the host receives completed reply
    /// bytes. Times before now are ignored.
    pub fn advance(&mut self, to: Duration) {
        let to = ns(to);
        if to < self.now {
            return;
        }
        // Receivers in the same state read the same bytes: decode once per state.
        let mut memo: Vec<((u32, u64), Vec<RxByte>, Receiver)> = Vec::new();
        for slot in &mut self.slots {
            let key = slot.rx.key();
            let i = if let Some(i) = memo.iter().position(|(k, _, _)| *k == key) {
                i
            } else {
                let mut rx = slot.rx.clone();
                let mut bytes = Vec::new();
                while let Some(b) = rx.poll(&self.down, to) {
                    bytes.push(b);
                }
                memo.push((key, bytes, rx));
                memo.len() - 1
            };
            let Some((_, bytes, rx)) = memo.get(i) else {
                continue;
            };
            slot.rx = rx.clone();
            let mut wire = Wire {
                up: &mut self.up,
                stats: &mut self.stats,
                faults: &self.config.faults,
                rng: &mut self.fault_rng,
            };
            for b in bytes {
                if let Some(bps) = deliver(slot, *b, &mut wire) {
                    // The module changed its baud rate: it listens at the new rate once
                    // its reply is out; read the rest of the wire at that rate.
                    slot.rx = Receiver::new(bps, slot.busy_until);
                    while let Some(b) = slot.rx.poll(&self.down, to) {
                        if let Some(bps) = deliver(slot, b, &mut wire) {
                            slot.rx = Receiver::new(bps, slot.busy_until);
                        }
                    }
                    break;
                }
            }
            slot.servo.advance(dur(to));
        }
        let f = self.config.faults;
        while let Some(b) = self.host_rx.poll(&self.up, to) {
            if f.drop_reply > 0.0 && self.fault_rng.random_bool(f.drop_reply.min(1.0)) {
                continue;
            }
            let mut byte = b.byte;
            if f.flip_reply > 0.0 && self.fault_rng.random_bool(f.flip_reply.min(1.0)) {
                byte ^= 1 << self.fault_rng.random_range(0..8u8);
            }
            self.stats.received_bytes += 1;
            self.received.push_back((dur(b.at), byte));
        }
        self.now = to;
        let keep = to.saturating_sub(KEEP_NS);
        self.down.prune(keep);
        self.up.prune(keep);
    }

    /// The oldest byte the host received and has not taken yet, with the instant its stop
    /// bit ended.
    pub fn pop_received(&mut self) -> Option<(Duration, u8)> {
        self.received.pop_front()
    }

    /// The oldest byte the host received and has not taken yet, left in place.
    pub fn peek_received(&self) -> Option<(Duration, u8)> {
        self.received.front().copied()
    }

    /// Bytes received and not taken yet.
    pub fn received_len(&self) -> usize {
        self.received.len()
    }

    /// Puts `bytes` on the reply line at the host's rate from `at` (or now, if that has
    /// passed), as if a module sent them: stray bytes the host receives whatever it asked
    /// (a late reply to a previous program, noise). Returns when the last stop bit ends.
    pub fn inject_to_host(&mut self, at: Duration, bytes: &[u8]) -> Duration {
        let start = ns(at).max(self.now);
        self.stats.stray_bytes += bytes.len() as u64;
        let baud = self.host_bps;
        let mut k = 0;
        for &byte in bytes {
            self.up.push(Frame {
                start: bit_boundary(start, baud, 10 * k),
                baud,
                byte,
            });
            k += 1;
        }
        dur(bit_boundary(start, baud, 10 * k))
    }

    // ----- servo faults -----

    /// Switches slot `i` off now (EEPROM kept, everything else lost).
    pub fn power_off(&mut self, i: usize) {
        let now = dur(self.now);
        if let Some(s) = self.slots.get_mut(i) {
            s.servo.power_off(now);
            s.decoder.reset();
        }
    }

    /// Switches slot `i` on now: it is deaf for 65 ms, then listens at its EEPROM baud.
    pub fn power_on(&mut self, i: usize) {
        let now = dur(self.now);
        if let Some(s) = self.slots.get_mut(i) {
            s.servo.power_on(now);
            s.decoder.reset();
            s.rx = Receiver::new(s.servo.baud().bits_per_second(), self.now);
            s.busy_until = 0;
        }
    }

    /// Power-cycles slot `i` now.
    pub fn power_cycle(&mut self, i: usize) {
        self.power_off(i);
        self.power_on(i);
    }

    /// Power-cycles every module now.
    pub fn power_cycle_all(&mut self) {
        for i in 0..self.slots.len() {
            self.power_cycle(i);
        }
    }

    /// Unplugs slot `i` (signal and power share the cable): it goes dark.
    pub fn unplug(&mut self, i: usize) {
        self.power_off(i);
        if let Some(s) = self.slots.get_mut(i) {
            s.plugged = false;
        }
    }

    /// Plugs slot `i` back in: a power-up.
    pub fn plug(&mut self, i: usize) {
        if let Some(s) = self.slots.get_mut(i) {
            s.plugged = true;
        }
        self.power_on(i);
    }

    /// Applies a scheduled device fault now to every module with its ID, and returns how
    /// many it hit: [`DeviceFaultKind::Silent`] powers the module off (it answers nothing
    /// from now on), [`DeviceFaultKind::PowerCycle`] is a brown-out (runtime state lost,
    /// deaf for 65 ms). wCK modules have no error bits: [`DeviceFaultKind::Error`] hits
    /// nothing.
    pub fn apply_fault(&mut self, fault: &DeviceFault) -> usize {
        let slots: Vec<usize> = self
            .slots
            .iter()
            .enumerate()
            .filter(|(_, s)| s.servo.id().get() == fault.id)
            .map(|(i, _)| i)
            .collect();
        match fault.kind {
            DeviceFaultKind::Silent => slots.iter().for_each(|&i| self.power_off(i)),
            DeviceFaultKind::PowerCycle => slots.iter().for_each(|&i| self.power_cycle(i)),
            DeviceFaultKind::Error(_) => return 0,
        }
        slots.len()
    }

    /// Makes slot `i` answer every command twice, the second answer `gap` after the first
    /// one's last stop bit (a firmware or adapter fault); `None` cures it.
    pub fn set_answers_twice(&mut self, i: usize, gap: Option<Duration>) {
        if let Some(s) = self.slots.get_mut(i) {
            s.double = gap.map(ns);
        }
    }

    /// Whether slot `i` is plugged in.
    pub fn is_plugged(&self, i: usize) -> bool {
        self.slots.get(i).is_some_and(|s| s.plugged)
    }

    // ----- EEPROM persistence -----

    /// The EEPROMs of every slot.
    pub fn eeproms(&self) -> Vec<Eeprom> {
        self.slots.iter().map(|s| *s.servo.eeprom()).collect()
    }

    /// Saves every slot's EEPROM to a text file.
    pub fn save_eeproms(&self, path: &Path) -> Result<(), EepromFileError> {
        Eeprom::save(&self.eeproms(), path)
    }

    /// Loads EEPROMs from a file into the slots (in order; extra entries are ignored),
    /// then power-cycles the modules so they take effect.
    pub fn load_eeproms(&mut self, path: &Path) -> Result<(), EepromFileError> {
        let all = Eeprom::load(path)?;
        for (i, e) in all.into_iter().enumerate() {
            if let Some(s) = self.slots.get_mut(i) {
                s.servo.set_eeprom(e);
            }
        }
        self.power_cycle_all();
        Ok(())
    }
}

/// What a module's reply goes onto: the reply line, the counters and the reply faults.
struct Wire<'a> {
    up: &'a mut Line,
    stats: &'a mut BusStats,
    faults: &'a Faults,
    rng: &'a mut ChaCha8Rng,
}

impl Wire<'_> {
    /// Whether a fault of probability `p` happens (no draw at all when `p` is 0, so a
    /// seed's other faults stay where they were).
    fn chance(&mut self, p: f64) -> bool {
        p > 0.0 && self.rng.random_bool(p.min(1.0))
    }

    /// Puts `bytes` on the reply line from `start` (ns) at `baud`, back to back; returns
    /// when the last stop bit ends.
    fn send(&mut self, start: u64, baud: u32, bytes: &[u8]) -> u64 {
        let mut k = 0;
        for &byte in bytes {
            self.up.push(Frame {
                start: bit_boundary(start, baud, 10 * k),
                baud,
                byte,
            });
            k += 1;
        }
        bit_boundary(start, baud, 10 * k)
    }
}

/// Hands one received byte to a module: decode, act, schedule the reply on the up line.
/// Returns the module's new baud rate if it just changed it.
fn deliver(slot: &mut Slot, b: RxByte, wire: &mut Wire<'_>) -> Option<u32> {
    let stats = &mut *wire.stats;
    let t = dur(b.at);
    if !slot.plugged || !slot.servo.listens_at(t) || b.at < slot.busy_until {
        slot.decoder.reset();
        stats.ignored_bytes += 1;
        return None;
    }
    let Ok(cmd) = slot.decoder.push(b.byte)? else {
        stats.decode_errors += 1;
        return None;
    };
    stats.commands += 1;
    let tx_baud = slot.servo.baud().bits_per_second();
    let out = slot.servo.handle(&cmd, t);
    let mut busy_until = b.at + ns(out.busy);
    if let Some(answer) = out.answer {
        stats.replies += 1;
        let on_time = b.at + ns(answer.delay) + slot.skew;
        busy_until = busy_until.max(bit_boundary(on_time, tx_baud, 20));
        let faults = *wire.faults;
        let start = if wire.chance(faults.late_reply) {
            wire.stats.late_replies += 1;
            on_time + ns(faults.late_by)
        } else {
            on_time
        };
        let bytes = answer.bytes;
        let end = wire.send(start, tx_baud, &bytes);
        let double = match slot.double {
            Some(gap) => Some(gap),
            None => wire
                .chance(faults.double_reply)
                .then(|| ns(faults.double_gap)),
        };
        if let Some(gap) = double {
            wire.stats.doubled_replies += 1;
            wire.send(end + gap, tx_baud, &bytes);
        }
    }
    slot.busy_until = busy_until;
    out.new_baud.map(BaudRate::bits_per_second)
}
