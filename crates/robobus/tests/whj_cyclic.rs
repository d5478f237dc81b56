//! The cyclic servo loop against seven simulated joints: point-to-point and broadcast,
//! statistics, trajectory splitting of far targets on the simulator's virtual clock
//! (`WhjSimLink`: exact counts, no misses), and the matching of late and lost feedback
//! (a relay holds feedback frames back by exact amounts of simulated time).

#![allow(clippy::unwrap_used)]

use crate::whj_common;

use std::time::{Duration, Instant};

use robobus::whj::{CycleReport, Cyclic, CyclicConfig, JointBus, Protocol, ServoMode, WhjError};
use robobus_whj::units::{Current, Position, TargetSpeed};
use robobus_whj::{ErrorCode, JointId, WorkMode};
use whj_common::{chain, virtual_bus};

fn ids(n: u8) -> Vec<JointId> {
    (1..=n).map(|i| JointId::new(i).unwrap()).collect()
}

fn deg(d: f64) -> Position {
    Position::from_degrees(d).unwrap()
}

/// The next complete cycle from now (a cycle can miss its deadline on a loaded machine).
fn complete_cycle(cyc: &Cyclic<'_>) -> CycleReport {
    cyc.clear_reports();
    (0..100)
        .filter_map(|_| cyc.next_report(Duration::from_millis(500)))
        .find(|r| !r.missed)
        .expect("no complete cycle in 100")
}

/// On the virtual clock every cycle completes: `cycles` cycles, no miss, no late reply.
fn all_complete(stats: &robobus::whj::CyclicStats, cycles: u64) {
    assert_eq!(
        (
            stats.cycles,
            stats.complete,
            stats.deadline_misses,
            stats.late_replies
        ),
        (cycles, cycles, 0, 0),
        "{stats:?}"
    );
}

fn ready(bus: &JointBus, joints: &[JointId], mode: WorkMode) {
    for &id in joints {
        let j = bus.joint(id).unwrap();
        j.disable().unwrap();
        j.set_mode(mode).unwrap();
        j.enable().unwrap();
    }
}

#[test]
fn seven_joints_point_to_point_far_targets_become_smooth_moves() {
    let (bus, _sim) = virtual_bus(chain(7));
    let joints = ids(7);
    ready(&bus, &joints, WorkMode::Position);
    let cyc = bus
        .cyclic(CyclicConfig::position(
            joints.clone(),
            Duration::from_millis(4),
        ))
        .unwrap();
    assert!(bus.cyclic_running());
    // 40° away from every joint: far beyond the 10° step protection.
    let targets: Vec<Position> = (0..7).map(|i| deg(40.0 - 5.0 * f64::from(i))).collect();
    cyc.set_positions(&targets).unwrap();
    // A single servo command to a joint of the loop is refused while it runs.
    let err = bus
        .joint_unchecked(joints[0])
        .command_position(deg(0.0))
        .unwrap_err();
    assert!(matches!(err, WhjError::Busy { .. }), "{err}");
    // Register traffic still works between the loop's frames.
    assert_eq!(
        bus.joint_unchecked(joints[3]).mode().unwrap(),
        WorkMode::Position
    );

    // 40° at 30 °/s with ramps: about 1.6 s; allow 3 s.
    let mut arrived = false;
    let mut max_step = 0.0f64;
    let mut last_cmd: Option<Vec<i32>> = None;
    for _ in 0..750 {
        let Some(r) = cyc.next_report(Duration::from_millis(200)) else {
            continue;
        };
        if let Some(prev) = &last_cmd {
            for (a, b) in prev.iter().zip(&r.commanded) {
                max_step = max_step.max(f64::from((a - b).abs()) / 10_000.0);
            }
        }
        last_cmd = Some(r.commanded.clone());
        for fb in r.feedback.iter().flatten() {
            assert!(!fb.error.contains(ErrorCode::POSITION_STEP), "{fb:?}");
            assert!(fb.enabled);
        }
        if r.feedback
            .iter()
            .zip(&targets)
            .all(|(fb, t)| fb.is_some_and(|f| (f.position.degrees() - t.degrees()).abs() < 0.1))
        {
            arrived = true;
            break;
        }
    }
    assert!(
        arrived,
        "joints did not reach their targets: {:?}",
        cyc.latest()
    );
    // Set-points move by at most 30 °/s × 4 ms = 0.12° per cycle along the profile.
    assert!(
        max_step <= 0.12 + 1e-9,
        "largest set-point step {max_step}°"
    );
    let stats = cyc.stop();
    assert!(!bus.cyclic_running());
    eprintln!("point-to-point stats: {stats:#?}");
    all_complete(&stats, 387);
    assert_eq!(stats.round_trip.samples as u64, stats.complete);
    assert!(stats.round_trip.p50 > Duration::ZERO && stats.round_trip.p50 <= stats.round_trip.p99);
    assert!(stats.round_trip.p99 <= stats.round_trip.max);
    // Every joint is error-free and holds its target after the loop.
    for (&id, t) in joints.iter().zip(&targets) {
        let s = bus.joint_unchecked(id).status().unwrap();
        assert!(s.error.is_empty(), "{id}: {:?}", s.error);
        assert!((s.position.degrees() - t.degrees()).abs() < 0.2);
    }
}

#[test]
fn broadcast_position_for_a_seven_joint_chain() {
    let (bus, sim) = virtual_bus(chain(7));
    let joints = ids(7);
    ready(&bus, &joints, WorkMode::Position);
    let cyc = bus
        .cyclic(CyclicConfig {
            protocol: Protocol::Broadcast,
            ..CyclicConfig::position(joints.clone(), Duration::from_millis(2))
        })
        .unwrap();
    let targets: Vec<Position> = (0..7).map(|i| deg(f64::from(i) - 3.0)).collect();
    cyc.set_positions(&targets).unwrap();
    let before = sim.with_bus(|b| b.stats());
    // Within 0.05° of the targets, in well under a second.
    let near = |r: &CycleReport| {
        r.feedback
            .iter()
            .zip(&targets)
            .all(|(fb, t)| fb.is_some_and(|f| (f.position.degrees() - t.degrees()).abs() < 0.05))
    };
    let start = bus.now();
    let mut r = complete_cycle(&cyc);
    while !near(&r) && bus.now() - start < Duration::from_secs(1) {
        bus.sleep_until(bus.now() + Duration::from_millis(50));
        r = complete_cycle(&cyc);
    }
    for ((fb, t), id) in r.feedback.iter().zip(&targets).zip(&joints) {
        let fb = fb.unwrap_or_else(|| panic!("no broadcast feedback from {id}"));
        assert!(
            (fb.position.degrees() - t.degrees()).abs() < 0.05,
            "{id}: {fb:?}"
        );
        assert!(fb.error.is_empty());
    }
    let stats = cyc.stop();
    eprintln!("broadcast stats: {stats:#?}");
    all_complete(&stats, 157);
    // One 0x2F frame per cycle, not seven point-to-point frames; seven feedback frames
    // to each.
    let after = sim.with_bus(|b| b.stats());
    assert_eq!(
        after.host_frames - before.host_frames,
        stats.cycles,
        "{after:?}"
    );
    assert_eq!(
        after.joint_frames - before.joint_frames,
        7 * stats.cycles,
        "{after:?}"
    );
}

#[test]
fn current_loop_point_to_point_and_broadcast() {
    let (bus, _sim) = virtual_bus(chain(2));
    let joints = ids(2);
    ready(&bus, &joints, WorkMode::Current);
    for protocol in [Protocol::PointToPoint, Protocol::Broadcast] {
        let cyc = bus
            .cyclic(CyclicConfig {
                mode: ServoMode::Current,
                protocol,
                smooth: None,
                ..CyclicConfig::position(joints.clone(), Duration::from_millis(5))
            })
            .unwrap();
        cyc.set_currents(&[Current(100), Current(-100)]).unwrap();
        let err = cyc.set_positions(&[deg(0.0), deg(0.0)]).unwrap_err();
        assert!(
            err.to_string()
                .contains("Position targets given to a Current loop"),
            "{err}"
        );
        assert!(cyc.set_currents(&[Current(1)]).is_err());
        bus.sleep_until(bus.now() + Duration::from_millis(100));
        // Eleven more complete cycles, each commanding and reading back both joints.
        for _ in 0..11 {
            let r = complete_cycle(&cyc);
            assert_eq!(r.commanded, vec![100, -100]);
            assert!(
                r.feedback.iter().all(Option::is_some),
                "{protocol:?}: {r:?}"
            );
        }
        cyc.set_currents(&[Current(0), Current(0)]).unwrap();
        let stats = cyc.stop();
        // 100 ms at 5 ms, and the eleven: every cycle complete.
        all_complete(&stats, 31);
    }
}

#[test]
fn speed_loop_point_to_point() {
    let (bus, _sim) = virtual_bus(chain(3));
    let joints = ids(3);
    ready(&bus, &joints, WorkMode::Speed);
    let cyc = bus
        .cyclic(CyclicConfig {
            mode: ServoMode::Speed,
            smooth: None,
            ..CyclicConfig::position(joints.clone(), Duration::from_millis(5))
        })
        .unwrap();
    assert_eq!(cyc.joints(), &joints[..]);
    assert_eq!(cyc.config().mode, ServoMode::Speed);
    let rpm = |r: f64| TargetSpeed::from_rpm(r).unwrap();
    cyc.set_speeds(&[rpm(2.0), rpm(-3.0), rpm(0.0)]).unwrap();
    // At speed in well under a second.
    let start = bus.now();
    let at_speed = |speeds: &[f64]| {
        speeds.len() == 3
            && speeds
                .iter()
                .zip([2.0, -3.0, 0.0])
                .all(|(got, want)| (got - want).abs() < 0.3)
    };
    let mut speeds: Vec<f64> = Vec::new();
    while !at_speed(&speeds) && bus.now() - start < Duration::from_secs(1) {
        bus.sleep_until(bus.now() + Duration::from_millis(50));
        let r = complete_cycle(&cyc);
        speeds = r.feedback.iter().map(|f| f.unwrap().speed.rpm()).collect();
    }
    assert!(at_speed(&speeds), "{speeds:?}");
    assert_eq!(cyc.latest().unwrap().commanded, vec![1000, -1500, 0]);
    // Ten more complete cycles: the statistics count at least those.
    for _ in 0..10 {
        complete_cycle(&cyc);
    }
    cyc.set_speeds(&[rpm(0.0); 3]).unwrap();
    let stats = cyc.stop();
    all_complete(&stats, 21);
}

#[test]
fn invalid_configurations_are_refused() {
    let (bus, _sim) = virtual_bus(chain(1));
    let j8 = JointId::new(8).unwrap();
    let cases = [
        (
            CyclicConfig::position(vec![], Duration::from_millis(2)),
            "no joints",
        ),
        (
            CyclicConfig::position(ids(1).repeat(2), Duration::from_millis(2)),
            "twice",
        ),
        (
            CyclicConfig::position(ids(1), Duration::from_micros(10)),
            "period",
        ),
        (
            CyclicConfig {
                protocol: Protocol::Broadcast,
                ..CyclicConfig::position(vec![j8], Duration::from_millis(2))
            },
            "broadcast slot",
        ),
        (
            CyclicConfig {
                protocol: Protocol::Broadcast,
                mode: ServoMode::Speed,
                ..CyclicConfig::position(ids(1), Duration::from_millis(2))
            },
            "speed",
        ),
    ];
    for (cfg, needle) in cases {
        let err = bus.cyclic(cfg).unwrap_err();
        assert!(err.to_string().contains(needle), "{needle}: {err}");
    }
    // A second loop on the same bus is refused while one runs.
    bus.joint(ids(1)[0]).unwrap();
    let first = bus
        .cyclic(CyclicConfig::position(ids(1), Duration::from_millis(5)))
        .unwrap();
    let err = bus
        .cyclic(CyclicConfig::position(ids(1), Duration::from_millis(5)))
        .unwrap_err();
    assert!(err.to_string().contains("already running"), "{err}");
    drop(first);
    assert!(!bus.cyclic_running());
}

/// The client's side of the bus: every servo feedback frame of joint 1 is held back by
/// `base` of the link's (virtual) time, so round trips are at least that long; the one
/// answering command number `slow_index` is held back by `slow` instead, or dropped if
/// `drop` is set; with `after_tick`, the `slow_count` frames from there on are held back
/// instead until `after_tick` past the tick that follows their command's (the loop's ticks
/// are exact on the virtual clock). Each feedback's current field is replaced by the number
/// of the command it answers (0, 1, ...: the joint answers every command, in order), so the
/// test can tell which command a feedback frame answers.
struct StampingLink<L> {
    inner: L,
    answered: i32,
    slow_index: i32,
    base: Duration,
    slow: Duration,
    drop: bool,
    after_tick: Option<(Duration, i32, Duration)>,
    /// When each current command to joint 1 went out.
    sent: Vec<Instant>,
    /// Held-back frames with their release instants, in arrival (and release) order.
    held: std::collections::VecDeque<(Instant, robobus_link::Received)>,
}

impl<L: robobus_link::FrameLink> StampingLink<L> {
    /// `at`, or later if a frame held before is released later.
    fn ready_after(&self, at: Instant) -> Instant {
        self.held.back().map_or(at, |(last, _)| at.max(*last))
    }

    fn hold(&mut self, rx: robobus_link::Received) {
        let Ok(robobus_whj::Reply::ServoFeedback {
            joint,
            mut feedback,
        }) = robobus_whj::Reply::from_frame(&rx.frame)
        else {
            let at = self.ready_after(self.inner.now());
            self.held.push_back((at, rx));
            return;
        };
        let n = self.answered;
        self.answered += 1;
        if n == self.slow_index && self.drop {
            return;
        }
        let delay = if n == self.slow_index {
            self.slow
        } else {
            self.base
        };
        let mut at = self.inner.now() + delay;
        if let Some((period, count, after)) = self.after_tick
            && (self.slow_index..self.slow_index + count).contains(&n)
            && let Some(sent) = usize::try_from(n).ok().and_then(|n| self.sent.get(n))
        {
            at = *sent + period + after;
        }
        feedback.current = Current(n);
        let frame = robobus_whj::Reply::ServoFeedback { joint, feedback }.to_frame();
        // One joint's frames stay in order (a held-back frame holds back the next).
        let at = self.ready_after(at);
        self.held
            .push_back((at, robobus_link::Received { frame, ..rx }));
    }
}

impl<L: robobus_link::FrameLink> robobus_link::FrameLink for StampingLink<L> {
    fn send(&mut self, frame: &robobus_whj::CanFrame) -> Result<(), robobus_link::FrameLinkError> {
        if frame.raw_id() == 0x401 {
            self.sent.push(self.inner.now());
        }
        self.inner.send(frame)
    }

    fn recv(
        &mut self,
        deadline: Instant,
    ) -> Result<robobus_link::Received, robobus_link::FrameLinkError> {
        loop {
            let now = self.inner.now();
            if let Some((at, _)) = self.held.front()
                && *at <= now
                && let Some((_, rx)) = self.held.pop_front()
            {
                return Ok(rx);
            }
            let until = self
                .held
                .front()
                .map_or(deadline, |(at, _)| deadline.min(*at));
            match self.inner.recv(until) {
                Ok(rx) => self.hold(rx),
                Err(e) if e.is_timeout() => {
                    if self.inner.now() >= deadline
                        && self.held.front().is_none_or(|(at, _)| *at > deadline)
                    {
                        return Err(e);
                    }
                }
                Err(e) => return Err(e),
            }
        }
    }

    fn set_filters(
        &mut self,
        filters: &[robobus_link::IdFilter],
    ) -> Result<(), robobus_link::FrameLinkError> {
        self.inner.set_filters(filters)
    }

    robobus_link::forward_frame_link_clock!(inner);
}

/// Runs a current loop for joint 1 on the virtual clock over a [`StampingLink`] whose
/// feedback to command 5 takes `slow` (or is dropped), until four complete cycles after
/// cycle 7.
fn stamped_run(
    period: Duration,
    base: Duration,
    slow: Duration,
    drop: bool,
) -> (Vec<CycleReport>, robobus::whj::CyclicStats) {
    stamped_run_with(period, base, slow, drop, None)
}

/// [`stamped_run`] with [`StampingLink`]'s `after_tick` (`count` frames, `after` past the
/// next tick).
fn stamped_run_with(
    period: Duration,
    base: Duration,
    slow: Duration,
    drop: bool,
    after_tick: Option<(i32, Duration)>,
) -> (Vec<CycleReport>, robobus::whj::CyclicStats) {
    let (link, _sim) = whj_common::sim_link(chain(1));
    let link = StampingLink {
        inner: link,
        answered: 0,
        slow_index: 5,
        base,
        slow,
        drop,
        after_tick: after_tick.map(|(count, after)| (period, count, after)),
        sent: Vec::new(),
        held: std::collections::VecDeque::new(),
    };
    let bus = JointBus::open_with(link, whj_common::virtual_config()).unwrap();
    let joints = ids(1);
    let j = bus.joint(joints[0]).unwrap();
    j.disable().unwrap();
    j.set_mode(WorkMode::Current).unwrap();
    j.enable().unwrap();
    let cyc = bus
        .cyclic(CyclicConfig {
            mode: ServoMode::Current,
            smooth: None,
            ..CyclicConfig::position(joints, period)
        })
        .unwrap();
    let mut reports: Vec<CycleReport> = Vec::new();
    while reports.iter().filter(|r| r.cycle > 7 && !r.missed).count() < 4 {
        let r = cyc.next_report(period * 2).unwrap();
        assert_eq!(r.start_lateness, Duration::ZERO, "{r:?}");
        assert!(reports.len() < 30, "{reports:?}");
        reports.push(r);
    }
    (reports, cyc.stop())
}

/// Every complete cycle holds the answer to its own command, never an earlier one.
fn assert_matched(reports: &[CycleReport], base: Duration) {
    for r in reports {
        if let [Some(fb)] = r.feedback[..] {
            assert_eq!(
                i64::from(fb.current.raw()),
                i64::try_from(r.cycle).unwrap(),
                "{r:?}"
            );
            let rt = r.round_trip.unwrap();
            assert!(rt >= base, "implausible round trip {rt:?}: {r:?}");
        }
    }
}

#[test]
fn feedback_later_than_the_next_tick_counts_as_late_and_later_cycles_stay_matched() {
    let period = Duration::from_millis(200);
    let base = Duration::from_millis(10);
    // Past the next tick: the feedback of cycle 5 arrives during cycle 6.
    let slow = period + Duration::from_millis(60);
    let (reports, stats) = stamped_run(period, base, slow, false);
    assert_eq!(stats.send_errors, 0, "{stats:?}");
    assert!(reports[5].missed, "{:?}", reports[5]);
    assert_eq!(reports[5].feedback, vec![None]);
    assert_eq!(stats.late_replies, 1, "{stats:?}");
    // Cycle 6 still gets its own feedback (after the late one), and so does every later one.
    assert!(!reports[6].missed, "{:?}", reports[6]);
    assert_matched(&reports, base);
    assert!(stats.round_trip.p50 >= base, "{stats:?}");
}

#[test]
fn a_lost_feedback_frame_costs_one_more_cycle_then_feedback_is_matched_again() {
    let period = Duration::from_millis(200);
    let base = Duration::from_millis(10);
    let (reports, stats) = stamped_run(period, base, Duration::ZERO, true);
    // Cycle 5's feedback never comes; cycle 6's frame is taken for it (frames carry no
    // sequence number), so cycle 6 misses too; from cycle 7 on every cycle is matched.
    assert!(reports[5].missed && reports[6].missed, "{reports:?}");
    assert!(reports[7..].iter().all(|r| !r.missed), "{reports:?}");
    assert_matched(&reports, base);
    assert_eq!(stats.late_replies, 1, "{stats:?}");
}

#[test]
fn feedback_just_after_the_next_tick_twice_in_a_row_is_never_taken_for_a_later_cycle() {
    // The feedback to commands 5 and 6 each comes 20 µs after the next tick, before the
    // next command can have been answered (a servo frame and its feedback take about
    // 125 µs on the wire). Both are late replies of their own cycles; cycle 7 and every
    // later one get their own feedback, never the one before (whose round trip would be
    // shorter than the wire allows).
    let period = Duration::from_millis(2);
    let base = Duration::from_micros(300);
    let after = Duration::from_micros(20);
    let (reports, stats) = stamped_run_with(period, base, base, false, Some((2, after)));
    assert!(reports[5].missed && reports[6].missed, "{reports:?}");
    assert_eq!(reports[5].feedback, vec![None]);
    assert_eq!(reports[6].feedback, vec![None]);
    assert!(reports[7..].iter().all(|r| !r.missed), "{reports:?}");
    assert_matched(&reports, base);
    assert_eq!(stats.late_replies, 2, "{stats:?}");
    assert_eq!(stats.deadline_misses, 2, "{stats:?}");
}

/// The owning form of the loop crosses threads: it holds an `Arc` of the bus, runs on a
/// thread of its own while the caller's bus handle is gone, and stops when that thread
/// drops it.
#[test]
fn an_owned_loop_runs_on_another_thread() {
    fn send_static<T: Send + 'static>(t: T) -> T {
        t
    }
    let (bus, _sim) = virtual_bus(chain(2));
    let bus = std::sync::Arc::new(bus);
    let joints = ids(2);
    ready(&bus, &joints, WorkMode::Position);
    let cyc = send_static(
        bus.cyclic_owned(CyclicConfig::position(
            joints.clone(),
            Duration::from_millis(4),
        ))
        .unwrap(),
    );
    let watcher = std::sync::Arc::downgrade(&bus);
    let check = std::sync::Arc::clone(&bus);
    drop(bus);
    // The loop keeps the bus alive and running after the caller's last handle is gone.
    assert!(watcher.upgrade().is_some());
    assert!(check.cyclic_running());
    drop(check);
    let worker = std::thread::spawn(move || {
        cyc.set_positions(&[deg(2.0), deg(-3.0)]).unwrap();
        let mut last = complete_cycle(&cyc);
        for _ in 0..200 {
            let at: Vec<f64> = last
                .feedback
                .iter()
                .map(|f| f.as_ref().unwrap().position.degrees())
                .collect();
            if (at[0] - 2.0).abs() < 0.05 && (at[1] + 3.0).abs() < 0.05 {
                return (at, cyc.stop());
            }
            last = complete_cycle(&cyc);
        }
        panic!("never reached the targets: {last:?}");
    });
    let (at, stats) = worker.join().unwrap();
    assert!(
        (at[0] - 2.0).abs() < 0.05 && (at[1] + 3.0).abs() < 0.05,
        "{at:?}"
    );
    assert_eq!(stats.complete, stats.cycles, "{stats:?}");
    // Stopped with the thread's handle; the bus went with it (no handle is left).
    assert!(watcher.upgrade().is_none());
}
