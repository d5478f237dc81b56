//! Late replies (issue: a reply must never be credited to another request): a scripted
//! fake bus whose servos answer status reads after a delay, some of them 15-45 ms late,
//! on a virtual clock of its own (time moves only when the client waits).
#![allow(clippy::unwrap_used)]

use std::collections::VecDeque;
use std::time::{Duration, Instant};

use robobus::WaitMode;
use robobus::ops::Control;
use robobus::ops::wck::{WckPlan, run_steps};
use robobus::wck::{ScanOptions, WckBus, WckConfig};
use robobus_link::{ByteLink, LinkError};
use robobus_wck::{BaudRate, Command, ServoId};

/// Servo `id` stands at position `10 * id + 10` and answers a status read after
/// `delay(id)`; IDs without a delay are absent.
struct LateBus {
    delay: fn(u8) -> Option<Duration>,
    /// Reply bytes with the time they arrive.
    pending: VecDeque<(Instant, u8)>,
    /// The link's clock.
    now: Instant,
    /// How many more replies come with a stray byte 0.1 ms after their command (before
    /// any module can have answered: line noise).
    stray: u32,
}

impl LateBus {
    fn new(delay: fn(u8) -> Option<Duration>) -> Self {
        Self {
            delay,
            pending: VecDeque::new(),
            now: Instant::now(),
            stray: 0,
        }
    }
}

impl ByteLink for LateBus {
    fn write_all(&mut self, bytes: &[u8]) -> Result<(), LinkError> {
        // A status read: FF, (5 << 5) | id, 0, checksum.
        if let [0xFF, b1, _, _] = *bytes
            && b1 >> 5 == 5
        {
            let id = b1 & 0x1F;
            if let Some(d) = (self.delay)(id) {
                // On the wire, bytes arrive in the order of their times.
                let at = self.now + d;
                let i = self.pending.partition_point(|&(t, _)| t <= at);
                self.pending.insert(i, (at, 10 * id + 10));
                self.pending.insert(i, (at, 0)); // load 0
                if self.stray > 0 {
                    self.stray -= 1;
                    let noise = self.now + Duration::from_micros(100);
                    let i = self.pending.partition_point(|&(t, _)| t <= noise);
                    self.pending.insert(i, (noise, 0x55));
                }
            }
        }
        Ok(())
    }

    fn read_some(&mut self, buf: &mut [u8], deadline: Instant) -> Result<usize, LinkError> {
        loop {
            let now = self.now;
            let mut n = 0;
            while n < buf.len()
                && let Some(&(at, b)) = self.pending.front()
                && at <= now
            {
                buf[n] = b;
                n += 1;
                self.pending.pop_front();
            }
            if n > 0 {
                return Ok(n);
            }
            if now >= deadline {
                return Err(LinkError::Timeout {
                    received: 0,
                    expected: buf.len(),
                });
            }
            let next = self
                .pending
                .front()
                .map_or(deadline, |&(at, _)| at.min(deadline));
            self.now = next;
        }
    }

    fn discard_input(&mut self) -> Result<(), LinkError> {
        // Only what has arrived; a reply still on its way is not in any buffer yet.
        let now = self.now;
        self.pending.retain(|&(at, _)| at > now);
        Ok(())
    }

    fn set_baud(&mut self, _: u32) -> Result<(), LinkError> {
        Ok(())
    }

    fn baud(&self) -> Option<u32> {
        Some(115_200)
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

/// Both ways of waiting for a reply: every test here must come out the same in each.
const MODES: [WaitMode; 2] = [WaitMode::Sleep, WaitMode::SPIN];

fn status_of(ids: std::ops::RangeInclusive<u8>) -> WckPlan {
    let mut plan = WckPlan::default();
    for id in ids {
        plan.push(Command::StatusRead {
            id: ServoId::new(id).unwrap(),
        });
    }
    plan
}

/// Each servo's reported position is its own (or it failed); never another's. Returns
/// the servos that answered.
fn assert_no_reply_credited_elsewhere(
    link: &LateBus,
    ids: std::ops::RangeInclusive<u8>,
) -> Vec<u8> {
    let mut answered = MODES.map(|wait| {
        let fresh = LateBus::new(link.delay);
        let start = fresh.now;
        let mut bus = WckBus::new(fresh, BaudRate::B115200)
            .unwrap()
            .with_config(WckConfig {
                margin: Duration::from_millis(10),
                wait,
                ..WckConfig::default()
            });
        let ok = credited(&mut bus, ids.clone());
        (ok, bus.now().saturating_duration_since(start))
    });
    let [(sleep, took_sleep), (spin, took_spin)] = &mut answered;
    assert_eq!(
        sleep, spin,
        "the servos that answered, sleeping and spinning"
    );
    assert_eq!(took_sleep, took_spin, "time taken on the link's clock");
    std::mem::take(sleep)
}

fn credited(bus: &mut WckBus<LateBus>, ids: std::ops::RangeInclusive<u8>) -> Vec<u8> {
    let report = run_steps(bus, "status", &status_of(ids), &mut Control::none()).unwrap();
    let mut ok = Vec::new();
    for r in &report.results {
        let id = r.id.cell().parse::<u8>().unwrap();
        if let Some(v) = r.value() {
            ok.push(id);
            assert_eq!(
                v.get("position").unwrap().cell(),
                (10 * id + 10).to_string(),
                "servo {id} was credited with another servo's reply: {report:?}"
            );
        }
    }
    ok
}

#[test]
fn a_reply_15_to_45_ms_late_is_never_credited_to_the_next_servo() {
    // Servo 2 answers 30 ms late (its deadline is about 11 ms), servo 4 45 ms late,
    // servo 1 15 ms late; the others at once.
    let link = LateBus::new(|id| match id {
        1 => Some(Duration::from_millis(15)),
        2 => Some(Duration::from_millis(30)),
        4 => Some(Duration::from_millis(45)),
        0..=5 => Some(Duration::from_micros(1500)),
        _ => None,
    });
    let ok = assert_no_reply_credited_elsewhere(&link, 0..=5);
    // Servos 1, 2 and 4 answer every attempt after its deadline: each reply lands in the
    // late window and is dropped, so they fail; the punctual ones answer.
    assert_eq!(ok, [0, 3, 5]);
}

#[test]
fn a_servo_18_ms_late_every_time_fails_and_none_of_its_replies_reaches_the_next() {
    // Servo 0 answers 18 ms late (deadline about 11.5 ms): each reply comes within the late
    // window of its attempt, which the retry waits out. Servos 1 and 2 answer 6 and 9 ms
    // after they are asked, so a stale reply of servo 0 would come before theirs.
    let link = LateBus::new(|id| match id {
        0 => Some(Duration::from_millis(18)),
        1 => Some(Duration::from_millis(6)),
        2 => Some(Duration::from_millis(9)),
        _ => None,
    });
    // On this clock every attempt's reply lands in the late window of the attempt before
    // and is dropped, so servo 0 fails; servos 1 and 2 get their own replies.
    assert_eq!(assert_no_reply_credited_elsewhere(&link, 0..=2), [1, 2]);
}

/// Scans `ids` (status reads only) and returns the IDs found, with the time it took on
/// the link's clock.
/// Both wait modes must find the same IDs in the same time.
fn scan_late(link: &LateBus, ids: std::ops::RangeInclusive<u8>) -> (Vec<u8>, Duration) {
    let [sleep, spin] = MODES.map(|wait| scan_late_in(LateBus::new(link.delay), ids.clone(), wait));
    assert_eq!(
        sleep, spin,
        "IDs found and time taken, sleeping and spinning"
    );
    sleep
}

fn scan_late_in(
    link: LateBus,
    ids: std::ops::RangeInclusive<u8>,
    wait: WaitMode,
) -> (Vec<u8>, Duration) {
    let mut bus = WckBus::new(link, BaudRate::B115200)
        .unwrap()
        .with_config(WckConfig {
            wait,
            ..WckConfig::default()
        });
    let start = bus.now();
    let options = ScanOptions {
        check_duplicates: false,
        ..ScanOptions::default().ids(ids)
    };
    let report = bus.scan(&options, |_| {}).unwrap();
    let found = report.found.iter().map(|f| f.id.get()).collect();
    (found, bus.now().saturating_duration_since(start))
}

#[test]
fn a_scan_never_takes_a_late_reply_for_the_next_id() {
    // Servo 1 answers 30 ms after it is asked, past its deadline (11.5 ms), while ID 2
    // (absent) is probed: that reply must not make a servo 2. Servo 3 answers 1.5 ms late,
    // within its deadline, right after the silent ID 2.
    let link = LateBus::new(|id| match id {
        1 => Some(Duration::from_millis(30)),
        3 => Some(Duration::from_micros(1500)),
        _ => None,
    });
    let (found, _) = scan_late(&link, 0..=4);
    assert_eq!(found, [3]);
    // Every probe of servo 1's is answered 30 ms late: the second probe of ID 1 and both of
    // ID 2 come within its replies' late windows.
    let link = LateBus::new(|id| match id {
        1 => Some(Duration::from_millis(30)),
        _ => None,
    });
    assert_eq!(scan_late(&link, 0..=4).0, Vec::<u8>::new());
}

#[test]
fn a_scan_of_silent_ids_costs_only_their_reply_waits() {
    // 31 IDs, 2 probes each, each waiting 11.53 ms (1.53 ms modelled + 10 ms margin): no
    // late window between them.
    let (found, took) = scan_late(&LateBus::new(|_| None), 0..=30);
    assert!(found.is_empty());
    assert_eq!(took, 62 * Duration::from_nanos(11_527_433));
    // Two servos: each found after silent IDs waits out one late window (50 ms) and is
    // asked again; that reply is credited once the line stayed quiet for the guard time
    // (one byte time plus the turnaround spread) after it.
    let link = LateBus::new(|id| match id {
        5 | 20 => Some(Duration::from_micros(1500)),
        _ => None,
    });
    let (found, took) = scan_late(&link, 0..=30);
    assert_eq!(found, [5, 20]);
    let wait = Duration::from_nanos(11_527_433);
    let reply = Duration::from_micros(1500);
    assert_eq!(
        took,
        58 * wait
            + 2 * (wait
                + Duration::from_millis(50)
                + reply
                + robobus::wck::reply_guard(BaudRate::B115200))
    );
}

/// A servo whose answers to every status read of a probe come with a stray byte before
/// them (line noise right after the command: the attempt is unattributable, its bytes are
/// not credited) is never reported absent: it answered. It is probed again and found
/// once an answer is clean.
#[test]
fn a_servo_whose_probes_come_with_stray_bytes_is_probed_again_never_absent() {
    for wait in MODES {
        let mut link = LateBus::new(|id| (id == 3).then(|| Duration::from_micros(1500)));
        link.stray = 4;
        let (found, _) = scan_late_in(link, 2..=4, wait);
        assert_eq!(found, [3], "{wait:?}");
    }
}
