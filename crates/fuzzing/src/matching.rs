//! The client's reply matching: scripted devices on a virtual clock answer honestly, late,
//! twice or not at all, among stray bytes and foreign frames the script chooses; every
//! value a read returns must be the honest answer to that read.

use std::collections::VecDeque;
use std::time::{Duration, Instant};

use robobus::wck::{WckBus, WckConfig};
use robobus::whj::{JointBus, JointBusConfig};
use robobus_link::{ByteLink, FrameLink, FrameLinkError, IdFilter, LinkError, Received};
use robobus_wck::{BaudRate, Command, ServoId, decode_packet, timing};
use robobus_whj::{CanFrame, JointId, RegisterAddr, Reply, Request};

use crate::{Checked, ensure};

/// The script: bytes of the fuzz input, then zeros.
struct Script(VecDeque<u8>);

impl Script {
    fn new(data: &[u8]) -> Self {
        Self(data.iter().copied().collect())
    }
    fn byte(&mut self) -> u8 {
        self.0.pop_front().unwrap_or(0)
    }
}

/// A virtual clock: an instant and what is due when.
struct Clock<T> {
    base: Instant,
    now: Duration,
    due: VecDeque<(Duration, T)>,
}

impl<T> Clock<T> {
    fn new() -> Self {
        Self {
            base: Instant::now(),
            now: Duration::ZERO,
            due: VecDeque::new(),
        }
    }
    fn at(&self, t: Instant) -> Duration {
        t.saturating_duration_since(self.base)
    }
    fn now(&self) -> Instant {
        self.base + self.now
    }
    fn schedule(&mut self, at: Duration, item: T) {
        let i = self
            .due
            .iter()
            .position(|(t, _)| *t > at)
            .unwrap_or(self.due.len());
        self.due.insert(i, (at, item));
    }
    /// Moves the clock to `t` (never back).
    fn advance_to(&mut self, t: Instant) {
        self.now = self.now.max(self.at(t));
    }
    /// The first item due by `deadline` (the clock moves to it), else the clock moves to
    /// the deadline.
    fn next_by(&mut self, deadline: Instant) -> Option<T> {
        let d = self.at(deadline);
        match self.due.front() {
            Some(&(t, _)) if t <= d => {
                self.now = self.now.max(t);
                self.due.pop_front().map(|(_, x)| x)
            }
            _ => {
                self.advance_to(deadline);
                None
            }
        }
    }
}

// ----- wCK -----

/// The honest status of servo `id`: load and position.
fn wck_honest(id: u8) -> [u8; 2] {
    [id.wrapping_mul(7) % 200, 20 + id * 3]
}

struct WckDevice {
    script: Script,
    clock: Clock<u8>,
    baud: BaudRate,
}

impl ByteLink for WckDevice {
    fn write_all(&mut self, bytes: &[u8]) -> Result<(), LinkError> {
        let Ok(command) = decode_packet(bytes) else {
            return Ok(());
        };
        let now = self.clock.now;
        let earliest = now + timing::earliest_reply(&command, self.baud);
        let byte_time = timing::wire_time(1, self.baud);
        // Stray bytes that arrive before any module can have answered.
        for _ in 0..(self.script.byte() % 4) {
            let span = earliest.saturating_sub(now).as_nanos().max(1);
            let at = now
                + Duration::from_nanos(
                    u64::try_from(u128::from(self.script.byte()) * span / 256).unwrap_or(0),
                );
            let value = self.script.byte();
            self.clock.schedule(at, value);
        }
        let Command::StatusRead { id } = command else {
            return Ok(());
        };
        let fate = self.script.byte();
        let reply = wck_honest(id.get());
        let start = earliest + byte_time * u32::from(fate >> 4);
        match fate & 3 {
            // On time (late within the deadline by up to 15 byte times).
            0 | 1 => {
                // Its first byte duplicated on the wire (the reply shifts by one byte).
                let bytes: &[u8] = if fate & 8 != 0 {
                    &[reply[0], reply[0], reply[1]]
                } else {
                    &reply
                };
                for (k, &b) in bytes.iter().enumerate() {
                    self.clock
                        .schedule(start + byte_time * u32::try_from(k).unwrap_or(0), b);
                }
                if fate & 4 != 0 {
                    // A duplicated byte right after it.
                    let after = u32::try_from(bytes.len()).unwrap_or(2);
                    self.clock.schedule(start + byte_time * after, reply[1]);
                }
            }
            // Silent.
            2 => {}
            // Twice: again half a millisecond later.
            _ => {
                for rep in 0..2u32 {
                    for (k, &b) in reply.iter().enumerate() {
                        let at = start
                            + Duration::from_micros(500) * rep
                            + byte_time * u32::try_from(k).unwrap_or(0);
                        self.clock.schedule(at, b);
                    }
                }
            }
        }
        Ok(())
    }

    fn read_some(&mut self, buf: &mut [u8], deadline: Instant) -> Result<usize, LinkError> {
        let mut n = 0;
        if let Some(b) = self.clock.next_by(deadline) {
            buf[0] = b;
            n = 1;
            while n < buf.len()
                && let Some(b) = self.clock.next_by(self.clock.now())
            {
                buf[n] = b;
                n += 1;
            }
        }
        if n == 0 {
            return Err(LinkError::Timeout {
                received: 0,
                expected: buf.len(),
            });
        }
        Ok(n)
    }

    fn discard_input(&mut self) -> Result<(), LinkError> {
        let now = self.clock.now;
        self.clock.due.retain(|(t, _)| *t > now);
        Ok(())
    }

    fn set_baud(&mut self, _baud: u32) -> Result<(), LinkError> {
        Ok(())
    }

    fn baud(&self) -> Option<u32> {
        Some(self.baud.bits_per_second())
    }

    fn now(&self) -> Instant {
        self.clock.now()
    }

    fn sleep_until(&mut self, deadline: Instant) {
        self.clock.advance_to(deadline);
    }
}

/// wCK status reads through a scripted bus: stray bytes before the earliest reply
/// instant, replies on time, silent, shifted by a duplicated byte, followed by one, or
/// doubled; every status a read returns
/// is the honest one of the servo asked.
pub fn wck_matching(data: &[u8]) -> Checked {
    wck_matching_with(data, WckConfig::default())
}

/// [`wck_matching`] with a client configuration (a test turns the guards off to show the
/// check catches what they prevent).
pub fn wck_matching_with(data: &[u8], config: WckConfig) -> Checked {
    let data = data.get(..data.len().min(4096)).unwrap_or_default();
    // The reads to make come from the front of the input, the device's script after it.
    let (picks, script) = data.split_at(data.len().min(8));
    let device = WckDevice {
        script: Script::new(script),
        clock: Clock::new(),
        baud: BaudRate::B115200,
    };
    let Ok(bus) = WckBus::new(device, BaudRate::B115200) else {
        return Ok(());
    };
    let mut bus = bus.with_config(config);
    for &pick in picks {
        let Ok(id) = ServoId::new(pick % 31) else {
            continue;
        };
        if let Ok(st) = bus.servo(id).status() {
            let got = [st.load.get(), st.position.get()];
            let want = wck_honest(id.get());
            ensure!(
                got == want,
                "servo {} read as load {} position {}, but it answered {want:?}",
                id.get(),
                got[0],
                got[1]
            );
        }
    }
    Ok(())
}

// ----- WHJ -----

/// The honest value of register `addr` of joint `j`.
fn whj_honest(j: u8, addr: u8) -> u16 {
    (u16::from(j) << 8) | u16::from(addr)
}

struct WhjDevice {
    script: Script,
    clock: Clock<CanFrame>,
}

impl WhjDevice {
    fn foreign(&mut self, joint: JointId, addr: RegisterAddr) -> Option<CanFrame> {
        let kind = self.script.byte();
        let value = u16::from_le_bytes([self.script.byte(), self.script.byte()]);
        // Joints and registers the reads never ask for (they ask joints 1..=7, registers
        // 0x10..=0x1F): such a frame cannot answer any of them, whenever it comes.
        let other_joint = JointId::new(8 + kind % 23).ok()?;
        let other_addr = RegisterAddr::new(0x20 + (kind >> 3) % 16).ok()?;
        let words = |v: u16| robobus_whj::Words::from_slice(&[v]).ok();
        Some(match kind % 4 {
            // Another joint's answer for this register.
            0 => Reply::Read {
                joint: other_joint,
                addr,
                words: words(value)?,
            }
            .to_frame(),
            // This joint's answer for another register.
            1 => Reply::Read {
                joint,
                addr: other_addr,
                words: words(value)?,
            }
            .to_frame(),
            // This joint's write acknowledgement for this register.
            2 => Reply::WriteAck {
                joint,
                addr,
                status: robobus_whj::WriteStatus::Ok,
            }
            .to_frame(),
            // Another joint's answer under a status identifier.
            _ => {
                let mut data = [0u8; 16];
                data[..2].copy_from_slice(&value.to_le_bytes());
                CanFrame::new_fd(
                    CanFrame::standard_id(0x700 + u16::from(joint.get())).ok()?,
                    &data,
                )
                .ok()?
            }
        })
    }
}

impl FrameLink for WhjDevice {
    fn send(&mut self, frame: &CanFrame) -> Result<(), FrameLinkError> {
        let Ok(Request::Read { joint, range }) = Request::from_frame(frame) else {
            return Ok(());
        };
        let now = self.clock.now;
        let addr = range.start();
        for _ in 0..(self.script.byte() % 4) {
            let at = now + Duration::from_micros(u64::from(self.script.byte()) * 40);
            if let Some(f) = self.foreign(joint, addr) {
                self.clock.schedule(at, f);
            }
        }
        let fate = self.script.byte();
        let values: Vec<u16> = (0..range.count())
            .map(|k| whj_honest(joint.get(), addr.get().wrapping_add(k)))
            .collect();
        let Ok(words) = robobus_whj::Words::from_slice(&values) else {
            return Ok(());
        };
        let honest = Reply::Read { joint, addr, words }.to_frame();
        let delay = Duration::from_micros(50 + u64::from(fate >> 3) * 20);
        match fate & 3 {
            0 | 1 => {
                self.clock.schedule(now + delay, honest);
                if fate & 0x80 != 0 {
                    // A second joint at this ID answers 20 µs earlier with its own value.
                    let other = values.iter().map(|v| v ^ 0x5A5A).collect::<Vec<_>>();
                    if let Ok(words) = robobus_whj::Words::from_slice(&other) {
                        let impostor = Reply::Read { joint, addr, words }.to_frame();
                        let at = (now + delay).saturating_sub(Duration::from_micros(20));
                        self.clock.schedule(at, impostor);
                    }
                }
            }
            2 => {}
            // Late: past the reply timeout, among the next requests' replies.
            _ => self
                .clock
                .schedule(now + delay + Duration::from_millis(25), honest),
        }
        if fate & 4 != 0 {
            // Twice, the same answer.
            self.clock
                .schedule(now + delay + Duration::from_micros(200), honest);
        }
        Ok(())
    }

    fn recv(&mut self, deadline: Instant) -> Result<Received, FrameLinkError> {
        self.clock
            .next_by(deadline)
            .map(|frame| Received {
                frame,
                timestamp: None,
            })
            .ok_or(FrameLinkError::Timeout)
    }

    fn set_filters(&mut self, _filters: &[IdFilter]) -> Result<(), FrameLinkError> {
        Ok(())
    }

    fn now(&self) -> Instant {
        self.clock.now()
    }

    fn sleep_until(&mut self, deadline: Instant) {
        self.clock.advance_to(deadline);
    }

    fn virtual_time(&self) -> bool {
        true
    }
}

/// WHJ register reads through a scripted bus: other joints' answers, answers for other
/// registers, acknowledgements and status frames around each request, honest replies on
/// time, twice, late or never, and a second joint at the same ID answering just before
/// the honest one; every value a read returns is the honest one.
pub fn whj_matching(data: &[u8]) -> Checked {
    whj_matching_with(data, JointBusConfig::default())
}

/// [`whj_matching`] with a client configuration.
pub fn whj_matching_with(data: &[u8], config: JointBusConfig) -> Checked {
    let data = data.get(..data.len().min(4096)).unwrap_or_default();
    // The reads to make come from the front of the input, the device's script after it.
    let (picks, script) = data.split_at(data.len().min(8));
    let device = WhjDevice {
        script: Script::new(script),
        clock: Clock::new(),
    };
    let Ok(bus) = JointBus::open_with(device, config) else {
        return Ok(());
    };
    for &pick in picks {
        let Ok(j) = JointId::new(pick % 7 + 1) else {
            continue;
        };
        let Ok(addr) = RegisterAddr::new(0x10 + (pick >> 3) % 16) else {
            continue;
        };
        if let Ok(words) = bus.joint_unchecked(j).read_words(addr, 1) {
            let want = whj_honest(j.get(), addr.get());
            ensure!(
                words == [want],
                "joint {} register {:#04X} read as {words:?}, but it answered {want:#06X}",
                j.get(),
                addr.get()
            );
        }
    }
    Ok(())
}
