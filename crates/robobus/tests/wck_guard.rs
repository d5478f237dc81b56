//! The quiet time after a wCK reply ([`WckConfig::guard`]), on a scripted bus with a
//! virtual clock of its own (time moves only when the client waits): bytes that follow a
//! reply within the wire's quiet time (one byte time plus the modules' turnaround spread)
//! fail that reading; a byte that comes later, during the next transaction, fails that
//! transaction's attempt and only it, and is never credited.
#![allow(clippy::unwrap_used)]

use std::collections::VecDeque;
use std::time::{Duration, Instant};

use robobus::WaitMode;
use robobus::wck::{TURNAROUND_SPREAD, WckBus, WckConfig, WckError, reply_guard};
use robobus_link::{ByteLink, LinkError};
use robobus_wck::{BaudRate, Command, ServoId, decode_packet, timing};

const BAUD: BaudRate = BaudRate::B115200;

/// Servo `id` (1..=9) stands at position `10 * id + 10`, load 0, and answers a status read
/// after exactly the manual's turnaround; `after` adds bytes after one servo's reply.
struct Scripted {
    now: Instant,
    /// Bytes with the instant their stop bit ends, in time order.
    pending: VecDeque<(Instant, u8)>,
    /// Once, after the reply of servo `.0`: byte `.2`, complete `.1` after the reply's
    /// last byte.
    after: Vec<(u8, Duration, u8)>,
    /// The reply bytes of the servo, if not its honest status.
    reply: fn(u8) -> [u8; 2],
}

fn honest(id: u8) -> [u8; 2] {
    [0, 10 * id + 10]
}

impl Scripted {
    fn new(after: Vec<(u8, Duration, u8)>) -> Self {
        Self {
            now: Instant::now(),
            pending: VecDeque::new(),
            after,
            reply: honest,
        }
    }

    fn schedule(&mut self, at: Instant, byte: u8) {
        let i = self.pending.partition_point(|&(t, _)| t <= at);
        self.pending.insert(i, (at, byte));
    }
}

impl ByteLink for Scripted {
    fn write_all(&mut self, bytes: &[u8]) -> Result<(), LinkError> {
        let Ok(Command::StatusRead { id }) = decode_packet(bytes) else {
            return Ok(());
        };
        let id = id.get();
        if !(1..=9).contains(&id) {
            return Ok(());
        }
        let command = Command::StatusRead {
            id: ServoId::new(id).unwrap(),
        };
        let byte = timing::byte_time(BAUD);
        let first = self.now + timing::earliest_reply(&command, BAUD) + byte;
        let reply = (self.reply)(id);
        self.schedule(first, reply[0]);
        self.schedule(first + byte, reply[1]);
        let last = first + byte;
        let (extra, rest): (Vec<_>, Vec<_>) = self.after.iter().partition(|(i, ..)| *i == id);
        self.after = rest;
        for (_, after, b) in extra {
            self.schedule(last + after, b);
        }
        Ok(())
    }

    fn read_some(&mut self, buf: &mut [u8], deadline: Instant) -> Result<usize, LinkError> {
        loop {
            let mut n = 0;
            while n < buf.len()
                && let Some(&(at, b)) = self.pending.front()
                && at <= self.now
            {
                buf[n] = b;
                n += 1;
                self.pending.pop_front();
            }
            if n > 0 {
                return Ok(n);
            }
            if self.now >= deadline {
                return Err(LinkError::Timeout {
                    received: 0,
                    expected: buf.len(),
                });
            }
            self.now = self
                .pending
                .front()
                .map_or(deadline, |&(at, _)| at.min(deadline));
        }
    }

    fn discard_input(&mut self) -> Result<(), LinkError> {
        let now = self.now;
        self.pending.retain(|&(at, _)| at > now);
        Ok(())
    }

    fn set_baud(&mut self, _: u32) -> Result<(), LinkError> {
        Ok(())
    }

    fn baud(&self) -> Option<u32> {
        Some(BAUD.bits_per_second())
    }

    fn now(&self) -> Instant {
        self.now
    }

    fn sleep_until(&mut self, deadline: Instant) {
        self.now = self.now.max(deadline);
    }

    fn virtual_time(&self) -> bool {
        true
    }
}

fn bus(link: Scripted, retries: u32, guard: Option<Duration>, wait: WaitMode) -> WckBus<Scripted> {
    WckBus::new(link, BAUD).unwrap().with_config(WckConfig {
        retries,
        guard,
        wait,
        ..WckConfig::default()
    })
}

/// Status reads of servos 1, 2, 3: each one's position, or the error.
#[allow(clippy::result_large_err)] // the errors are compared as they are
fn read_three(bus: &mut WckBus<Scripted>) -> Vec<Result<u8, WckError>> {
    (1..=3u8)
        .map(|id| {
            bus.servo(ServoId::new(id).unwrap())
                .status()
                .map(|s| s.position.get())
        })
        .collect()
}

fn is_unattributable(r: &Result<u8, WckError>, text: &str) -> bool {
    matches!(r, Err(e @ WckError::Unattributable { .. }) if e.to_string().contains(text))
}

const MODES: [WaitMode; 2] = [WaitMode::Sleep, WaitMode::SPIN];

/// The default quiet time is the wire's, per baud rate: one byte time plus the modules'
/// turnaround spread (3 µs), not a whole turnaround.
#[test]
fn the_default_guard_is_one_byte_time_plus_the_turnaround_spread() {
    assert_eq!(TURNAROUND_SPREAD, Duration::from_micros(3));
    let cases = [
        (BaudRate::B4800, 2_083_333 + 3_000),
        (BaudRate::B9600, 1_041_667 + 3_000),
        (BaudRate::B115200, 86_806 + 3_000),
        (BaudRate::B921600, 10_851 + 3_000),
    ];
    for (baud, ns) in cases {
        assert_eq!(reply_guard(baud), Duration::from_nanos(ns), "{baud:?}");
        assert_eq!(WckConfig::default().guard_at(baud), reply_guard(baud));
    }
    let fixed = WckConfig {
        guard: Some(Duration::from_millis(1)),
        ..WckConfig::default()
    };
    assert_eq!(fixed.guard_at(BaudRate::B921600), Duration::from_millis(1));
}

/// A byte 1 µs before the quiet time after servo 1's reply ends fails servo 1's reading;
/// 1 µs after it, servo 1's reply is credited and the byte, which came before any module
/// can have answered servo 2's command, fails servo 2's attempt and only it.
#[test]
fn a_byte_just_inside_the_guard_fails_that_reading_one_just_after_fails_only_the_next_attempt() {
    let guard = reply_guard(BAUD);
    let mut inside = bus(
        Scripted::new(vec![(
            1,
            guard.saturating_sub(Duration::from_micros(1)),
            0x33,
        )]),
        0,
        None,
        WaitMode::Sleep,
    );
    let got = read_three(&mut inside);
    assert!(
        is_unattributable(&got[0], "more than one answer"),
        "{got:?}"
    );
    assert_eq!(
        (got[1].as_ref().ok(), got[2].as_ref().ok()),
        (Some(&30), Some(&40))
    );

    let mut after = bus(
        Scripted::new(vec![(1, guard + Duration::from_micros(1), 0x33)]),
        0,
        None,
        WaitMode::Sleep,
    );
    let got = read_three(&mut after);
    assert_eq!(got[0].as_ref().ok(), Some(&20), "{got:?}");
    assert!(
        is_unattributable(&got[1], "before any module can have answered"),
        "{got:?}"
    );
    assert_eq!(got[2].as_ref().ok(), Some(&40), "{got:?}");
    assert_eq!(after.stats().unattributable, 1);
}

/// Servo 1 answers twice, its second answer 0.5 ms after the first (within a
/// turnaround): the second answer arrives while servo 2's command is on its way, before
/// servo 2 can have answered. Servo 1's reading is its own; servo 2's attempt fails and
/// is asked again (its own value then), servo 3's is untouched. Without retries servo
/// 2's reading fails, and only it. The same sleeping and spinning.
#[test]
fn a_second_answer_during_the_next_transaction_fails_that_attempt_only_and_is_never_credited() {
    for wait in MODES {
        let doubled = || {
            Scripted::new(vec![
                (
                    1,
                    Duration::from_micros(500).saturating_sub(timing::byte_time(BAUD)),
                    0,
                ),
                (1, Duration::from_micros(500), 20),
            ])
        };
        let mut once = bus(doubled(), 0, None, wait);
        let got = read_three(&mut once);
        assert_eq!(got[0].as_ref().ok(), Some(&20), "{wait}: {got:?}");
        assert!(
            is_unattributable(&got[1], "before any module can have answered"),
            "{wait}: {got:?}"
        );
        assert_eq!(got[2].as_ref().ok(), Some(&40), "{wait}: {got:?}");

        let mut retried = bus(doubled(), 3, None, wait);
        let got: Vec<_> = read_three(&mut retried)
            .into_iter()
            .map(Result::ok)
            .collect();
        assert_eq!(got, [Some(20), Some(30), Some(40)], "{wait}");
        let stats = retried.stats();
        assert_eq!((stats.unattributable, stats.retries), (1, 1), "{wait}");
    }
}

/// The first byte of servo 1's reply duplicated by the link (`0 0 20`): the first two
/// bytes read as position 0. The default guard catches the third byte one byte time
/// later and the read is asked again; with the guard off, position 0 is credited.
#[test]
fn a_duplicated_byte_is_caught_by_the_guard_and_credited_without_it() {
    for wait in MODES {
        let link = || {
            let mut s = Scripted::new(vec![(1, timing::byte_time(BAUD), 20)]);
            s.reply = |id| if id == 1 { [0, 0] } else { honest(id) };
            s
        };
        let got = read_three(&mut bus(link(), 0, None, wait));
        assert!(
            is_unattributable(&got[0], "more than one answer"),
            "{wait}: {got:?}"
        );
        let got = read_three(&mut bus(link(), 0, Some(Duration::ZERO), wait));
        assert_eq!(got[0].as_ref().ok(), Some(&0), "{wait}: credited {got:?}");
    }
}

/// A second module at servo 1's ID answers within the turnaround spread: the overlapping
/// answers reach the host as a plausible but wrong position (44) and a last garbled byte
/// complete one spread after the first answer's last byte. The default guard fails the
/// reading (it names the bytes); without it position 44 is credited.
#[test]
fn an_impostor_within_the_turnaround_spread_is_caught_by_the_guard() {
    for wait in MODES {
        let link = || {
            let mut s = Scripted::new(vec![(1, TURNAROUND_SPREAD, 0xE0)]);
            s.reply = |id| if id == 1 { [0, 44] } else { honest(id) };
            s
        };
        let got = read_three(&mut bus(link(), 0, None, wait));
        assert!(is_unattributable(&got[0], "00 2C E0"), "{wait}: {got:?}");
        assert_eq!(got[1].as_ref().ok(), Some(&30), "{wait}: {got:?}");
        let got = read_three(&mut bus(link(), 0, Some(Duration::ZERO), wait));
        assert_eq!(got[0].as_ref().ok(), Some(&44), "{wait}: {got:?}");
    }
}
