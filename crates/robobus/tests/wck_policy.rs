//! The retry policy, plausibility checks and verification, against a scripted fake
//! module on an in-memory link (each scripted reply says exactly what the module does).
#![allow(clippy::unwrap_used)] // test helpers

use std::collections::VecDeque;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use robobus::wck::{Gains, RetryClass, WckBus, WckConfig, WckError, read_back, retry_class};
use robobus_link::{ByteLink, LinkError};
use robobus_wck::program::{Instruction, Program};
use robobus_wck::{
    BaudRate, Command, DGain, ExtServoId, IGain, PGain, Position, ServoId, StreamDecoder,
    TorqueLevel,
};

/// What the fake module does with the next command it decodes.
#[derive(Debug, Clone)]
enum Step {
    /// Answers these bytes.
    Reply(Vec<u8>),
    /// Stays silent (the command or its reply was lost).
    Silent,
}
use Step::{Reply, Silent};

/// The fake module's log.
struct Fake {
    log: Arc<Mutex<Vec<Command>>>,
}

impl Fake {
    fn commands(&self) -> Vec<Command> {
        self.log.lock().unwrap().clone()
    }

    fn count(&self, f: impl Fn(&Command) -> bool) -> usize {
        self.commands().iter().filter(|c| f(c)).count()
    }
}

/// The link to the fake module, on a virtual clock of its own: a scripted reply arrives
/// when the wire-time model says a module's would (its first byte one turnaround after
/// the command, then one byte time a byte), a read that waits moves the clock to the next
/// byte, and a read that finds nothing before its deadline moves the clock there.
struct FakeLink {
    script: VecDeque<Step>,
    decoder: StreamDecoder,
    log: Arc<Mutex<Vec<Command>>>,
    pending: VecDeque<(Instant, u8)>,
    now: Instant,
}

impl ByteLink for FakeLink {
    fn write_all(&mut self, bytes: &[u8]) -> Result<(), LinkError> {
        let commands: Vec<Command> = self.decoder.feed(bytes).filter_map(Result::ok).collect();
        for command in commands {
            self.log.lock().unwrap().push(command);
            if let Some(Reply(reply)) = self.script.pop_front() {
                let baud = BaudRate::B115200;
                let first = self.now + robobus_wck::timing::earliest_reply(&command, baud);
                let byte = robobus_wck::timing::byte_time(baud);
                let at = (1u32..).map(|k| first + byte * k);
                self.pending.extend(at.zip(reply));
            }
        }
        Ok(())
    }

    fn read_some(&mut self, buf: &mut [u8], deadline: Instant) -> Result<usize, LinkError> {
        if buf.is_empty() {
            return Ok(0);
        }
        match self.pending.front() {
            Some(&(at, _)) if at <= deadline => self.now = self.now.max(at),
            _ => {
                self.now = self.now.max(deadline);
                return Err(LinkError::Timeout {
                    received: 0,
                    expected: buf.len(),
                });
            }
        }
        let mut n = 0;
        while n < buf.len()
            && let Some(&(at, b)) = self.pending.front()
            && at <= self.now
        {
            buf[n] = b;
            n += 1;
            self.pending.pop_front();
        }
        Ok(n)
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
}

/// A bus whose other end is a fake module following `script`, one step per decoded
/// command (silent once the script is used up).
fn fake_module(script: Vec<Step>, config: WckConfig) -> (WckBus<FakeLink>, Fake) {
    let log = Arc::new(Mutex::new(Vec::new()));
    let link = FakeLink {
        script: script.into(),
        decoder: StreamDecoder::new(),
        log: Arc::clone(&log),
        pending: VecDeque::new(),
        now: Instant::now(),
    };
    let bus = WckBus::new(link, BaudRate::B115200)
        .unwrap()
        .with_device_name("fake")
        .with_config(config);
    (bus, Fake { log })
}

fn quick() -> WckConfig {
    WckConfig {
        margin: Duration::from_millis(25),
        ..WckConfig::default()
    }
}

fn id(n: u8) -> ServoId {
    ServoId::new(n).unwrap()
}

#[test]
fn an_implausible_reply_is_retried_and_never_returned() {
    // Load 255 is out of range (0..=254): the first reply is refused, the second taken.
    let (mut bus, fake) = fake_module(vec![Reply(vec![255, 10]), Reply(vec![0, 10])], quick());
    let status = bus.servo(id(1)).status().unwrap();
    assert_eq!(status.position, Position::new(10).unwrap());
    assert_eq!(fake.commands().len(), 2);
    let counters = bus.stats();
    assert_eq!(
        (counters.bad_replies, counters.retries),
        (1, 1),
        "{counters:?}"
    );
}

#[test]
fn a_reply_that_stays_implausible_is_an_error_with_its_bytes() {
    let (mut bus, fake) = fake_module(vec![Reply(vec![3, 4]); 4], quick());
    // An I gain read repeats the gain in both bytes: 3 and 4 cannot both be it.
    let err = bus.servo(id(2)).i_gain().unwrap_err();
    match &err {
        WckError::BadReply {
            bytes, attempts, ..
        } => {
            assert_eq!(bytes, &[3, 4]);
            assert_eq!(*attempts, 4);
        }
        other => panic!("{other:?}"),
    }
    assert!(err.to_string().contains("03 04"), "{err}");
    assert_eq!(fake.commands().len(), 4);
}

#[test]
fn retries_can_be_turned_off() {
    let config = WckConfig {
        retries: 0,
        ..quick()
    };
    let (mut bus, fake) = fake_module(vec![Reply(vec![255, 10]), Reply(vec![0, 10])], config);
    assert!(matches!(
        bus.servo(id(1)).status(),
        Err(WckError::BadReply { attempts: 1, .. })
    ));
    assert_eq!(fake.commands().len(), 1);
}

#[test]
fn a_lost_id_set_reply_is_never_resent_and_the_old_id_is_reported() {
    let script = vec![
        Silent, // probe of the new ID 9: free
        Silent, // ID set: no reply
        Silent, // status at ID 9, 4 attempts: nothing
        Silent,
        Silent,
        Silent,
        Reply(vec![0, 127]), // status at the old ID 1: still there
    ];
    let (mut bus, fake) = fake_module(script, quick());
    let err = bus
        .servo(id(1))
        .set_id(ExtServoId::new(9).unwrap())
        .unwrap_err();
    assert!(matches!(err, WckError::NotApplied { .. }), "{err}");
    assert!(err.to_string().contains("ID 1"), "{err}");
    assert_eq!(fake.count(|c| matches!(c, Command::IdSet { .. })), 1);
}

#[test]
fn an_id_set_answered_nowhere_is_not_verified() {
    let (mut bus, fake) = fake_module(vec![], quick());
    let err = bus
        .servo(id(1))
        .set_id(ExtServoId::new(9).unwrap())
        .unwrap_err();
    assert!(matches!(err, WckError::NotVerified { .. }), "{err}");
    assert_eq!(fake.count(|c| matches!(c, Command::IdSet { .. })), 1);
}

#[test]
fn a_lost_baud_set_reply_is_never_resent_and_the_bus_goes_back() {
    let script = vec![
        Silent, // baud set
        Silent, // status at the new rate, 4 attempts
        Silent,
        Silent,
        Silent,
        Reply(vec![0, 127]), // at the old rate
    ];
    let (mut bus, fake) = fake_module(script, quick());
    let err = bus.servo(id(1)).set_baud(BaudRate::B57600).unwrap_err();
    assert!(matches!(err, WckError::NotApplied { .. }), "{err}");
    assert_eq!(bus.baud(), BaudRate::B115200);
    assert_eq!(bus.link().baud(), Some(115_200));
    assert_eq!(fake.count(|c| matches!(c, Command::BaudSet { .. })), 1);
}

fn gains(p: u8, d: u8) -> Gains {
    Gains {
        p: PGain::new(p).unwrap(),
        d: DGain::new(d).unwrap(),
    }
}

#[test]
fn an_eeprom_write_is_resent_only_when_the_read_back_shows_it_did_not_take() {
    let script = vec![
        Silent,              // gain set: lost
        Reply(vec![20, 30]), // gain read: still the old gains
        Reply(vec![40, 60]), // gain set again: echoed
        Reply(vec![40, 60]), // gain read: took
    ];
    let (mut bus, fake) = fake_module(script, quick());
    bus.servo(id(0)).set_gains(gains(40, 60)).unwrap();
    let kinds: Vec<&str> = fake.commands().iter().map(Command::name).collect();
    assert_eq!(
        kinds,
        [
            "P, D gain set",
            "P, D gain read",
            "P, D gain set",
            "P, D gain read"
        ]
    );
}

#[test]
fn an_eeprom_write_whose_reply_was_lost_but_took_is_not_resent() {
    let (mut bus, fake) = fake_module(vec![Silent, Reply(vec![40, 60])], quick());
    bus.servo(id(0)).set_gains(gains(40, 60)).unwrap();
    assert_eq!(fake.count(|c| matches!(c, Command::GainSet { .. })), 1);
}

#[test]
fn an_eeprom_write_that_never_takes_is_not_applied() {
    let script = vec![
        Reply(vec![5, 5]), // I gain set: echoed
        Reply(vec![0, 0]), // read back: 0
        Reply(vec![5, 5]),
        Reply(vec![0, 0]),
        Reply(vec![5, 5]),
        Reply(vec![0, 0]),
        Reply(vec![5, 5]),
        Reply(vec![0, 0]),
    ];
    let (mut bus, fake) = fake_module(script, quick());
    let err = bus
        .servo(id(0))
        .set_i_gain(IGain::new(5).unwrap())
        .unwrap_err();
    assert!(matches!(err, WckError::NotApplied { .. }), "{err}");
    assert!(
        err.to_string().contains("I 5") && err.to_string().contains("I 0"),
        "{err}"
    );
    assert_eq!(fake.count(|c| matches!(c, Command::IGainSet { .. })), 4);
}

fn two_step_program() -> Program {
    Program::new(&[
        Instruction::Move {
            torque: TorqueLevel::new(0).unwrap(),
            position: Position::new(82).unwrap(),
        },
        Instruction::End,
    ])
    .unwrap()
}

#[test]
fn a_motion_upload_is_never_resent_and_is_verified_by_the_count() {
    // The write's reply is garbled, but the count reads back right: done, one write.
    let (mut bus, fake) = fake_module(vec![Reply(vec![1, 2]), Reply(vec![2, 2])], quick());
    bus.servo(id(0))
        .upload_program(&two_step_program())
        .unwrap();
    assert_eq!(fake.count(|c| matches!(c, Command::MotionWrite { .. })), 1);

    // The count reads back wrong: an error, still one write.
    let (mut bus, fake) = fake_module(vec![Reply(vec![2, 2]), Reply(vec![0, 0])], quick());
    let err = bus
        .servo(id(0))
        .upload_program(&two_step_program())
        .unwrap_err();
    assert!(matches!(err, WckError::NotApplied { .. }), "{err}");
    assert_eq!(fake.count(|c| matches!(c, Command::MotionWrite { .. })), 1);
}

#[test]
fn confirmed_reads_need_equal_replies_in_a_row() {
    let twice = WckConfig {
        confirm_reads: 2,
        ..quick()
    };
    // The second reply has a flipped bit: a third read settles it.
    let script = vec![Reply(vec![0, 10]), Reply(vec![0, 11]), Reply(vec![0, 11])];
    let (mut bus, fake) = fake_module(script, twice);
    assert_eq!(bus.servo(id(0)).status().unwrap().position.get(), 11);
    assert_eq!(fake.commands().len(), 3);
    assert_eq!(bus.stats().mismatches, 1);

    // Reads that repeat their value in both bytes need one reply fewer.
    let (mut bus, fake) = fake_module(vec![Reply(vec![3, 3])], twice);
    assert_eq!(bus.servo(id(0)).i_gain().unwrap().get(), 3);
    assert_eq!(fake.commands().len(), 1);

    // Never two equal: an error, after (retries + 1) x 2 attempts.
    let script = (0..8).map(|i| Reply(vec![0, i])).collect();
    let (mut bus, fake) = fake_module(script, twice);
    let err = bus.servo(id(0)).status().unwrap_err();
    assert!(
        matches!(err, WckError::Unconfirmed { attempts: 8, .. }),
        "{err}"
    );
    assert!(err.to_string().contains("00 06 and 00 07"), "{err}");
    assert_eq!(fake.commands().len(), 8);

    // Three in a row; a timeout in between does not break the streak.
    let thrice = WckConfig {
        confirm_reads: 3,
        ..quick()
    };
    let script = vec![
        Reply(vec![0, 10]),
        Reply(vec![0, 10]),
        Reply(vec![0, 11]),
        Reply(vec![0, 11]),
        Silent,
        Reply(vec![0, 11]),
    ];
    let (mut bus, fake) = fake_module(script, thrice);
    assert_eq!(bus.servo(id(0)).status().unwrap().position.get(), 11);
    assert_eq!(fake.commands().len(), 6);
    let (mut bus, fake) = fake_module(vec![Reply(vec![4, 4]), Reply(vec![4, 4])], thrice);
    assert_eq!(bus.servo(id(0)).i_gain().unwrap().get(), 4);
    assert_eq!(fake.commands().len(), 2);

    // Operations are never confirmed (a move must not be sent twice for that).
    let (mut bus, fake) = fake_module(vec![Reply(vec![0, 10])], thrice);
    bus.servo(id(0))
        .move_to(TorqueLevel::new(0).unwrap(), Position::new(99).unwrap())
        .unwrap();
    assert_eq!(fake.commands().len(), 1);
}

#[test]
fn a_garbled_break_reply_means_several_modules_heard_it() {
    let (mut bus, fake) = fake_module(vec![Reply(vec![0xE1, 0x05])], quick());
    assert_eq!(bus.break_all().unwrap(), None);
    assert_eq!(fake.count(|c| matches!(c, Command::Break)), 1);

    let (mut bus, fake) = fake_module(vec![], quick());
    let err = bus.break_all().unwrap_err();
    assert!(err.is_timeout(), "{err}");
    assert_eq!(fake.count(|c| matches!(c, Command::Break)), 4);
}

#[test]
fn commands_without_reply_are_sent_once() {
    let (mut bus, fake) = fake_module(vec![], quick());
    let p = Position::new(100).unwrap();
    bus.sync_move(TorqueLevel::new(1).unwrap(), &[p, p, p])
        .unwrap();
    assert_eq!(fake.commands().len(), 1);
    assert_eq!(bus.stats().attempts, 1);
}

#[test]
fn the_retry_table_is_consistent() {
    let s = id(0);
    let reads = [
        Command::StatusRead { id: s },
        Command::GainRead { id: s },
        Command::IGainRead { id: s },
        Command::MotionRead { id: s },
        Command::Read10 {
            id: ExtServoId::new(40).unwrap(),
        },
    ];
    for c in reads {
        assert_eq!(retry_class(&c), RetryClass::Read, "{c}");
        assert!(retry_class(&c).resend_on_failure());
    }
    let once = [
        Command::IdSet {
            id: s,
            new_id: ExtServoId::new(3).unwrap(),
        },
        Command::BaudSet {
            id: s,
            baud: BaudRate::B9600,
        },
        Command::MotionWrite {
            id: s,
            program: Program::EMPTY,
        },
    ];
    for c in once {
        assert_eq!(retry_class(&c), RetryClass::Once, "{c}");
        assert!(!retry_class(&c).resend_on_failure());
    }
    // Every verified write has a read-back, and it reads the same module.
    let verified = Command::GainSet {
        id: s,
        p: PGain::DEFAULT,
        d: DGain::DEFAULT,
    };
    assert_eq!(retry_class(&verified), RetryClass::VerifiedWrite);
    assert_eq!(read_back(&verified), Some(Command::GainRead { id: s }));
    assert_eq!(read_back(&Command::StatusRead { id: s }), None);
}

#[test]
fn the_reply_deadline_is_the_wire_time_model_plus_the_margin() {
    let (mut bus, _fake) = fake_module(vec![], quick());
    let status = Command::StatusRead { id: id(0) };
    let eeprom = Command::GainSet {
        id: id(0),
        p: PGain::DEFAULT,
        d: DGain::DEFAULT,
    };
    let margin = quick().margin;
    // 4 + 2 bytes at 115200 (520.8 µs) + 1006.6 µs turnaround.
    assert_eq!(
        bus.reply_wait(&status),
        Duration::from_nanos(1_527_433) + margin
    );
    // 6 + 2 bytes + 121 ms for an EEPROM write.
    assert_eq!(
        bus.reply_wait(&eeprom),
        robobus_wck::timing::transaction_time(&eeprom, BaudRate::B115200) + margin
    );
    assert_eq!(
        bus.reply_wait(&eeprom),
        robobus_wck::timing::wire_time(8, BaudRate::B115200) + Duration::from_millis(121) + margin
    );
    let err = bus.servo(id(0)).status().unwrap_err();
    assert!(
        matches!(err, WckError::Timeout { waited, .. } if waited == bus.reply_wait(&status)),
        "{err:?}"
    );
    bus.set_host_baud(BaudRate::B9600).unwrap();
    assert_eq!(
        bus.reply_wait(&status),
        robobus_wck::timing::transaction_time(&status, BaudRate::B9600) + margin
    );
}

#[test]
fn opening_a_missing_port_names_it() {
    let err = WckBus::open("/dev/robobus-no-such-port", BaudRate::B115200).unwrap_err();
    assert!(matches!(err, WckError::Link { .. }), "{err}");
    assert!(
        err.to_string().contains("/dev/robobus-no-such-port"),
        "{err}"
    );
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(256))]

    /// Whatever a module answers, a read returns exactly what the checked decoder makes of
    /// the bytes, or an error: never a guess, never a panic. Three bytes are more than one
    /// reply: nothing is credited (not "the first two win").
    #[test]
    fn any_reply_is_the_decoded_value_or_an_error(
        reply in proptest::collection::vec(proptest::prelude::any::<u8>(), 0..=3),
        which in 0..4u8,
    ) {
        let config = WckConfig { retries: 1, margin: Duration::from_millis(25), ..WckConfig::default() };
        let (mut bus, _fake) = fake_module(vec![Reply(reply.clone()), Reply(reply.clone())], config);
        let s = id(3);
        let command = match which {
            0 => Command::StatusRead { id: s },
            1 => Command::IGainRead { id: s },
            2 => Command::BoundaryRead { id: s },
            _ => Command::Read10 { id: ExtServoId::from(s) },
        };
        let expected = if reply.len() == 2 { command.decode_reply(&reply).ok() } else { None };
        match bus.execute(&command) {
            Ok(got) => proptest::prop_assert_eq!(got, expected),
            Err(e) => proptest::prop_assert!(expected.is_none(), "{e} for {reply:?}"),
        }
    }
}
