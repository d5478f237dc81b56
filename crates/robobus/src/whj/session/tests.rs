//! The session driven by hand: no bus, no link, no thread, no lock. Each test feeds it
//! requests, frames, errors and explicit instants, and checks what it polls out.

use robobus_whj::reply::WriteStatus;
use robobus_whj::request::ReadRange;
use robobus_whj::units::{ActualSpeed, Current, Position, Temperature, Voltage};
use robobus_whj::{BroadcastFeedback, CmdError, ErrorCode, RegisterAddr, ServoFeedback};

use super::arbitration::loser_time;
use super::cyclic::{CyclicConfig, ServoMode};
use super::late::LATE_HORIZON_TIMEOUTS;
use super::*;

fn j(n: u8) -> JointId {
    JointId::new(n).unwrap()
}

fn j1() -> JointId {
    j(1)
}

fn read(addr: u8, count: u8) -> (Request, ReadRange) {
    let range = ReadRange::new(RegisterAddr::new(addr).unwrap(), count).unwrap();
    (Request::Read { joint: j1(), range }, range)
}

/// Replies credited at once (the tests of other rules than the collision window).
fn no_window() -> JointBusConfig {
    JointBusConfig {
        collision_window: Some(Duration::ZERO),
        ..JointBusConfig::default()
    }
}

/// One attempt of `request`, 20 ms for its reply.
fn txn(request: Request, submitted: Instant) -> Txn {
    Txn {
        request,
        expect: Expect::of(&request).unwrap(),
        timeout: Duration::from_millis(20),
        quiet_after: Duration::ZERO,
        submitted,
        attempts: 1,
    }
}

/// `request` with up to `attempts` attempts.
fn retried(request: Request, submitted: Instant, attempts: u32) -> Txn {
    Txn {
        attempts,
        ..txn(request, submitted)
    }
}

/// Sends what the session wants sent at `now`: the frames, each reported sent.
fn transmit(s: &mut Session, now: Instant) -> Vec<CanFrame> {
    let mut sent = Vec::new();
    while let Some(tx) = s.poll_transmit(now) {
        s.handle_sent();
        sent.push(tx.frame);
    }
    sent
}

fn ms(n: u64) -> Duration {
    Duration::from_millis(n)
}

fn us(n: u64) -> Duration {
    Duration::from_micros(n)
}

/// How long the default settings hold `reply` for a second answer when nothing is sent
/// meanwhile, on a link that does not say its allowance ([`Session::new`]): the
/// arbitration loser's frame and the default allowance.
fn hold(reply: &Reply) -> Duration {
    loser_time(&reply.to_frame()) + robobus_link::DEFAULT_REPLY_ALLOWANCE
}

fn snapshot(s: &mut Session) -> BusTelemetry {
    let mut t = BusTelemetry::default();
    s.poll_telemetry(&mut t);
    t
}

#[test]
fn a_matching_reply_finishes_the_transaction_and_lands_in_the_telemetry() {
    let t0 = Instant::now();
    let mut s = Session::new(no_window());
    let (req, range) = read(0x14, 2);
    let id = s.submit(txn(req, t0));
    assert!(!s.is_idle());
    assert_eq!(transmit(&mut s, t0), vec![req.to_frame()]);
    assert!(s.awaiting());
    assert_eq!(s.next_deadline(t0), t0 + s.config.poll_interval);
    assert!(s.poll_outcome(id).is_none());
    let reply = Reply::read(j1(), range, &[0x1A80, 0x0006]).unwrap();
    let at = t0 + us(300);
    s.handle_frame(&reply.to_frame(), at);
    let got = s.poll_outcome(id).unwrap();
    assert!(matches!(&got.attempt, Attempt::Reply { reply: r } if *r == reply));
    assert_eq!(got.attempts, 1);
    // Polled once.
    assert!(s.poll_outcome(id).is_none());
    assert!(s.is_idle());
    let mut t = BusTelemetry::default();
    assert!(s.poll_telemetry(&mut t));
    assert_eq!((t.bus.frames_sent, t.bus.frames_received), (1, 1));
    let joint = t.joint(j1());
    assert_eq!((joint.replies, joint.updated), (1, Some(at)));
    assert_eq!(joint.position, Some(Position(0x0006_1A80)));
    // Nothing changed since: nothing to copy.
    assert!(!s.poll_telemetry(&mut t));
}

#[test]
fn a_reply_to_another_register_is_not_credited_and_the_deadline_is_exact() {
    let t0 = Instant::now();
    let mut s = Session::new(no_window());
    let (req, _) = read(0x14, 2);
    let id = s.submit(txn(req, t0));
    let tx = s.poll_transmit(t0).unwrap();
    assert_eq!(tx.frame, req.to_frame());
    // A second request on the same reply ID waits for the first.
    let (other, other_range) = read(0x2A, 6);
    let second = s.submit(txn(other, t0));
    assert!(s.poll_transmit(t0).is_none());
    assert_eq!(s.next_deadline(t0 + ms(19)), t0 + ms(19) + us(500));
    assert_eq!(s.next_deadline(t0 + us(19_800)), t0 + ms(20));
    // A late reply for register 0x2A arrives: it answers another request, so the read
    // of 0x14 keeps waiting.
    let late = Reply::read(j1(), other_range, &[0; 6]).unwrap();
    s.handle_frame(&late.to_frame(), t0 + ms(1));
    assert!(s.poll_outcome(id).is_none());
    assert_eq!(snapshot(&mut s).bus.unmatched, 1);
    // Nothing else comes: it times out exactly at its deadline, not before.
    s.handle_timeout(t0 + us(19_999));
    assert!(s.poll_outcome(id).is_none());
    s.handle_timeout(t0 + ms(20));
    assert!(matches!(
        s.poll_outcome(id),
        Some(Outcome { attempt: Attempt::Timeout { waited, state: BusState::Active }, attempts: 1 })
            if waited == ms(20)
    ));
    // Now the second request goes out, and the same reply is credited to it.
    let t1 = t0 + ms(20);
    assert_eq!(s.poll_transmit(t1).unwrap().frame, other.to_frame());
    s.handle_frame(&late.to_frame(), t1 + us(100));
    let got = s.poll_outcome(second).map(|o| o.attempt);
    assert!(
        matches!(&got, Some(Attempt::Reply { reply: Reply::Read { addr, words, .. } }) if addr.get() == 0x2A && words.len() >= 6),
        "{got:?}"
    );
}

#[test]
fn timeouts_are_resent_at_their_deadline_until_the_attempts_are_spent() {
    let t0 = Instant::now();
    let mut s = Session::new(no_window());
    let (req, _) = read(0x14, 2);
    let id = s.submit(retried(req, t0, 3));
    assert_eq!(transmit(&mut s, t0), vec![req.to_frame()]);
    for k in 1..=2 {
        let deadline = t0 + ms(20) * k;
        let before = deadline.checked_sub(Duration::from_nanos(1)).unwrap();
        s.handle_timeout(before);
        assert!(transmit(&mut s, before).is_empty());
        s.handle_timeout(deadline);
        // Not finished: queued again, and out at once.
        assert!(s.poll_outcome(id).is_none());
        assert_eq!(transmit(&mut s, deadline), vec![req.to_frame()]);
    }
    s.handle_timeout(t0 + ms(60));
    let got = s.poll_outcome(id).unwrap();
    assert!(matches!(got.attempt, Attempt::Timeout { waited, .. } if waited == ms(20)));
    assert_eq!(got.attempts, 3);
    assert!(transmit(&mut s, t0 + ms(60)).is_empty());
    assert_eq!(snapshot(&mut s).bus.frames_sent, 3);
    // A transaction of one attempt is never resent.
    let once = s.submit(txn(req, t0 + ms(60)));
    assert_eq!(transmit(&mut s, t0 + ms(60)).len(), 1);
    s.handle_timeout(t0 + ms(80));
    assert_eq!(s.poll_outcome(once).map(|o| o.attempts), Some(1));
    assert!(transmit(&mut s, t0 + ms(80)).is_empty());
}

#[test]
fn a_malformed_reply_is_a_mismatch_and_the_request_is_resent() {
    let t0 = Instant::now();
    let mut s = Session::new(no_window());
    let (req, range) = read(0x14, 2);
    let id = s.submit(retried(req, t0, 2));
    transmit(&mut s, t0);
    // A read reply of register 0x14 with one word instead of two claims to answer the
    // read but cannot: a mismatch, resent at once.
    let (_, short) = read(0x14, 1);
    let bad = Reply::read(j1(), short, &[7]).unwrap();
    s.handle_frame(&bad.to_frame(), t0 + us(200));
    assert!(s.poll_outcome(id).is_none());
    assert_eq!(transmit(&mut s, t0 + us(200)), vec![req.to_frame()]);
    // The second answer is right.
    let good = Reply::read(j1(), range, &[1, 0]).unwrap();
    s.handle_frame(&good.to_frame(), t0 + us(400));
    let got = s.poll_outcome(id).unwrap();
    assert!(matches!(got.attempt, Attempt::Reply { reply } if reply == good));
    assert_eq!(got.attempts, 2);
    // With its last attempt spent, the mismatch is the outcome.
    let once = s.submit(txn(req, t0 + us(400)));
    transmit(&mut s, t0 + us(400));
    s.handle_frame(&bad.to_frame(), t0 + us(600));
    let got = s.poll_outcome(once).unwrap();
    assert!(matches!(&got.attempt, Attempt::Mismatch(reason) if reason.contains("expected")));
}

#[test]
fn a_cmd_err_format_error_is_resent_a_permission_error_is_not() {
    let t0 = Instant::now();
    let mut s = Session::new(no_window());
    let write = Request::write(j1(), RegisterAddr::new(0x30).unwrap(), 1).unwrap();
    let id = s.submit(retried(write, t0, 3));
    transmit(&mut s, t0);
    s.handle_frame(
        &Reply::cmd_err(j1(), CmdError::Format).to_frame(),
        t0 + us(200),
    );
    assert!(s.poll_outcome(id).is_none());
    assert_eq!(transmit(&mut s, t0 + us(200)), vec![write.to_frame()]);
    let refused = Reply::cmd_err(j1(), CmdError::Permission);
    s.handle_frame(&refused.to_frame(), t0 + us(400));
    let got = s.poll_outcome(id).unwrap();
    assert!(matches!(got.attempt, Attempt::Reply { reply } if reply == refused));
    assert_eq!(got.attempts, 2);
    assert!(transmit(&mut s, t0 + us(400)).is_empty());
}

#[test]
fn a_settle_time_holds_the_next_request_to_the_joint_until_it_ends() {
    let t0 = Instant::now();
    let mut s = Session::new(no_window());
    let write = Request::write(j1(), RegisterAddr::new(0x0A).unwrap(), 0).unwrap();
    let id = s.submit(Txn {
        quiet_after: ms(5),
        ..txn(write, t0)
    });
    // Sent 0.2 ms before its ack comes at t0.
    s.poll_transmit(t0.checked_sub(us(200)).unwrap()).unwrap();
    let ack = Reply::WriteAck {
        joint: j1(),
        addr: RegisterAddr::new(0x0A).unwrap(),
        status: WriteStatus::Ok,
    };
    s.handle_frame(&ack.to_frame(), t0);
    assert!(matches!(
        s.poll_outcome(id),
        Some(Outcome {
            attempt: Attempt::Reply { .. },
            ..
        })
    ));
    let (req, _) = read(0x14, 2);
    s.submit(txn(req, t0));
    // Another joint is not held.
    let other = Request::StatusQuery { joint: j(2) };
    s.submit(txn(other, t0));
    assert_eq!(transmit(&mut s, t0), vec![other.to_frame()]);
    let settled = t0 + ms(5);
    assert_eq!(s.next_deadline(t0), t0 + us(500));
    assert_eq!(s.next_deadline(t0 + us(4_800)), settled);
    assert!(s.poll_transmit(t0 + us(4_999)).is_none());
    assert_eq!(s.poll_transmit(settled).unwrap().frame, req.to_frame());
}

#[test]
fn a_failed_write_ack_starts_no_settle_time() {
    let t0 = Instant::now();
    let mut s = Session::new(no_window());
    let addr = RegisterAddr::new(0x0A).unwrap();
    let write = Request::write(j1(), addr, 0).unwrap();
    s.submit(Txn {
        quiet_after: ms(5),
        ..txn(write, t0)
    });
    transmit(&mut s, t0);
    let refused = Reply::WriteAck {
        joint: j1(),
        addr,
        status: WriteStatus::Failed,
    };
    s.handle_frame(&refused.to_frame(), t0 + us(100));
    let (req, _) = read(0x14, 2);
    s.submit(txn(req, t0 + us(100)));
    assert_eq!(transmit(&mut s, t0 + us(100)), vec![req.to_frame()]);
}

#[test]
fn a_second_different_reply_within_the_collision_window_is_a_duplicate_not_a_value() {
    let t0 = Instant::now();
    assert_eq!(JointBusConfig::default().collision_window, None);
    let mut s = Session::new(JointBusConfig::default());
    assert_eq!(s.allowance(), Some(us(150)));
    let (req, range) = read(0x14, 2);
    let id = s.submit(txn(req, t0));
    s.poll_transmit(t0).unwrap();
    let first = Reply::read(j1(), range, &[0, 0]).unwrap();
    let second = Reply::read(j1(), range, &[0x1A80, 0x0007]).unwrap();
    // One frame of the reply's length on the wire, and the link's allowance.
    let window = hold(&first);
    assert!(window > us(150) && window < us(300), "{window:?}");
    let t1 = t0 + us(200);
    s.handle_frame(&first.to_frame(), t1);
    // Held for the window: not credited yet, and the reply ID stays busy.
    assert!(s.poll_outcome(id).is_none());
    assert_eq!(s.next_deadline(t1), t1 + window);
    let next = s.submit(txn(req, t1));
    assert!(s.poll_transmit(t1).is_none());
    // The joint that lost arbitration answers too, differently: a fault.
    s.handle_frame(&second.to_frame(), t1 + us(150));
    let got = s.poll_outcome(id).map(|o| o.attempt);
    assert!(
        matches!(&got, Some(Attempt::Duplicate { first: f, second: g }) if *f == first && *g == second),
        "{got:?}"
    );
    // The next request goes out, and one reply (or identical ones) is credited once
    // the window closed, not before.
    let t2 = t1 + us(150);
    assert!(s.poll_transmit(t2).is_some());
    let t3 = t2 + us(100);
    s.handle_frame(&first.to_frame(), t3);
    s.handle_frame(&first.to_frame(), t3 + us(100));
    s.handle_timeout(t3 + window.saturating_sub(us(1)));
    assert!(s.poll_outcome(next).is_none());
    s.handle_timeout(t3 + window);
    assert!(matches!(
        s.poll_outcome(next).map(|o| o.attempt),
        Some(Attempt::Reply { reply }) if reply == first
    ));
    assert_eq!(snapshot(&mut s).bus.duplicates, 1);
}

#[test]
fn a_duplicate_during_the_next_transaction_to_another_joint_fails_its_own_reading_only() {
    let t0 = Instant::now();
    let mut s = Session::new(JointBusConfig::default());
    let (_, range) = read(0x14, 2);
    let ask = |n: u8| Request::Read { joint: j(n), range };
    let first = s.submit(txn(ask(1), t0));
    assert_eq!(transmit(&mut s, t0).len(), 1);
    let own = Reply::read(j1(), range, &[0x1000, 0]).unwrap();
    let impostor = Reply::read(j1(), range, &[0x1200, 0]).unwrap();
    let t1 = t0 + us(200);
    s.handle_frame(&own.to_frame(), t1);
    // Joint 1's reading is held from its caller; another caller's request to joint 2
    // goes out at once.
    assert!(s.poll_outcome(first).is_none());
    let second = s.submit(txn(ask(2), t1));
    let sent = transmit(&mut s, t1);
    assert_eq!(sent.len(), 1);
    // That request won arbitration over a loser's answer on joint 1's ID: the hold of
    // joint 1's reply lasts until a loser's frame could have followed it.
    let request = timing::frame_duration(&sent[0], BitRates::WHJ);
    let held_until = t1 + request + hold(&own);
    assert_eq!(s.next_deadline(t1), held_until);
    s.handle_timeout(t1 + hold(&own));
    assert!(s.poll_outcome(first).is_none());
    // The second joint at ID 1 answers during joint 2's transaction, after the hold
    // joint 1's reply had without that request; joint 2's reply comes after it.
    let t2 = t1 + hold(&own) + request / 2;
    s.handle_frame(&impostor.to_frame(), t2);
    let got = s.poll_outcome(first).map(|o| o.attempt);
    assert!(
        matches!(&got, Some(Attempt::Duplicate { first: f, second: g }) if *f == own && *g == impostor),
        "{got:?}"
    );
    let theirs = Reply::read(j(2), range, &[0x0100, 0]).unwrap();
    let t3 = t2 + us(50);
    s.handle_frame(&theirs.to_frame(), t3);
    s.handle_timeout(t3 + hold(&theirs));
    let got = s.poll_outcome(second).map(|o| o.attempt);
    assert!(
        matches!(&got, Some(Attempt::Reply { reply }) if *reply == theirs),
        "{got:?}"
    );
    let bus = snapshot(&mut s).bus;
    assert_eq!((bus.duplicates, bus.unmatched, bus.late), (1, 0, 0));
}

#[test]
fn a_bus_off_ends_the_attempt_and_holds_the_resend_until_the_bus_recovers() {
    let t0 = Instant::now();
    let mut s = Session::new(no_window());
    let (req, range) = read(0x14, 2);
    let id = s.submit(retried(req, t0, 2));
    transmit(&mut s, t0);
    let bus_off = FrameLinkError::BusOff {
        iface: "can0".into(),
    };
    s.handle_link_error(&bus_off, t0 + ms(1));
    // The attempt in flight failed; the second one waits for the recovery.
    assert!(s.poll_outcome(id).is_none());
    assert!(transmit(&mut s, t0 + ms(2)).is_empty());
    assert!(s.awaiting());
    let t = snapshot(&mut s);
    assert_eq!((t.bus.state, t.bus.bus_off_events), (BusState::BusOff, 1));
    // Any frame means the bus works again.
    let stray = servo_feedback(j(2), 0);
    s.handle_frame(&stray.to_frame(), t0 + ms(3));
    assert_eq!(transmit(&mut s, t0 + ms(3)), vec![req.to_frame()]);
    let reply = Reply::read(j1(), range, &[0, 0]).unwrap();
    s.handle_frame(&reply.to_frame(), t0 + ms(4));
    assert_eq!(s.poll_outcome(id).map(|o| o.attempts), Some(2));
    let t = snapshot(&mut s);
    assert_eq!((t.bus.state, t.bus.recoveries), (BusState::Active, 1));
}

#[test]
fn a_request_queued_while_bus_off_fails_after_the_recovery_timeout() {
    let t0 = Instant::now();
    let config = no_window();
    let mut s = Session::new(config);
    let bus_off = FrameLinkError::BusOff {
        iface: "can0".into(),
    };
    s.handle_link_error(&bus_off, t0);
    let (req, _) = read(0x14, 2);
    let id = s.submit(txn(req, t0));
    let limit = t0 + config.bus_recovery_timeout;
    let before = limit.checked_sub(Duration::from_nanos(1)).unwrap();
    assert!(transmit(&mut s, before).is_empty());
    assert!(s.poll_outcome(id).is_none());
    assert!(transmit(&mut s, limit).is_empty());
    let got = s.poll_outcome(id).unwrap();
    assert!(
        matches!(&got.attempt, Attempt::Bus { state: BusState::BusOff, waited, detail } if *waited == config.bus_recovery_timeout && detail.contains("bus-off")),
        "{got:?}"
    );
}

#[test]
fn a_failed_send_is_resent_from_the_next_timeout_on() {
    let t0 = Instant::now();
    let mut s = Session::new(no_window());
    let (req, _) = read(0x14, 2);
    let id = s.submit(retried(req, t0, 2));
    let tx = s.poll_transmit(t0).unwrap();
    let passive = FrameLinkError::ErrorPassive {
        iface: "can0".into(),
    };
    s.handle_send_failed(&tx, &passive, t0);
    // Not at once: not in this round of sends.
    assert!(s.poll_transmit(t0).is_none());
    assert!(s.poll_outcome(id).is_none());
    s.handle_timeout(t0 + us(500));
    assert_eq!(transmit(&mut s, t0 + us(500)), vec![req.to_frame()]);
    assert_eq!(snapshot(&mut s).bus.state, BusState::ErrorPassive);
    // A link error is final.
    let other = s.submit(retried(Request::StatusQuery { joint: j(2) }, t0, 3));
    let tx = s.poll_transmit(t0 + us(500)).unwrap();
    let io = FrameLinkError::Closed {
        context: "gone".into(),
    };
    s.handle_send_failed(&tx, &io, t0 + us(500));
    let got = s.poll_outcome(other).unwrap();
    assert!(matches!(got.attempt, Attempt::Link(_)));
    assert_eq!(got.attempts, 1);
}

#[test]
fn abandoned_transactions_are_not_sent_again() {
    let t0 = Instant::now();
    let mut s = Session::new(no_window());
    let (req, _) = read(0x14, 2);
    let id = s.submit(retried(req, t0, 3));
    transmit(&mut s, t0);
    s.abandon(id);
    s.handle_timeout(t0 + ms(20));
    assert!(transmit(&mut s, t0 + ms(20)).is_empty());
    let queued = s.submit(txn(Request::StatusQuery { joint: j(2) }, t0));
    s.abandon(queued);
    assert!(transmit(&mut s, t0 + ms(20)).is_empty());
}

/// A joint's servo feedback, with `current`.
fn servo_feedback(joint: JointId, current: i32) -> Reply {
    Reply::ServoFeedback {
        joint,
        feedback: ServoFeedback {
            current: Current(current),
            speed: ActualSpeed(0),
            position: Position(0),
            enable: 1,
            error: ErrorCode::NONE,
        },
    }
}

/// A joint's 24-byte broadcast feedback, at `position`.
fn broadcast_feedback(joint: JointId, position: i32) -> Reply {
    Reply::BroadcastFeedback {
        joint,
        feedback: BroadcastFeedback {
            current: Current(0),
            speed: ActualSpeed(0),
            position: Position(position),
            error: ErrorCode::NONE,
            voltage: Voltage(4800),
            temperature: Temperature(300),
            state: BroadcastFeedback::STATE_ENABLED,
            encoder: 0,
            counter: 0,
        },
    }
}

#[test]
fn the_broadcast_log_keeps_the_last_frames_on_broadcast_reply_ids_with_their_instants() {
    let t0 = Instant::now();
    let mut s = Session::new(no_window());
    s.handle_broadcast_sent(t0);
    // Replies are awaited for five reply timeouts.
    assert!(s.broadcast_pending(t0 + ms(99)));
    assert!(!s.broadcast_pending(t0 + ms(100)));
    let n = u32::try_from(BROADCAST_LOG).unwrap() + 6;
    for k in 0..n {
        let joint = j(1 + u8::try_from(k % 7).unwrap());
        let reply = broadcast_feedback(joint, 100 * i32::try_from(k).unwrap());
        s.handle_frame(&reply.to_frame(), t0 + us(u64::from(k) + 1));
    }
    // A point-to-point reply is not logged.
    let (_, range) = read(0x14, 2);
    let p2p = Reply::read(j1(), range, &[0, 0]).unwrap();
    s.handle_frame(&p2p.to_frame(), t0 + ms(1));
    let all = s.broadcast_replies_since(t0);
    assert_eq!(all.len(), BROADCAST_LOG);
    assert_eq!(all[0].0, t0 + us(7));
    assert_eq!(all[BROADCAST_LOG - 1].0, t0 + us(u64::from(n)));
    assert!(all.windows(2).all(|w| w[0].0 < w[1].0));
    assert_eq!(
        all[0].1,
        broadcast_feedback(j(7), 600).to_frame(),
        "the oldest kept is the seventh"
    );
    // Strictly after `since`.
    let last = s.broadcast_replies_since(t0 + us(u64::from(n) - 2));
    assert_eq!(last.len(), 2);
    // The statistics count every frame; none answered a request.
    let t = snapshot(&mut s);
    let frames = u64::from(n) + 1;
    assert_eq!(
        (t.bus.frames_received, t.bus.unmatched, t.bus.malformed),
        (frames, frames, 0)
    );
    assert_eq!(t.bus.frames_sent, 1);
    let last_of_7 = 100 * (i32::try_from(n).unwrap() - 1);
    assert_eq!(t.joint(j(7)).position, Some(Position(last_of_7)));
    assert_eq!(t.joint(j(7)).voltage, Some(Voltage(4800)));
}

#[test]
fn a_malformed_frame_is_counted_and_changes_no_joint() {
    let t0 = Instant::now();
    let mut s = Session::new(no_window());
    // A 24-byte payload on joint 1's broadcast feedback ID is logged and decoded; a
    // two-byte one on it is malformed.
    let id = broadcast_feedback(j1(), 0).can_id();
    let short = CanFrame::new_fd(CanFrame::standard_id(id).unwrap(), &[1, 2]).unwrap();
    s.handle_frame(&short, t0);
    let t = snapshot(&mut s);
    assert_eq!((t.bus.frames_received, t.bus.malformed), (1, 1));
    assert_eq!(t.joint(j1()).replies, 0);
    let since = t0.checked_sub(us(1)).unwrap();
    assert_eq!(s.broadcast_replies_since(since).len(), 1);
}

#[test]
fn telemetry_polls_copy_only_what_changed() {
    let t0 = Instant::now();
    let mut s = Session::new(no_window());
    let mut published = BusTelemetry::default();
    assert!(!s.poll_telemetry(&mut published));
    s.handle_frame(&broadcast_feedback(j(2), 5).to_frame(), t0);
    assert!(s.poll_telemetry(&mut published));
    assert_eq!(published.joint(j(2)).position, Some(Position(5)));
    // A copy edited on the reader's side keeps its edit for joints that did not change.
    let mut stale = published.clone();
    s.handle_frame(&broadcast_feedback(j(3), 9).to_frame(), t0 + ms(1));
    assert!(s.poll_telemetry(&mut stale));
    assert_eq!(stale.joint(j(3)).position, Some(Position(9)));
    assert_eq!(stale.joint(j(2)), published.joint(j(2)));
    assert_eq!(stale.bus.frames_received, 2);
}

#[test]
fn the_cyclic_loop_runs_in_the_session_and_reports_through_polls() {
    let t0 = Instant::now();
    let mut s = Session::new(no_window());
    let mut config = CyclicConfig::position(vec![j1()], ms(2));
    config.mode = ServoMode::Current;
    config.smooth = None;
    let setup = || CyclicSetup {
        config: config.clone(),
        initial: vec![0],
        step_limit_deg: 5.0,
    };
    assert!(s.start_cyclic(setup(), t0));
    assert!(!s.start_cyclic(setup(), t0), "one loop per bus");
    assert!(s.cyclic_running());
    assert!(s.cyclic_due(t0));
    assert!(s.set_cyclic_targets(vec![25]));
    assert!(!s.set_cyclic_targets(vec![1, 2]), "one target per joint");
    s.handle_timeout(t0);
    let command = Request::CurrentServo {
        joint: j1(),
        target: Current(25),
    };
    assert_eq!(transmit(&mut s, t0), vec![command.to_frame()]);
    assert!(!s.cyclic_due(t0 + us(1_999)));
    assert_eq!(s.next_deadline(t0 + us(1_900)), t0 + ms(2));
    // A servo request to the loop's joint is refused while it runs.
    let servo = s.submit(txn(command, t0));
    assert!(transmit(&mut s, t0).is_empty());
    assert!(matches!(
        s.poll_outcome(servo).map(|o| o.attempt),
        Some(Attempt::Busy)
    ));
    // The feedback closes the cycle.
    let feedback = servo_feedback(j1(), 24);
    s.handle_frame(&feedback.to_frame(), t0 + us(600));
    let Some(Event::Cycle(report)) = s.poll_event() else {
        panic!("no report");
    };
    assert_eq!((report.cycle, report.missed), (0, false));
    assert_eq!(report.commanded, vec![25]);
    assert_eq!(report.round_trip, Some(us(600)));
    assert!(s.poll_event().is_none());
    // The next tick is silent; stopping ends the loop: its last report, then its end.
    s.handle_timeout(t0 + ms(2));
    assert_eq!(transmit(&mut s, t0 + ms(2)).len(), 1);
    let running = s.cyclic_stats().unwrap();
    assert_eq!((running.cycles, running.complete), (1, 1));
    s.stop_cyclic();
    assert!(!s.cyclic_running());
    let Some(Event::CyclicEnded(stats)) = s.poll_event() else {
        panic!("no end");
    };
    // The unanswered second cycle is left out, not counted a miss.
    assert_eq!(
        (stats.cycles, stats.complete, stats.deadline_misses),
        (1, 1, 0)
    );
    assert_eq!(stats.round_trip.samples, 1);
    assert!(s.poll_event().is_none());
    assert!(s.is_idle());
}

#[test]
fn a_closed_link_fails_everything_and_ends_the_loop() {
    let t0 = Instant::now();
    let mut s = Session::new(no_window());
    let mut config = CyclicConfig::position(vec![j(3)], ms(2));
    config.mode = ServoMode::Current;
    assert!(s.start_cyclic(
        CyclicSetup {
            config,
            initial: vec![0],
            step_limit_deg: 5.0,
        },
        t0,
    ));
    let (req, _) = read(0x14, 2);
    let in_flight = s.submit(retried(req, t0, 3));
    let queued = s.submit(retried(req, t0, 3));
    s.handle_timeout(t0);
    assert_eq!(transmit(&mut s, t0).len(), 2);
    let closed = FrameLinkError::Closed {
        context: "peer gone".into(),
    };
    s.handle_link_error(&closed, t0 + ms(1));
    for id in [in_flight, queued] {
        let got = s.poll_outcome(id).unwrap();
        assert!(matches!(&got.attempt, Attempt::Link(d) if d.contains("peer gone")));
    }
    assert!(matches!(s.poll_event(), Some(Event::CyclicEnded(_))));
    assert!(s.is_idle());
    let t = snapshot(&mut s);
    assert!(t.bus.last_error.unwrap().contains("peer gone"));
}

/// Two status replies of joint 1 that differ (it moved between them).
fn two_statuses() -> (Reply, Reply) {
    let (req, range) = read(0x14, 2);
    let _ = req;
    (
        Reply::read(j1(), range, &[0x1000, 0]).unwrap(),
        Reply::read(j1(), range, &[0x1200, 0]).unwrap(),
    )
}

/// A read of 0x14 with three attempts whose first timed out at `t0 + 20 ms`: the retry
/// went out then. Returns the transaction.
fn retry_after_a_timeout(s: &mut Session, t0: Instant) -> TxnId {
    let (req, _) = read(0x14, 2);
    let id = s.submit(retried(req, t0, 3));
    assert_eq!(transmit(s, t0).len(), 1);
    s.handle_timeout(t0 + ms(20));
    assert!(s.poll_outcome(id).is_none());
    assert_eq!(transmit(s, t0 + ms(20)).len(), 1);
    id
}

#[test]
fn a_late_answer_then_the_retrys_own_is_one_joint_answering_twice_not_two_joints() {
    let t0 = Instant::now();
    let mut s = Session::new(JointBusConfig::default());
    let id = retry_after_a_timeout(&mut s, t0);
    // The first attempt's answer, a reply timeout late, then the retry's own: different.
    let (late, own) = two_statuses();
    let window = hold(&own);
    let t1 = t0 + ms(20) + us(300);
    s.handle_frame(&late.to_frame(), t1);
    s.handle_frame(&own.to_frame(), t1 + us(100));
    // Not a duplicate: the second (a joint answers in order) is held for its own window.
    assert!(s.poll_outcome(id).is_none());
    s.handle_timeout(t1 + us(100) + window);
    let got = s.poll_outcome(id).unwrap();
    assert!(
        matches!(&got.attempt, Attempt::Reply { reply } if *reply == own),
        "{got:?}"
    );
    assert_eq!(got.attempts, 2);
    let bus = snapshot(&mut s).bus;
    assert_eq!((bus.duplicates, bus.late, bus.unmatched), (0, 1, 0));
}

#[test]
fn a_late_answer_alone_in_the_retrys_window_is_not_credited_and_the_request_is_made_again() {
    let t0 = Instant::now();
    // The bus delivered a frame late a moment ago.
    let mut s = seen_late(t0);
    s.config = JointBusConfig::default();
    s.allowance = Some(robobus_link::DEFAULT_REPLY_ALLOWANCE);
    let id = retry_after_a_timeout(&mut s, t0);
    // One reply comes: the first attempt's late answer or the retry's own, which cannot
    // be told. Nothing is credited; a third attempt goes out when the window closes.
    let (late, own) = two_statuses();
    let window = hold(&late);
    let t1 = t0 + ms(20) + us(300);
    s.handle_frame(&late.to_frame(), t1);
    s.handle_timeout(t1 + window);
    assert!(s.poll_outcome(id).is_none());
    assert_eq!(transmit(&mut s, t1 + window).len(), 1);
    // The other answer (still due) and the third attempt's own arrive together: the
    // first of them is the one still due, the second is credited.
    let t2 = t1 + window + us(300);
    s.handle_frame(&own.to_frame(), t2);
    s.handle_frame(&late.to_frame(), t2 + us(50));
    s.handle_timeout(t2 + us(50) + window);
    let got = s.poll_outcome(id).unwrap();
    assert!(
        matches!(&got.attempt, Attempt::Reply { reply } if *reply == late),
        "{got:?}"
    );
    assert_eq!(got.attempts, 3);
    // Two here, and the one before.
    assert_eq!(snapshot(&mut s).bus.late, 3);
}

#[test]
fn a_late_answer_before_the_retry_is_on_the_wire_is_never_its_answer() {
    let t0 = Instant::now();
    let mut s = Session::new(no_window());
    let id = retry_after_a_timeout(&mut s, t0);
    let (late, own) = two_statuses();
    // 10 µs after the retry went out: the request itself is still on the wire.
    s.handle_frame(&late.to_frame(), t0 + ms(20) + us(10));
    assert!(s.poll_outcome(id).is_none());
    s.handle_frame(&own.to_frame(), t0 + ms(20) + us(300));
    let got = s.poll_outcome(id).unwrap();
    assert!(
        matches!(&got.attempt, Attempt::Reply { reply } if *reply == own),
        "{got:?}"
    );
    assert_eq!(snapshot(&mut s).bus.late, 1);
}

#[test]
fn two_joints_at_one_id_are_still_a_duplicate_after_a_late_answer_was_accounted_for() {
    let t0 = Instant::now();
    let mut s = Session::new(JointBusConfig::default());
    let id = retry_after_a_timeout(&mut s, t0);
    let (late, own) = two_statuses();
    let (_, range) = read(0x14, 2);
    let other = Reply::read(j1(), range, &[0x7000, 0]).unwrap();
    let t1 = t0 + ms(20) + us(300);
    // The late answer, the retry's own, and a third, different one: a second joint.
    s.handle_frame(&late.to_frame(), t1);
    s.handle_frame(&own.to_frame(), t1 + us(100));
    s.handle_frame(&other.to_frame(), t1 + us(250));
    let got = s.poll_outcome(id).unwrap();
    assert!(
        matches!(&got.attempt, Attempt::Duplicate { first, second } if *first == own && *second == other),
        "{got:?}"
    );
    assert_eq!(snapshot(&mut s).bus.duplicates, 1);
}

/// A session that saw a frame come late (the answer to a timed-out read of joint 2, after
/// its attempt ended) at `t0 - 1 ms`.
fn seen_late(t0: Instant) -> Session {
    let before = |d: Duration| t0.checked_sub(d).unwrap();
    let mut s = Session::new(no_window());
    let (_, range) = read(0x14, 2);
    let req = Request::Read { joint: j(2), range };
    let id = s.submit(txn(req, before(ms(30))));
    transmit(&mut s, before(ms(30)));
    s.handle_timeout(before(ms(10)));
    assert!(s.poll_outcome(id).is_some());
    let stray = Reply::read(j(2), range, &[0, 0]).unwrap();
    s.handle_frame(&stray.to_frame(), before(ms(1)));
    assert_eq!(snapshot(&mut s).bus.late, 1);
    s
}

#[test]
fn an_answer_due_late_is_due_only_for_the_late_horizon() {
    let t0 = Instant::now();
    let mut s = seen_late(t0);
    let (req, _) = read(0x14, 2);
    let (reply, _) = two_statuses();
    // One attempt, timed out with no frame at all: its answer may come late.
    let first = s.submit(txn(req, t0));
    transmit(&mut s, t0);
    s.handle_timeout(t0 + ms(20));
    assert!(s.poll_outcome(first).is_some());
    // Within the horizon, a reply alone to the next read may be that late answer.
    let horizon = ms(20) * LATE_HORIZON_TIMEOUTS;
    let t1 = t0 + horizon.checked_sub(ms(1)).unwrap();
    let second = s.submit(txn(req, t1));
    transmit(&mut s, t1);
    s.handle_frame(&reply.to_frame(), t1 + us(300));
    assert!(matches!(
        s.poll_outcome(second).map(|o| o.attempt),
        Some(Attempt::Late { reply: r }) if r == reply
    ));
    // After it, the same is credited.
    let t2 = t0 + horizon;
    s.handle_timeout(t2);
    let third = s.submit(txn(req, t2));
    transmit(&mut s, t2);
    s.handle_frame(&reply.to_frame(), t2 + us(300));
    assert!(matches!(
        s.poll_outcome(third).map(|o| o.attempt),
        Some(Attempt::Reply { reply: r }) if r == reply
    ));
}

/// On session `s` at `t0`: a read of 0x14 that times out with no frame at all, then
/// another whose reply comes alone; what that second read came to.
fn a_reply_after_a_silent_read(s: &mut Session, t0: Instant) -> Option<Attempt> {
    let (req, _) = read(0x14, 2);
    let (reply, _) = two_statuses();
    let first = s.submit(txn(req, t0));
    transmit(s, t0);
    s.handle_timeout(t0 + ms(20));
    assert!(s.poll_outcome(first).is_some());
    let second = s.submit(txn(req, t0 + ms(20)));
    transmit(s, t0 + ms(20));
    s.handle_frame(&reply.to_frame(), t0 + ms(20) + us(300));
    s.poll_outcome(second).map(|o| o.attempt)
}

#[test]
fn a_joint_that_was_only_silent_is_credited_its_first_reply() {
    // No frame ever came late on this bus: the joint was off, not late.
    let t0 = Instant::now();
    let (reply, _) = two_statuses();
    let got = a_reply_after_a_silent_read(&mut Session::new(no_window()), t0);
    assert!(matches!(got, Some(Attempt::Reply { reply: r }) if r == reply));
    // Once a frame came late, a reply alone while an answer is due is doubted.
    let t1 = t0 + ms(40);
    let got = a_reply_after_a_silent_read(&mut seen_late(t1), t1);
    assert!(matches!(got, Some(Attempt::Late { reply: r }) if r == reply));
}

#[test]
fn a_losers_answer_is_waited_for_with_the_most_stuff_bits_its_length_allows() {
    // Two status frames of joint 1, 16 bytes: the winner's payload has few stuff bits,
    // the loser's (all zeros) the most. The hold covers the loser's, not a copy of the
    // winner's length on the wire.
    let id = CanFrame::standard_id(0x701).unwrap();
    let few = CanFrame::new_fd(id, &[0x55; 16]).unwrap();
    let most = CanFrame::new_fd(id, &[0x00; 16]).unwrap();
    let few_time = timing::frame_duration(&few, BitRates::WHJ);
    let most_time = timing::frame_duration(&most, BitRates::WHJ);
    assert!(most_time > few_time, "{few_time:?} {most_time:?}");
    assert_eq!(loser_time(&few), loser_time(&most));
    assert!(loser_time(&few) >= most_time, "{:?}", loser_time(&few));
    eprintln!("{few_time:?} {most_time:?} {:?}", loser_time(&few));
    let mut s = Session::new(JointBusConfig::default());
    assert_eq!(
        s.hold(&few),
        (loser_time(&most), loser_time(&most) + us(150))
    );
}

#[test]
fn a_duplicate_during_the_next_transaction_to_the_same_joint_fails_its_own_reading_only() {
    let t0 = Instant::now();
    let mut s = Session::new(JointBusConfig::default());
    let (req, range) = read(0x14, 2);
    let first = s.submit(txn(req, t0));
    assert_eq!(transmit(&mut s, t0).len(), 1);
    let own = Reply::read(j1(), range, &[0x1000, 0]).unwrap();
    let impostor = Reply::read(j1(), range, &[0x1200, 0]).unwrap();
    let t1 = t0 + us(200);
    s.handle_frame(&own.to_frame(), t1);
    // The next transaction to joint 1 (another caller's, or the same caller's next
    // reading) is queued during the hold: it is not sent while the reading it could be
    // mistaken for is held, so a second answer cannot be taken for its reply.
    let second = s.submit(txn(req, t1));
    assert!(transmit(&mut s, t1).is_empty());
    assert!(transmit(&mut s, t1 + hold(&own).saturating_sub(us(1))).is_empty());
    // The second joint at ID 1 answers at the hold's last instant, before the session
    // lets that instant pass: the first reading fails, the next is not touched.
    let t2 = t1 + hold(&own);
    s.handle_frame(&impostor.to_frame(), t2);
    let got = s.poll_outcome(first).map(|o| o.attempt);
    assert!(
        matches!(&got, Some(Attempt::Duplicate { first: f, second: g }) if *f == own && *g == impostor),
        "{got:?}"
    );
    assert!(s.poll_outcome(second).is_none());
    // Now the next transaction goes out, and its own reply is credited after its hold.
    assert_eq!(transmit(&mut s, t2), vec![req.to_frame()]);
    let next = Reply::read(j1(), range, &[0x1010, 0]).unwrap();
    let t3 = t2 + us(200);
    s.handle_frame(&next.to_frame(), t3);
    s.handle_timeout(t3 + hold(&next));
    let got = s.poll_outcome(second).map(|o| o.attempt);
    assert!(
        matches!(&got, Some(Attempt::Reply { reply }) if *reply == next),
        "{got:?}"
    );
    let bus = snapshot(&mut s).bus;
    assert_eq!((bus.duplicates, bus.unmatched, bus.late), (1, 0, 0));
}

#[test]
fn a_hold_lasts_past_every_frame_that_won_arbitration_over_the_losers_answer() {
    let t0 = Instant::now();
    let mut s = Session::new(JointBusConfig::default());
    let (_, range) = read(0x14, 2);
    let ask = |n: u8| Request::Read { joint: j(n), range };
    let answer = |n: u8, v: u16| Reply::read(j(n), range, &[v, 0]).unwrap();
    let held = s.submit(txn(ask(2), t0));
    assert_eq!(transmit(&mut s, t0).len(), 1);
    let own = answer(2, 0x1000);
    let t1 = t0 + us(200);
    s.handle_frame(&own.to_frame(), t1);
    assert_eq!(s.next_deadline(t1), t1 + hold(&own));
    // Two requests go out together: the loser's answer waits for both, one after the
    // other on the wire.
    let others = [s.submit(txn(ask(1), t1)), s.submit(txn(ask(3), t1))];
    let sent = transmit(&mut s, t1);
    assert_eq!(sent.len(), 2);
    let both: Duration = sent
        .iter()
        .map(|f| timing::frame_duration(f, BitRates::WHJ))
        .sum();
    assert_eq!(s.next_deadline(t1), t1 + both + hold(&own));
    // Joint 3's answer (a higher ID than joint 2's) loses to the loser: no longer hold.
    let t2 = t1 + both + us(30);
    s.handle_frame(&answer(3, 0x0300).to_frame(), t2);
    assert_eq!(s.next_deadline(t2), t1 + both + hold(&own));
    // Joint 1's answer (a lower ID) won over the loser's, which may follow it at once.
    let t3 = t2 + us(60);
    s.handle_frame(&answer(1, 0x0100).to_frame(), t3);
    assert_eq!(s.next_deadline(t3), t3 + hold(&own));
    // The second joint at ID 2 answers then, after the hold it had before: a duplicate.
    let t4 = t3 + hold(&own);
    s.handle_frame(&answer(2, 0x1200).to_frame(), t4);
    assert!(
        matches!(
            s.poll_outcome(held).map(|o| o.attempt),
            Some(Attempt::Duplicate { .. })
        ),
        "joint 2's reading is a duplicate"
    );
    s.handle_timeout(t4 + ms(1));
    for id in others {
        assert!(matches!(
            s.poll_outcome(id).map(|o| o.attempt),
            Some(Attempt::Reply { .. })
        ));
    }
    assert_eq!(snapshot(&mut s).bus.duplicates, 1);
}
