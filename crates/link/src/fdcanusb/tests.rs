//! The host link against a small scripted fdcanusb on a memory byte link.

use std::collections::HashMap;
use std::sync::{Arc, Mutex, PoisonError};
use std::thread::JoinHandle;

use super::*;
use crate::MemoryByteLink;
use crate::adapter::AdapterErrorKind;

/// What the scripted adapter does; the test may change it while the link runs.
#[derive(Debug, Default)]
struct Script {
    conf: HashMap<String, String>,
    on: bool,
    /// `conf set KEY` answered with `ERR` and these details.
    refuse: Option<(&'static str, &'static str)>,
    /// `conf set KEY` accepted but this value kept.
    keep: Option<(&'static str, &'static str)>,
    /// Answer nothing at all.
    silent: bool,
    /// Answer every command with this instead.
    garbage: Option<&'static [u8]>,
    /// Frames sent back (as `rcv` lines, before the `OK`) for every frame sent.
    echo: Vec<CanFrame>,
    /// Lines sent before the answer to the next command (once).
    before_next: Vec<String>,
    status: Status,
    /// Answer `can std` with `ERR` and these details.
    refuse_send: Option<&'static str>,
    /// Answer `can status` as early firmware does (`ERR not implemented`).
    no_status: bool,
    /// Every line the adapter received.
    log: Vec<String>,
}

impl Script {
    fn answer(&mut self, line: &str) -> Vec<u8> {
        self.log.push(line.to_owned());
        if self.silent {
            return Vec::new();
        }
        if let Some(g) = self.garbage {
            return g.to_vec();
        }
        let mut out: String = self.before_next.drain(..).collect();
        let reply = match codec::parse_command(line) {
            Err(e) => codec::encode_err(&e.0),
            Ok(Command::CanOn) if self.on => codec::encode_err("already in BusOn"),
            Ok(Command::CanOn) => {
                self.on = true;
                codec::OK_LINE.into()
            }
            Ok(Command::CanOff) if !self.on => codec::encode_err("already in BusOff"),
            Ok(Command::CanOff) => {
                self.on = false;
                codec::OK_LINE.into()
            }
            Ok(Command::CanStatus | Command::Send(_)) if !self.on => {
                codec::encode_err("not in BusOn")
            }
            Ok(Command::CanStatus) if self.no_status => codec::encode_err("not implemented"),
            Ok(Command::CanStatus) => {
                format!("{}{}", codec::encode_status(&self.status), codec::OK_LINE)
            }
            Ok(Command::ConfSet { key, value }) => match (self.refuse, self.keep) {
                (Some((k, details)), _) if k == key => codec::encode_err(details),
                (_, Some((k, kept))) if k == key => {
                    self.conf.insert(key, kept.into());
                    codec::OK_LINE.into()
                }
                _ => {
                    self.conf.insert(key, value);
                    codec::OK_LINE.into()
                }
            },
            Ok(Command::ConfGet { key }) => format!(
                "{}\r\n{}",
                self.conf.get(&key).cloned().unwrap_or_else(|| "0".into()),
                codec::OK_LINE
            ),
            Ok(Command::Send(_)) => {
                if let Some(details) = self.refuse_send {
                    codec::encode_err(details)
                } else {
                    let mut s: String = self
                        .echo
                        .iter()
                        .map(|f| codec::encode_rcv(f, Some(42), Some(-1)))
                        .collect();
                    s.push_str(codec::OK_LINE);
                    s
                }
            }
        };
        out.push_str(&reply);
        out.into_bytes()
    }
}

type Shared = Arc<Mutex<Script>>;

fn lock(s: &Shared) -> std::sync::MutexGuard<'_, Script> {
    s.lock().unwrap_or_else(PoisonError::into_inner)
}

/// A scripted adapter on a thread; returns the host's end of the link.
fn adapter(script: Script) -> (MemoryByteLink, Shared, JoinHandle<()>) {
    let (host, mut dev) = MemoryByteLink::pair();
    let shared = Arc::new(Mutex::new(script));
    let s = Arc::clone(&shared);
    let thread = std::thread::spawn(move || {
        let mut lines = LineSplitter::new();
        let mut buf = [0u8; 256];
        loop {
            let Ok(n) = dev.read_some(&mut buf, Instant::now() + Duration::from_secs(30)) else {
                return;
            };
            let mut out = Vec::new();
            lines.feed(buf.get(..n).unwrap_or_default(), |line| {
                if let Line::Text(text) = line {
                    out.extend(lock(&s).answer(text));
                }
            });
            if !out.is_empty() && dev.write_all(&out).is_err() {
                return;
            }
        }
    });
    (host, shared, thread)
}

fn quick() -> FdcanusbConfig {
    FdcanusbConfig {
        reply_timeout: Duration::from_millis(200),
        ..FdcanusbConfig::default()
    }
}

fn fd(id: u16, data: &[u8]) -> CanFrame {
    CanFrame::new_fd(CanFrame::standard_id(id).unwrap(), data).unwrap()
}

fn sent_frames(s: &Shared) -> usize {
    lock(s)
        .log
        .iter()
        .filter(|l| l.starts_with("can std") || l.starts_with("can ext"))
        .count()
}

#[test]
fn open_configures_the_joints_rates_reads_them_back_and_switches_the_adapter_on() {
    let (host, s, thread) = adapter(Script::default());
    let link = FdcanusbLink::open(host, "/dev/ttyACM0", quick()).unwrap();
    assert_eq!(
        lock(&s).log,
        [
            "can off",
            "conf set can.bitrate 1000000",
            "conf get can.bitrate",
            "conf set can.fd_bitrate 5000000",
            "conf get can.fd_bitrate",
            "conf set can.fdcan_frame 1",
            "conf get can.fdcan_frame",
            "conf set can.bitrate_switch 1",
            "conf get can.bitrate_switch",
            "conf set can.automatic_retransmission 1",
            "conf get can.automatic_retransmission",
            "can on",
            "can status",
        ]
    );
    assert!(lock(&s).on);
    // Dropping the link takes the adapter off the bus.
    drop(link);
    thread.join().unwrap();
    assert_eq!(lock(&s).log.last().map(String::as_str), Some("can off"));
    assert!(!lock(&s).on);
}

#[test]
fn an_adapter_already_on_the_bus_is_taken_off_before_it_is_configured() {
    let (host, s, _t) = adapter(Script {
        on: true,
        ..Script::default()
    });
    let _link = FdcanusbLink::open(host, "p", quick()).unwrap();
    let log = lock(&s).log.clone();
    assert_eq!(log.first().map(String::as_str), Some("can off"));
    assert_eq!(log.iter().filter(|l| *l == "can on").count(), 1);
}

#[test]
fn a_silent_port_fails_at_the_reply_timeout_naming_the_command_and_sends_nothing_else() {
    let (host, s, _t) = adapter(Script {
        silent: true,
        ..Script::default()
    });
    let t0 = Instant::now();
    let e = FdcanusbLink::open(host, "/dev/ttyACM0", quick()).unwrap_err();
    assert!(t0.elapsed() >= Duration::from_millis(200));
    assert_eq!(e.kind, AdapterErrorKind::NotAnswering);
    assert_eq!(
        e.to_string(),
        "fdcanusb adapter on /dev/ttyACM0: no answer to `can off` within 200 ms: is an \
         fdcanusb on this port, plugged in and powered? (nothing was sent to a joint)"
    );
    assert_eq!(lock(&s).log, ["can off"]);
}

#[test]
fn a_device_that_answers_garbage_is_not_taken_for_an_fdcanusb() {
    // An slcan adapter refuses what it does not know with BEL.
    for garbage in [&b"\x07"[..], b"\x07\r", b"hello there\r\n", b"OK\r\nOK\r\n"] {
        let (host, s, _t) = adapter(Script {
            garbage: Some(garbage),
            ..Script::default()
        });
        let e = FdcanusbLink::open(host, "COM8", quick()).unwrap_err();
        assert_eq!(e.kind, AdapterErrorKind::Garbage, "{e}");
        assert!(e.to_string().contains("answered `can off` with"), "{e}");
        assert!(e.to_string().contains("COM8"), "{e}");
        assert_eq!(sent_frames(&s), 0);
        assert!(
            !lock(&s).log.iter().any(|l| l == "can on"),
            "{:?}",
            lock(&s).log
        );
    }
}

#[test]
fn a_data_rate_the_adapter_refuses_names_the_value_and_what_it_allows() {
    let (host, s, _t) = adapter(Script {
        refuse: Some((
            "can.fd_bitrate",
            "can.fd_bitrate 5000000 not supported (allowed: 1000000 2000000)",
        )),
        ..Script::default()
    });
    let e = FdcanusbLink::open(host, "/dev/ttyACM0", quick()).unwrap_err();
    assert_eq!(e.kind, AdapterErrorKind::RateUnsupported);
    let msg = e.to_string();
    assert!(msg.contains("allowed: 1000000 2000000"), "{msg}");
    assert!(msg.contains("can.fd_bitrate to 5000000"), "{msg}");
    assert!(!lock(&s).log.iter().any(|l| l == "can on"));
    assert_eq!(sent_frames(&s), 0);
}

#[test]
fn a_rate_the_adapter_does_not_keep_is_an_error_naming_what_it_kept() {
    let (host, s, _t) = adapter(Script {
        keep: Some(("can.bitrate", "500000")),
        ..Script::default()
    });
    let e = FdcanusbLink::open(host, "p", quick()).unwrap_err();
    let msg = e.to_string();
    assert!(
        msg.contains("can.bitrate to 1000000") && msg.contains("\"500000\""),
        "{msg}"
    );
    assert!(!lock(&s).log.iter().any(|l| l == "can on"));
}

#[test]
fn a_rate_no_fdcanusb_has_is_refused_before_anything_is_written() {
    let (host, s, _t) = adapter(Script::default());
    let e = FdcanusbLink::open(
        host,
        "p",
        FdcanusbConfig {
            fd_bitrate: 12_000_000,
            ..quick()
        },
    )
    .unwrap_err();
    assert_eq!(e.kind, AdapterErrorKind::RateUnsupported);
    assert_eq!(
        e.to_string(),
        "fdcanusb adapter on p: can.fd_bitrate 12000000 bit/s is out of range for an fdcanusb \
         (allowed: 125000..=8000000); nothing was sent"
    );
    assert!(lock(&s).log.is_empty());
}

#[test]
fn a_send_waits_for_ok_and_keeps_the_frames_that_arrived_before_it() {
    let replies = vec![fd(0x501, &[1; 16]), fd(0x502, &[2; 16])];
    let (host, s, _t) = adapter(Script {
        echo: replies.clone(),
        ..Script::default()
    });
    let mut link = FdcanusbLink::open(host, "p", quick()).unwrap();
    link.send(&fd(0x201, &[0x50, 0xC3, 0, 0])).unwrap();
    assert!(lock(&s).log.iter().any(|l| l == "can std 201 50C30000 BF"));
    // Both replies came before the OK: already queued, returned at once.
    for want in &replies {
        let got = link.recv(Instant::now()).unwrap();
        assert_eq!(&got.frame, want);
        assert!(got.timestamp.is_some());
    }
    assert!(link.recv(Instant::now()).unwrap_err().is_timeout());
}

#[test]
fn a_receive_ends_at_its_deadline_when_nothing_comes() {
    let (host, _s, _t) = adapter(Script::default());
    let mut link = FdcanusbLink::open(
        host,
        "p",
        FdcanusbConfig {
            status_every: Duration::from_secs(3600),
            ..quick()
        },
    )
    .unwrap();
    let t0 = Instant::now();
    let e = link.recv(t0 + Duration::from_millis(30)).unwrap_err();
    assert!(e.is_timeout(), "{e:?}");
    assert!(t0.elapsed() >= Duration::from_millis(30));
}

#[test]
fn frames_that_do_not_pass_the_filters_are_dropped() {
    let (host, _s, _t) = adapter(Script {
        echo: vec![fd(0x501, &[1]), fd(0x107, &[2]), fd(0x502, &[3])],
        ..Script::default()
    });
    let mut link = FdcanusbLink::open(host, "p", quick()).unwrap();
    link.set_filters(&[IdFilter::standard_masked(0x500, 0x7F0)])
        .unwrap();
    link.send(&fd(0x201, &[0])).unwrap();
    assert_eq!(link.recv(Instant::now()).unwrap().frame.raw_id(), 0x501);
    assert_eq!(link.recv(Instant::now()).unwrap().frame.raw_id(), 0x502);
    assert!(link.recv(Instant::now()).unwrap_err().is_timeout());
    assert_eq!(link.stats().filtered, 1);
}

#[test]
fn the_controller_state_reaches_the_client_as_socketcan_reports_it() {
    let (host, s, _t) = adapter(Script::default());
    let mut link = FdcanusbLink::open(
        host,
        "/dev/ttyACM0",
        FdcanusbConfig {
            status_every: Duration::ZERO,
            ..quick()
        },
    )
    .unwrap();
    let next = |link: &mut FdcanusbLink<MemoryByteLink>| {
        link.recv(Instant::now() + Duration::from_millis(100))
    };
    assert!(next(&mut link).unwrap_err().is_timeout());
    lock(&s).status.error_passive = true;
    let e = next(&mut link).unwrap_err();
    assert!(
        matches!(&e, FrameLinkError::ErrorPassive { iface } if iface == "fdcanusb:/dev/ttyACM0"),
        "{e:?}"
    );
    lock(&s).status.bus_off = true;
    assert!(matches!(
        next(&mut link),
        Err(FrameLinkError::BusOff { .. })
    ));
    // Reported once, as an error frame is.
    assert!(next(&mut link).unwrap_err().is_timeout());
    lock(&s).status = Status::default();
    assert!(matches!(
        next(&mut link),
        Err(FrameLinkError::BusError {
            kind: BusErrorKind::Restarted,
            ..
        })
    ));
    lock(&s).status.warning = true;
    assert!(matches!(
        next(&mut link),
        Err(FrameLinkError::BusError {
            kind: BusErrorKind::ErrorWarning,
            ..
        })
    ));
    assert!(link.stats().status_polls >= 6);
}

#[test]
fn frames_the_adapter_dropped_are_reported_as_an_overrun() {
    let (host, s, _t) = adapter(Script {
        status: Status {
            rx_overruns: Some(3),
            ..Status::default()
        },
        ..Script::default()
    });
    let mut link = FdcanusbLink::open(
        host,
        "p",
        FdcanusbConfig {
            status_every: Duration::ZERO,
            ..quick()
        },
    )
    .unwrap();
    // The count at open is the starting point, not news.
    assert!(
        link.recv(Instant::now() + Duration::from_millis(50))
            .unwrap_err()
            .is_timeout()
    );
    lock(&s).status.rx_overruns = Some(5);
    assert!(matches!(
        link.recv(Instant::now() + Duration::from_millis(100)),
        Err(FrameLinkError::BusError {
            kind: BusErrorKind::Other { class: 0x04 },
            ..
        })
    ));
}

#[test]
fn an_adapter_off_the_bus_refuses_a_frame_as_bus_off() {
    let (host, s, _t) = adapter(Script::default());
    let mut link = FdcanusbLink::open(host, "p", quick()).unwrap();
    lock(&s).refuse_send = Some("not in BusOn state");
    assert!(matches!(
        link.send(&fd(1, &[1])),
        Err(FrameLinkError::BusOff { .. })
    ));
    lock(&s).refuse_send = Some("bad id");
    let e = link.send(&fd(1, &[1])).unwrap_err();
    assert!(e.to_string().contains("ERR bad id"), "{e}");
}

#[test]
fn a_frame_without_data_is_refused_before_it_is_written() {
    let (host, s, _t) = adapter(Script::default());
    let mut link = FdcanusbLink::open(host, "p", quick()).unwrap();
    let e = link.send(&fd(1, &[])).unwrap_err();
    assert!(matches!(e, FrameLinkError::Unsendable { .. }), "{e:?}");
    assert_eq!(sent_frames(&s), 0);
}

#[test]
fn garbage_after_open_is_skipped_and_the_frames_around_it_delivered() {
    let (host, s, _t) = adapter(Script::default());
    let mut link = FdcanusbLink::open(host, "p", quick()).unwrap();
    let mut junk = String::from("\x07\x07 noise\r\n");
    junk.push_str(&"X".repeat(5000));
    junk.push_str("\r\nrcv 800 01 e B F r\r\nOK\r\n");
    junk.push_str(&codec::encode_rcv(&fd(0x501, &[9]), None, None));
    lock(&s).before_next = vec![junk];
    lock(&s).echo = vec![fd(0x502, &[8])];
    link.send(&fd(0x201, &[1])).unwrap();
    assert_eq!(link.recv(Instant::now()).unwrap().frame.raw_id(), 0x501);
    assert_eq!(link.recv(Instant::now()).unwrap().frame.raw_id(), 0x502);
    // The stray OK was taken for the send's: the send's own OK is one more stray line.
    assert!(link.stats().garbage >= 3, "{:?}", link.stats());
}

#[test]
fn the_queue_of_received_frames_is_bounded_and_an_overflow_reported() {
    let (host, s, _t) = adapter(Script::default());
    let mut link = FdcanusbLink::open(
        host,
        "p",
        FdcanusbConfig {
            status_every: Duration::from_secs(3600),
            ..quick()
        },
    )
    .unwrap();
    let rcv = codec::encode_rcv(&fd(0x501, &[1]), None, None);
    lock(&s).before_next = vec![rcv.repeat(MAX_QUEUED + 10)];
    link.send(&fd(0x201, &[1])).unwrap();
    assert!(matches!(
        link.recv(Instant::now()),
        Err(FrameLinkError::BusError {
            kind: BusErrorKind::Other { class: 0x04 },
            ..
        })
    ));
    let mut n = 0;
    while link.recv(Instant::now()).is_ok() {
        n += 1;
    }
    assert_eq!(n, MAX_QUEUED);
    assert_eq!(link.stats().overrun, 10);
}

#[test]
fn firmware_without_can_status_opens_and_is_not_asked_again() {
    let (host, s, _t) = adapter(Script {
        no_status: true,
        echo: vec![fd(0x501, &[1])],
        ..Script::default()
    });
    let mut link = FdcanusbLink::open(
        host,
        "p",
        FdcanusbConfig {
            status_every: Duration::ZERO,
            ..quick()
        },
    )
    .unwrap();
    link.send(&fd(0x201, &[1])).unwrap();
    assert_eq!(link.recv(Instant::now()).unwrap().frame.raw_id(), 0x501);
    assert!(
        link.recv(Instant::now() + Duration::from_millis(20))
            .unwrap_err()
            .is_timeout()
    );
    let asked = lock(&s).log.iter().filter(|l| *l == "can status").count();
    assert_eq!(asked, 1);
    assert_eq!(link.stats().status_polls, 0);
}
