//! The WHJ reply fault suite: replies that come twice (the same or a different answer),
//! replies that come late, in a later request's slot, and replies with implausible values.
//! Each is injected into 1 % of the replies; 10,000 status reads of two joints give no wrong
//! value, with and without read verification. A read may fail (and is then counted by its
//! kind); it never returns a value the joint asked did not send in answer to that request.
//! On the simulator's virtual clock, so the seeded faults give the same counts on every run.

#![allow(clippy::unwrap_used, clippy::panic)]

use crate::whj_common;

use std::collections::{BTreeMap, VecDeque};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use robobus::ErrorKind;
use robobus::WaitMode;
use robobus::ops::whj::joint_status;
use robobus::whj::{JointBus, JointBusConfig};
use robobus_link::{FrameLink, FrameLinkError, IdFilter, Received};
use robobus_sim::whj::{JointConfig, WhjModel};
use robobus_whj::timing::{BitRates, frame_duration};
use robobus_whj::{CanFrame, JointId};
use whj_common::{configs, sim_link, virtual_config};

/// Which faults the link injects, each into this share of the replies.
#[derive(Clone, Copy)]
struct Faults {
    /// Two answers, the second an arbitration loser's (one frame after the first, plus
    /// the link's [`FrameLink::reply_allowance`]): half the time the same frame twice,
    /// half the time the other joint's answer under this joint's ID first (two joints at
    /// one ID).
    doubled: f64,
    /// The reply is held back and arrives after the next or the one after next request.
    wrong_slot: f64,
    /// A status reply's position becomes `0x7FFF_FFFF` (214748.3647°).
    implausible: f64,
}

#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
struct Injected {
    doubled_same: u32,
    doubled_other: u32,
    wrong_slot: u32,
    implausible: u32,
}

/// A frame link that injects [`Faults`] into the frames the host receives.
struct ReplyFaults<L> {
    inner: L,
    faults: Faults,
    rng: u64,
    /// Frames to deliver at an instant of the link's clock.
    due: VecDeque<(Instant, Received)>,
    /// Held frames, each with the number of sends still to pass before it is delivered.
    held: Vec<(u32, Received)>,
    /// The last status payload of each joint (CAN ID 0x700 + ID), for a different answer.
    last_status: BTreeMap<u32, Vec<u8>>,
    injected: Arc<Mutex<Injected>>,
}

impl<L: FrameLink> ReplyFaults<L> {
    fn new(inner: L, faults: Faults, seed: u64, injected: Arc<Mutex<Injected>>) -> Self {
        Self {
            inner,
            faults,
            rng: seed | 1,
            due: VecDeque::new(),
            held: Vec::new(),
            last_status: BTreeMap::new(),
            injected,
        }
    }

    /// A uniform number in [0, 1) (xorshift64*).
    fn uniform(&mut self) -> f64 {
        self.rng ^= self.rng >> 12;
        self.rng ^= self.rng << 25;
        self.rng ^= self.rng >> 27;
        let x = self.rng.wrapping_mul(0x2545_F491_4F6C_DD1D);
        (x >> 11) as f64 / (1u64 << 53) as f64
    }

    fn chance(&mut self, p: f64) -> bool {
        p > 0.0 && self.uniform() < p
    }

    fn frame_with(id: u32, data: &[u8]) -> CanFrame {
        CanFrame::new_fd(
            CanFrame::standard_id(u16::try_from(id).unwrap()).unwrap(),
            data,
        )
        .unwrap()
    }

    /// The faults for one received frame: what to deliver now, if anything.
    fn mangle(&mut self, r: Received) -> Option<Received> {
        let id = r.frame.raw_id();
        let status = (0x701..=0x71E).contains(&id) && r.frame.data().len() == 16;
        let mut r = r;
        if status && self.chance(self.faults.implausible) {
            let mut data = r.frame.data().to_vec();
            data[8..12].copy_from_slice(&0x7FFF_FFFF_i32.to_le_bytes());
            r.frame = Self::frame_with(id, &data);
            self.injected.lock().unwrap().implausible += 1;
        }
        if status {
            self.last_status.insert(id, r.frame.data().to_vec());
        }
        if self.chance(self.faults.wrong_slot) {
            let after = if self.uniform() < 0.5 { 1 } else { 2 };
            self.held.push((after, r));
            self.injected.lock().unwrap().wrong_slot += 1;
            return None;
        }
        if self.chance(self.faults.doubled) {
            // The second answer is an arbitration loser's: it follows the first on the
            // wire at once (the intermission, then a frame as long), and the link may
            // deliver it that much later again.
            let at = self.inner.now()
                + frame_duration(&r.frame, BitRates::WHJ)
                + self.inner.reply_allowance();
            let other = self
                .last_status
                .iter()
                .find(|&(&k, _)| k != id)
                .map(|(_, d)| d.clone());
            match other {
                Some(data) if status && self.uniform() < 0.5 => {
                    // The other joint's answer comes first, this joint's one frame later.
                    self.injected.lock().unwrap().doubled_other += 1;
                    let first = Received {
                        frame: Self::frame_with(id, &data),
                        timestamp: r.timestamp,
                    };
                    self.due.push_back((at, r));
                    return Some(first);
                }
                _ => {
                    self.injected.lock().unwrap().doubled_same += 1;
                    self.due.push_back((at, r));
                }
            }
        }
        Some(r)
    }
}

impl<L: FrameLink> FrameLink for ReplyFaults<L> {
    fn send(&mut self, frame: &CanFrame) -> Result<(), FrameLinkError> {
        self.inner.send(frame)?;
        // Held replies whose slot has come arrive just after this request, before its
        // own reply can.
        let at = self.inner.now() + Duration::from_micros(20);
        let mut keep = Vec::new();
        for (left, r) in self.held.drain(..) {
            if left <= 1 {
                self.due.push_back((at, r));
            } else {
                keep.push((left - 1, r));
            }
        }
        self.held = keep;
        Ok(())
    }

    fn recv(&mut self, deadline: Instant) -> Result<Received, FrameLinkError> {
        loop {
            let now = self.inner.now();
            if let Some(i) = self.due.iter().position(|(t, _)| *t <= now) {
                return Ok(self.due.remove(i).unwrap().1);
            }
            let next = self.due.iter().map(|(t, _)| *t).min();
            let until = next.map_or(deadline, |t| t.min(deadline));
            match self.inner.recv(until) {
                Ok(r) => {
                    if let Some(r) = self.mangle(r) {
                        return Ok(r);
                    }
                }
                Err(FrameLinkError::Timeout) if until < deadline => {}
                Err(e) => return Err(e),
            }
        }
    }

    fn set_filters(&mut self, filters: &[IdFilter]) -> Result<(), FrameLinkError> {
        self.inner.set_filters(filters)
    }

    robobus_link::forward_frame_link_clock!(inner);
}

/// Where the two joints stand (disabled, brakes locked: they do not move).
const TRUTH: [(u8, f64); 2] = [(1, 12.3456), (2, -45.6789)];

struct Outcome {
    right: u32,
    wrong: u32,
    failed: BTreeMap<String, u32>,
    injected: Injected,
}

fn run(faults: Faults, verify_reads: bool, reads: u32) -> Outcome {
    run_with(faults, verify_reads, reads, virtual_config())
}

fn run_with(faults: Faults, verify_reads: bool, reads: u32, base: JointBusConfig) -> Outcome {
    let cfgs = TRUTH
        .iter()
        .map(|&(id, deg)| {
            let mut cfg = JointConfig::new(id, WhjModel::Whj30);
            cfg.initial_position_deg = deg;
            cfg
        })
        .collect();
    let (link, _sim) = sim_link(configs(cfgs));
    let injected = Arc::new(Mutex::new(Injected::default()));
    let bus = JointBus::open_with(
        ReplyFaults::new(link, faults, 0x5EED, Arc::clone(&injected)),
        JointBusConfig {
            verify_reads,
            reply_timeout: Duration::from_millis(5),
            retries: 10,
            ..base
        },
    )
    .unwrap();
    let joints: Vec<_> = TRUTH
        .iter()
        .map(|&(id, deg)| (bus.joint(JointId::new(id).unwrap()).unwrap(), deg))
        .collect();
    for (j, _) in &joints {
        j.disable().unwrap();
    }
    let mut out = Outcome {
        right: 0,
        wrong: 0,
        failed: BTreeMap::new(),
        injected: Injected::default(),
    };
    for i in 0..reads {
        let (j, deg) = &joints[(i % 2) as usize];
        match joint_status(j) {
            Ok(st) => {
                // Within half the joint's unit of 0.0001°: the same raw value.
                if (st.position_deg - deg).abs() < 0.000_05 && !st.enabled {
                    out.right += 1;
                } else {
                    eprintln!("read {i} of joint {}: {st:?}, wanted {deg}", j.id());
                    out.wrong += 1;
                }
            }
            Err(e) => {
                let kind = match e.kind() {
                    ErrorKind::Device => "device",
                    ErrorKind::NoDevice => "no-device",
                    k => panic!("read {i}: unexpected kind {k:?}: {e}"),
                };
                *out.failed.entry(kind.to_string()).or_default() += 1;
            }
        }
    }
    out.injected = *injected.lock().unwrap();
    out
}

const ONE_PERCENT_EACH: Faults = Faults {
    doubled: 0.01,
    wrong_slot: 0.01,
    implausible: 0.01,
};

#[test]
fn ten_thousand_status_reads_through_doubled_late_and_implausible_replies_give_no_wrong_value() {
    // In both wait modes: spinning changes no reply attribution (the counts below are
    // exact, and the same for each mode).
    let runs: Vec<_> = [WaitMode::Sleep, WaitMode::SPIN]
        .into_iter()
        .flat_map(|wait| [false, true].map(|v| (v, wait)))
        .map(|(v, wait)| {
            let base = JointBusConfig {
                wait,
                ..virtual_config()
            };
            (v, run_with(ONE_PERCENT_EACH, v, 10_000, base))
        })
        .collect();
    for (verify_reads, o) in &runs {
        eprintln!(
            "verify_reads {verify_reads}: {} right, {} wrong, failed {:?}, injected {:?}",
            o.right, o.wrong, o.failed, o.injected
        );
        assert_eq!(o.wrong, 0, "verify_reads {verify_reads}");
        assert_eq!(o.right + o.failed.values().sum::<u32>(), 10_000);
    }
    // Seeded, on the virtual clock: the counts are exact. Every kind of fault was injected
    // many times; the reads that failed did so as device faults (a second, different
    // answer; an implausible position), never as a value.
    let counts: Vec<_> = runs
        .iter()
        .map(|(_, o)| (o.right, o.failed.get("device").copied(), o.injected))
        .collect();
    let injected = |doubled_same, doubled_other, wrong_slot, implausible| Injected {
        doubled_same,
        doubled_other,
        wrong_slot,
        implausible,
    };
    assert_eq!(
        counts,
        [
            (9835, Some(165), injected(170, 67, 197, 99)),
            (9821, Some(179), injected(269, 54, 302, 126)),
            (9835, Some(165), injected(170, 67, 197, 99)),
            (9821, Some(179), injected(269, 54, 302, 126)),
        ]
    );
}

#[test]
fn each_reply_fault_alone_fails_reads_instead_of_misreporting_them() {
    // Each fault at 5 %, alone: the failures are the ones that fault causes.
    let alone = |doubled, wrong_slot, implausible| Faults {
        doubled,
        wrong_slot,
        implausible,
    };
    // Late replies in the wrong slot cost retries, never a value or a failure: the reply
    // that fits the request is waited for.
    let o = run(alone(0.0, 0.05, 0.0), false, 2_000);
    assert_eq!((o.wrong, o.right), (0, 2_000), "{:?}", o.failed);
    // Implausible positions fail the read as a device fault.
    let o = run(alone(0.0, 0.0, 0.05), false, 2_000);
    assert_eq!(o.wrong, 0);
    assert_eq!(
        o.failed.get("device").copied(),
        Some(o.injected.implausible),
        "{:?}",
        o.failed
    );
    // A second, different answer fails the read; the same answer twice does not.
    let o = run(alone(0.05, 0.0, 0.0), false, 2_000);
    assert_eq!(o.wrong, 0);
    assert!(o.injected.doubled_same > 0 && o.injected.doubled_other > 0);
    assert_eq!(
        o.failed.get("device").copied(),
        Some(o.injected.doubled_other),
        "{:?} {:?}",
        o.failed,
        o.injected
    );
}

#[test]
fn without_the_collision_window_the_first_of_two_answers_would_be_taken() {
    // The control experiment: the same faults with the client taking the first answer at
    // once (no collision window) report the other joint's position as this one's.
    let o = run_with(
        ONE_PERCENT_EACH,
        false,
        10_000,
        JointBusConfig {
            collision_window: Some(Duration::ZERO),
            ..virtual_config()
        },
    );
    // Seeded, on the virtual clock: the count is exact (0 with the window, above).
    assert_eq!(o.wrong, 59, "{:?}", o.injected);
}

/// How long after a frame like `frame` a second node's answer to the same request has
/// crossed the wire at the latest: the intermission, then a frame of its ID and length
/// with the most stuff bits any payload of that length can have.
fn longest_loser(frame: &CanFrame) -> Duration {
    use robobus_whj::timing::{FrameBits, fd_data_stuff_bounds, frame_bits};
    let bits = frame_bits(frame);
    let id = frame.standard_raw_id().unwrap();
    let (_, most) = fd_data_stuff_bounds(id, frame.len(), frame.esi()).unwrap();
    FrameBits {
        data_bits: bits.data_bits + most.saturating_sub(bits.stuff_data),
        stuff_data: most,
        ..bits
    }
    .duration(BitRates::WHJ)
}

/// A second joint at joint 1's ID, slower than it by the most the wire allows: each status
/// answer of joint 1 is followed by a different one (another position) exactly when the
/// longest arbitration loser's frame can have ended, plus the link's allowance.
struct LoserAtTheLastInstant<L> {
    inner: L,
    due: Option<(Instant, Received)>,
}

impl<L: FrameLink> FrameLink for LoserAtTheLastInstant<L> {
    fn send(&mut self, frame: &CanFrame) -> Result<(), FrameLinkError> {
        self.inner.send(frame)
    }

    fn recv(&mut self, deadline: Instant) -> Result<Received, FrameLinkError> {
        if let Some((at, r)) = self.due
            && at <= self.inner.now()
        {
            self.due = None;
            return Ok(r);
        }
        let until = self.due.map_or(deadline, |(at, _)| at.min(deadline));
        let r = self.inner.recv(until)?;
        if r.frame.raw_id() == 0x701 && r.frame.data().len() == 16 {
            let mut data = r.frame.data().to_vec();
            data[8] ^= 0x01;
            let frame = CanFrame::new_fd(CanFrame::standard_id(0x701).unwrap(), &data).unwrap();
            let at = self.inner.now() + longest_loser(&r.frame) + self.inner.reply_allowance();
            self.due = Some((
                at,
                Received {
                    frame,
                    timestamp: r.timestamp,
                },
            ));
        }
        Ok(r)
    }

    fn set_filters(&mut self, filters: &[IdFilter]) -> Result<(), FrameLinkError> {
        self.inner.set_filters(filters)
    }

    robobus_link::forward_frame_link_clock!(inner);
}

#[test]
fn a_second_answer_at_the_last_instant_a_loser_can_send_it_fails_the_read() {
    for wait in [WaitMode::Sleep, WaitMode::SPIN] {
        let joint = JointConfig::new(1, WhjModel::Whj30).without_iap();
        let (link, _sim) = sim_link(configs(vec![joint]));
        let bus = JointBus::open_with(
            LoserAtTheLastInstant {
                inner: link,
                due: None,
            },
            JointBusConfig {
                wait,
                ..virtual_config()
            },
        )
        .unwrap();
        let j = bus.joint_unchecked(JointId::new(1).unwrap());
        for read in 0..20 {
            let e = joint_status(&j).unwrap_err();
            assert_eq!(e.kind(), ErrorKind::Device, "{wait} read {read}: {e}");
            assert!(e.to_string().contains("two joints answer"), "{e}");
        }
        assert_eq!(bus.telemetry().bus.duplicates, 20, "{wait}");
    }
}
