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

#[test]
fn a_sample_with_no_joint_answering_is_a_failed_sample_and_a_silent_joint_is_left_out() {
    let s = shared(false);
    let names: Vec<String> = s
        .follower
        .as_ref()
        .unwrap()
        .joints()
        .iter()
        .map(|j| j.name.clone())
        .collect();
    let row = |name: &str, ok: bool| {
        if ok {
            serde_json::json!({"id": name, "position_deg": 90.0, "speed_deg_s": null})
        } else {
            serde_json::json!({"id": name, "kind": "no-device", "error": "silent"})
        }
    };
    let report = |silent: usize| {
        robobus::catalogue::Report::with_rows(
            "robot.sample",
            "robot",
            names
                .iter()
                .enumerate()
                .map(|(i, n)| row(n, i >= silent))
                .collect(),
        )
    };
    // A read that failed as a whole, twice; a sample where no joint answered.
    assert!(health::joint_state(&s, None, 0.0).is_none());
    assert!(health::joint_state(&s, None, 0.0).is_none());
    assert!(health::joint_state(&s, Some(&report(names.len())), 0.0).is_none());
    // Two joints silent: left out, the others published.
    let msg = health::joint_state(&s, Some(&report(2)), 0.0).unwrap();
    assert_eq!(msg.name, names[2..].to_vec());
    assert!((msg.position[0] - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
    let h = health::of(&s);
    assert_eq!(
        (h.states.failed_samples, h.states.joints_left_out),
        (3, names.len() as u64 + 2)
    );
    let answering: usize = h.buses.iter().map(|b| b.answering).sum();
    assert_eq!(answering, names.len() - 2);
}

#[test]
fn the_rate_achieved_is_the_samples_of_the_last_two_seconds_and_lost_slots_keep_their_reason() {
    let s = shared(false);
    let t0 = s.started;
    // 30 samples 100 ms apart (3 s): the last 2 s hold 21 of them (t = 1.0 ..= 3.0 s),
    // 20 intervals.
    for k in 0..30u32 {
        s.states.took(t0 + Duration::from_millis(100) * (k + 1));
    }
    let now = t0 + Duration::from_secs(3);
    assert_eq!(s.states.achieved_hz(now), Some(10.0));
    // Half a second without a sample: 16 left in the window (t = 1.5 ..= 3.0 s), 15
    // intervals over the 2 s since the first of them.
    let later = now + Duration::from_millis(500);
    assert_eq!(s.states.achieved_hz(later), Some(7.5));
    s.states.lose(4, health::LOST_TO_COMMANDS);
    s.states.lose(3, health::LOST_TO_BUSES);
    let h = health::of(&s);
    assert_eq!((h.states.lost_samples, h.states.lost_to_commands), (7, 4));
    assert_eq!(h.states.lost_reason.as_deref(), Some(health::LOST_TO_BUSES));
}
