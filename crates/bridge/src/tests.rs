//! The bridge's admission: the library's one, as the studio and Python apply it.

use super::*;

/// An EEPROM write (`confirm` class non-volatile).
const WRITE: &str = r#"{"op":"wck.set","id":0,"param":"gains","p":20,"d":30,"confirm":true}"#;
const MOVE: &str = r#"{"op":"whj.move","joint":3,"degrees":10}"#;
const READ: &str = r#"{"op":"wck.status","ids":"0"}"#;

fn shared(read_only: bool) -> Arc<Shared> {
    let config = BridgeConfig {
        read_only,
        ..BridgeConfig::default()
    };
    let keys = Keys::new(None).unwrap();
    Shared::new(Station::simulated().unwrap(), None, config, keys).unwrap()
}

#[test]
fn the_eleventh_eeprom_write_within_a_minute_is_refused() {
    let s = shared(false);
    for n in 1..=robobus::frontend::admission::WRITES_PER_MINUTE {
        let r = run_request(&s, WRITE);
        assert!(r.is_ok(), "write {n}: {r:?}");
    }
    let e = run_request(&s, WRITE).unwrap_err();
    assert_eq!(e.kind(), ErrorKind::Refused);
    let m = e.to_string();
    assert!(
        m.starts_with(
            "wck.set: at most 10 EEPROM / flash / ID writes a minute (they wear the device's \
             memory); try again in "
        ),
        "{m}"
    );
    // Reads are not counted.
    run_request(&s, READ).unwrap();
}

#[test]
fn motion_and_commands_need_the_bridge_armed() {
    let s = shared(false);
    let e = run_request(&s, MOVE).unwrap_err();
    assert_eq!(e.kind(), ErrorKind::Refused);
    assert_eq!(
        e.to_string(),
        "whj.move: not armed: motion needs this bridge armed (--armed, or arm on \
         robobus/arm); nothing was sent"
    );
    let command = cdr::Float64MultiArray {
        dim: Vec::new(),
        data_offset: 0,
        data: vec![0.0; s.follower.as_ref().unwrap().joints().len()],
    }
    .encode();
    assert!(!follow(&s, &command));
    assert_eq!(s.counters.refused_not_armed.load(Ordering::Relaxed), 1);
    assert!(
        s.last_refusal
            .lock()
            .unwrap()
            .as_deref()
            .is_some_and(|m| m.starts_with("joint_commands: not armed: motion needs this bridge")),
        "{:?}",
        s.last_refusal.lock().unwrap()
    );
    s.set_armed(true).unwrap();
    s.guard.heartbeat(SESSION);
    run_request(&s, MOVE).unwrap();
    s.set_armed(false).unwrap();
    assert!(run_request(&s, MOVE).is_err());
}

#[test]
fn a_read_only_bridge_reads_and_never_arms() {
    let s = shared(true);
    run_request(&s, READ).unwrap();
    for r in [WRITE, MOVE] {
        let e = run_request(&s, r).unwrap_err();
        assert!(
            e.to_string()
                .contains("this bridge is read-only (started with --read-only)"),
            "{e}"
        );
    }
    assert_eq!(s.set_armed(true).unwrap_err().kind(), ErrorKind::Refused);
    assert!(!s.armed());
    let h = health::of(&s);
    assert!(h.read_only && !h.armed, "{h:?}");
    assert!(!health::of(&shared(false)).read_only);
}

#[test]
fn a_command_replaced_before_it_was_taken_is_counted_superseded() {
    let s = shared(false);
    let t0 = Instant::now();
    for k in 0..3u32 {
        s.post(
            vec![u8::try_from(k).unwrap()],
            t0 + Duration::from_millis(u64::from(k) * 20),
        );
    }
    assert_eq!(s.counters.commands_superseded.load(Ordering::Relaxed), 2);
    let inbox = s.mailbox.slot.lock().unwrap();
    // The newest waits; the stream's interval is the commands' 20 ms.
    assert_eq!(inbox.newest.as_ref().map(|(p, _)| p.clone()), Some(vec![2]));
    assert_eq!(
        inbox.next_due(),
        Some((t0 + Duration::from_millis(60), Duration::from_millis(20)))
    );
}

#[test]
fn a_held_command_is_counted_with_its_reason() {
    let s = shared(false);
    let n = s.follower.as_ref().unwrap().joints().len();
    let command = |len: usize| {
        cdr::Float64MultiArray {
            dim: Vec::new(),
            data_offset: 0,
            data: vec![0.0; len],
        }
        .encode()
    };
    assert!(!follow(&s, &command(n)));
    s.set_armed(true).unwrap();
    assert!(!follow(&s, &command(n - 1)));
    let h = health::of(&s);
    assert_eq!(
        (h.commands.held, h.refused.not_armed, h.refused.out_of_range),
        (2, 1, 1)
    );
    let why = h.commands.last_held.unwrap();
    assert!(
        why.starts_with("joint_commands: ") && why.contains("22 values"),
        "{why}"
    );
    s.set_armed(false).unwrap();
}
