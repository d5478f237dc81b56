//! The one admission, on a manual clock.

use std::sync::Arc;
use std::time::Duration;

use super::*;
use crate::ErrorKind;
use crate::frontend::guard::{Guard, GuardConfig};
use crate::station::Station;

fn req(json: &str) -> Request {
    serde_json::from_str(json).unwrap()
}

/// An EEPROM write (`confirm` class non-volatile).
const WRITE: &str = r#"{"op":"wck.set","id":0,"param":"gains","p":20,"d":30,"confirm":true}"#;
const READ: &str = r#"{"op":"wck.status","ids":"0"}"#;
const MOVE: &str = r#"{"op":"whj.move","joint":3,"degrees":10}"#;
/// A change that does not move and writes no memory.
const CONFIGURE: &str = r#"{"op":"whj.disable","joints":"3"}"#;

fn front() -> FrontEnd {
    FrontEnd {
        name: "this test".into(),
        read_only_how: "made read-only".into(),
        arm_how: "arm it".into(),
    }
}

fn admission(read_only: bool) -> (Admission, ManualClock) {
    let clock = ManualClock::new();
    (
        Admission::with_clock(front(), read_only, clock.clone()),
        clock,
    )
}

#[test]
fn the_eleventh_write_within_a_minute_is_refused_until_the_oldest_leaves_the_window() {
    let (a, clock) = admission(false);
    for n in 0..WRITES_PER_MINUTE {
        assert!(a.admit(Arming::Local, req(WRITE)).is_ok(), "write {n}");
        // Reads are never counted.
        assert!(a.admit(Arming::Local, req(READ)).is_ok());
        clock.advance(Duration::from_secs(1));
    }
    // 10 s after the first write: it leaves the window 50 s from now.
    let r = a.admit(Arming::Local, req(WRITE)).unwrap_err();
    assert_eq!(r.kind, RefusalKind::RateLimited);
    assert_eq!(r.retry_after, Some(Duration::from_secs(50)));
    assert_eq!(r.error.kind(), ErrorKind::Refused);
    assert_eq!(
        r.to_string(),
        "wck.set: at most 10 EEPROM / flash / ID writes a minute (they wear the device's \
         memory); try again in 50 s; nothing was sent"
    );
    // A refused write is not counted: 49.5 s later it is still the oldest that waits.
    clock.advance(Duration::from_millis(49_500));
    let r = a.admit(Arming::Local, req(WRITE)).unwrap_err();
    assert_eq!(r.retry_after, Some(Duration::from_secs(1)));
    clock.advance(Duration::from_millis(500));
    assert!(a.admit(Arming::Local, req(WRITE)).is_ok());
    // The second write (at 1 s) has not left yet.
    assert_eq!(
        a.admit(Arming::Local, req(WRITE)).unwrap_err().kind,
        RefusalKind::RateLimited
    );
}

#[test]
fn what_the_plan_calls_a_confirmed_write_is_counted_and_nothing_else() {
    let (a, _clock) = admission(false);
    a.arm().unwrap();
    // An ID change and a WHJ flash save count; a move and a disable do not.
    let id = r#"{"op":"wck.set-id","id":3,"new_id":20,"confirm":true}"#;
    let save = r#"{"op":"whj.save","joints":"4","confirm":true}"#;
    for _ in 0..5 {
        a.admit(Arming::Local, req(id)).unwrap();
        a.admit(Arming::Local, req(save)).unwrap();
        a.admit(Arming::Local, req(MOVE)).unwrap();
        a.admit(Arming::Local, req(CONFIGURE)).unwrap();
    }
    assert_eq!(
        a.admit(Arming::Local, req(save)).unwrap_err().kind,
        RefusalKind::RateLimited
    );
    a.admit(Arming::Local, req(MOVE)).unwrap();
    // A current target, whose plan needs the joint's model, is a motion and no write.
    a.admit(
        Arming::Local,
        req(r#"{"op":"whj.current","joint":3,"milliamps":100}"#),
    )
    .unwrap();
    // A request that does not validate is bad input, whatever the window.
    let bad = a
        .admit(
            Arming::Local,
            req(r#"{"op":"wck.set-id","id":40,"new_id":3}"#),
        )
        .unwrap_err();
    assert_eq!(bad.kind, RefusalKind::BadInput);
    assert_eq!(bad.error.kind(), ErrorKind::BadInput);
}

#[test]
fn read_only_runs_reads_only_and_never_arms() {
    let (a, _clock) = admission(true);
    assert!(a.admit(Arming::Local, req(READ)).is_ok());
    for r in [WRITE, MOVE, CONFIGURE] {
        let e = a.admit(Arming::Local, req(r)).unwrap_err();
        assert_eq!(e.kind, RefusalKind::ReadOnly, "{r}");
    }
    assert_eq!(
        a.admit(Arming::Local, req(MOVE)).unwrap_err().to_string(),
        "whj.move: this test is read-only (made read-only): only reading requests run; \
         nothing was sent"
    );
    assert_eq!(a.arm().unwrap_err().kind, RefusalKind::ReadOnly);
    assert!(!a.armed());
    assert_eq!(
        a.admit_jog(Arming::Local, Family::Whj, None, 3)
            .unwrap_err()
            .kind,
        RefusalKind::ReadOnly
    );
}

#[test]
fn local_arming_admits_motion_only_while_armed() {
    let (a, _clock) = admission(false);
    let e = a.admit(Arming::Local, req(MOVE)).unwrap_err();
    assert_eq!(e.kind, RefusalKind::NotArmed);
    assert_eq!(
        e.to_string(),
        "whj.move: not armed: motion needs this test armed (arm it); nothing was sent"
    );
    // A change that does not move needs no arming.
    a.admit(Arming::Local, req(CONFIGURE)).unwrap();
    a.arm().unwrap();
    a.admit(Arming::Local, req(MOVE)).unwrap();
    a.admit_jog(Arming::Local, Family::Whj, None, 3).unwrap();
    a.disarm();
    assert_eq!(
        a.admit(Arming::Local, req(MOVE)).unwrap_err().kind,
        RefusalKind::NotArmed
    );
    assert_eq!(
        a.admit_jog(Arming::Local, Family::Wck, None, 2)
            .unwrap_err()
            .to_string(),
        "jog of wck servo 2: not armed: motion needs this test armed (arm it); nothing was sent"
    );
}

#[test]
fn a_guard_admits_motion_from_its_armed_controller_only_in_the_same_wording() {
    let station = Arc::new(Station::simulated().unwrap());
    let guard = Guard::new(
        Arc::clone(&station),
        GuardConfig {
            heartbeat_timeout: Duration::from_secs(3600),
            ..GuardConfig::default()
        },
        |_| {},
    )
    .unwrap();
    let (a, _clock) = admission(false);
    let as_session = |session| Arming::Guard {
        guard: &guard,
        session,
    };
    guard.take_control(1);
    // Not armed yet: the same refusal as a front end without a guard.
    let e = a.admit(as_session(Some(1)), req(MOVE)).unwrap_err();
    assert_eq!(e.kind, RefusalKind::NotArmed);
    assert_eq!(
        e.to_string(),
        "whj.move: not armed: motion needs this test armed (arm it); nothing was sent"
    );
    guard.arm(1).unwrap();
    a.admit(as_session(Some(1)), req(MOVE)).unwrap();
    assert!(
        guard.has_moved(),
        "the admitted move is recorded for the safe stop"
    );
    a.admit_jog(as_session(Some(1)), Family::Wck, None, 2)
        .unwrap();
    // Another session, or none, never moves; and changes nothing while 1 controls.
    for s in [Some(2), None] {
        assert_eq!(
            a.admit(as_session(s), req(MOVE)).unwrap_err().kind,
            RefusalKind::NotArmed
        );
        assert_eq!(
            a.admit_jog(as_session(s), Family::Whj, None, 3)
                .unwrap_err()
                .kind,
            RefusalKind::NotArmed
        );
        assert_eq!(
            a.admit(as_session(s), req(CONFIGURE)).unwrap_err().kind,
            RefusalKind::NotController
        );
        assert!(a.admit(as_session(s), req(READ)).is_ok());
    }
    // The write rate holds through a guard as without one.
    for _ in 0..WRITES_PER_MINUTE {
        a.admit(as_session(Some(1)), req(WRITE)).unwrap();
    }
    assert_eq!(
        a.admit(as_session(Some(1)), req(WRITE)).unwrap_err().kind,
        RefusalKind::RateLimited
    );
}

#[test]
fn bad_input_is_said_before_arming_and_after_read_only() {
    let bad_move = r#"{"op":"wck.move","id":3,"position":300}"#;
    let (a, _clock) = admission(false);
    let e = a.admit(Arming::Local, req(bad_move)).unwrap_err();
    assert_eq!(e.kind, RefusalKind::BadInput);
    assert!(e.to_string().contains("300"), "{e}");
    let (ro, _clock) = admission(true);
    assert_eq!(
        ro.admit(Arming::Local, req(bad_move)).unwrap_err().kind,
        RefusalKind::ReadOnly
    );
}
