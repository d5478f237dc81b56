//! Property tests: round trips host ↔ device, replies, arbitrary streams, program text.

#![allow(clippy::unwrap_used)] // test and bench set-up: a failed unwrap is a failed run

use proptest::prelude::*;
use robobus_wck::program::{Compare, DelayMs, Instruction, MotionType, Program, Repeat};
use robobus_wck::{
    Accel, BaudRate, Boundaries, Command, DGain, DataByte, DecodeError, ExtServoId, IGain, IoBits,
    Load, MotionCount, Overload, PGain, Position, Position10, RepeatCount, Reply, Rotation,
    ServoId, Speed, StreamDecoder, SyncMove, TorqueLevel, WheelSpeed, decode_packet,
};

macro_rules! ranged {
    ($f:ident, $t:ty, $lo:expr, $hi:expr) => {
        fn $f() -> impl Strategy<Value = $t> {
            ($lo..=$hi).prop_map(|v| <$t>::new(v).unwrap())
        }
    };
}

ranged!(servo_id, ServoId, 0u8, 30);
ranged!(ext_id, ExtServoId, 0u8, 253);
ranged!(position, Position, 0u8, 254);
ranged!(position10, Position10, 0u16, 1023);
ranged!(torque, TorqueLevel, 0u8, 4);
ranged!(speed, Speed, 0u8, 30);
ranged!(wheel_speed, WheelSpeed, 0u8, 15);
ranged!(accel, Accel, 20u8, 100);
ranged!(p_gain, PGain, 1u8, 254);
ranged!(d_gain, DGain, 0u8, 254);
ranged!(i_gain, IGain, 0u8, 254);
ranged!(overload, Overload, 33u8, 199);
ranged!(io_bits, IoBits, 0u8, 3);
ranged!(data_byte, DataByte, 0u8, 254);
ranged!(load, Load, 0u8, 254);
ranged!(repeat_count, RepeatCount, 1u8, 254);

fn baud() -> impl Strategy<Value = BaudRate> {
    proptest::sample::select(BaudRate::ALL.to_vec())
}

fn rotation() -> impl Strategy<Value = Rotation> {
    prop_oneof![Just(Rotation::Ccw), Just(Rotation::Cw)]
}

fn compare() -> impl Strategy<Value = Compare> {
    proptest::sample::select(Compare::ALL.to_vec())
}

fn bounds() -> impl Strategy<Value = Boundaries> {
    (position(), position()).prop_map(|(a, b)| Boundaries::new(a.min(b), a.max(b)).unwrap())
}

fn delay() -> impl Strategy<Value = DelayMs> {
    (0u16..=4095).prop_filter_map("low byte 0xFF", |ms| DelayMs::new(ms).ok())
}

fn instruction() -> impl Strategy<Value = Instruction> {
    prop_oneof![
        Just(Instruction::None),
        (torque(), position())
            .prop_map(|(torque, position)| Instruction::Move { torque, position }),
        Just(Instruction::Motion(MotionType::Passive)),
        Just(Instruction::Motion(MotionType::Break)),
        (rotation(), wheel_speed()).prop_map(|(r, s)| Instruction::Motion(MotionType::Wheel(r, s))),
        delay().prop_map(Instruction::Delay),
        io_bits().prop_map(Instruction::Output),
        (compare(), position()).prop_map(|(c, p)| Instruction::IfPosition(c, p)),
        (compare(), data_byte()).prop_map(|(c, v)| Instruction::IfAdc(c, v)),
        Just(Instruction::Repeat(Repeat::Forever)),
        repeat_count().prop_map(|n| Instruction::Repeat(Repeat::Times(n))),
        Just(Instruction::End),
    ]
}

fn program() -> impl Strategy<Value = Program> {
    proptest::collection::vec(instruction(), 0..=8).prop_map(|v| Program::new(&v).unwrap())
}

fn command() -> impl Strategy<Value = Command> {
    prop_oneof![
        (servo_id(), torque(), position()).prop_map(|(id, torque, position)| Command::Move {
            id,
            torque,
            position
        }),
        (torque(), proptest::collection::vec(position(), 1..=31))
            .prop_map(|(t, p)| Command::SyncMove(SyncMove::new(t, &p).unwrap())),
        servo_id().prop_map(|id| Command::StatusRead { id }),
        servo_id().prop_map(|id| Command::Passive { id }),
        (servo_id(), rotation(), wheel_speed()).prop_map(|(id, rotation, speed)| Command::Wheel {
            id,
            rotation,
            speed
        }),
        Just(Command::Break),
        (servo_id(), baud()).prop_map(|(id, baud)| Command::BaudSet { id, baud }),
        (servo_id(), p_gain(), d_gain()).prop_map(|(id, p, d)| Command::GainSet { id, p, d }),
        servo_id().prop_map(|id| Command::GainRead { id }),
        (servo_id(), i_gain()).prop_map(|(id, i)| Command::IGainSet { id, i }),
        servo_id().prop_map(|id| Command::IGainRead { id }),
        (servo_id(), p_gain(), d_gain()).prop_map(|(id, p, d)| Command::RuntimeGainSet {
            id,
            p,
            d
        }),
        (servo_id(), i_gain()).prop_map(|(id, i)| Command::RuntimeIGainSet { id, i }),
        (servo_id(), ext_id()).prop_map(|(id, new_id)| Command::IdSet { id, new_id }),
        (servo_id(), speed(), accel()).prop_map(|(id, speed, accel)| Command::SpeedSet {
            id,
            speed,
            accel
        }),
        servo_id().prop_map(|id| Command::SpeedRead { id }),
        (servo_id(), speed(), accel()).prop_map(|(id, speed, accel)| Command::RuntimeSpeedSet {
            id,
            speed,
            accel
        }),
        (servo_id(), overload()).prop_map(|(id, overload)| Command::OverloadSet { id, overload }),
        servo_id().prop_map(|id| Command::OverloadRead { id }),
        (servo_id(), bounds()).prop_map(|(id, bounds)| Command::BoundarySet { id, bounds }),
        servo_id().prop_map(|id| Command::BoundaryRead { id }),
        (servo_id(), io_bits()).prop_map(|(id, outputs)| Command::IoWrite { id, outputs }),
        servo_id().prop_map(|id| Command::IoRead { id }),
        (servo_id(), program()).prop_map(|(id, program)| Command::MotionWrite { id, program }),
        servo_id().prop_map(|id| Command::MotionRead { id }),
        (ext_id(), data_byte(), position10()).prop_map(|(id, torque, position)| Command::Move10 {
            id,
            torque,
            position
        }),
        ext_id().prop_map(|id| Command::Read10 { id }),
    ]
}

/// Raw values a device might report, from which [`device_reply`] builds a plausible reply.
#[derive(Debug, Clone)]
struct DeviceState {
    load: Load,
    position: Position,
    rotations: u8,
    id: ServoId,
    p: PGain,
    d: DGain,
    i: IGain,
    speed: Speed,
    accel: Accel,
    overload: Overload,
    bounds: Boundaries,
    outputs: IoBits,
    adc: u8,
    count: MotionCount,
    position10: Position10,
}

fn device_state() -> impl Strategy<Value = DeviceState> {
    (
        (
            load(),
            position(),
            any::<u8>(),
            servo_id(),
            p_gain(),
            d_gain(),
            i_gain(),
        ),
        (
            speed(),
            accel(),
            overload(),
            bounds(),
            io_bits(),
            any::<u8>(),
            0u8..=8,
            position10(),
        ),
    )
        .prop_map(
            |(
                (load, position, rotations, id, p, d, i),
                (speed, accel, overload, bounds, outputs, adc, count, position10),
            )| {
                DeviceState {
                    load,
                    position,
                    rotations,
                    id,
                    p,
                    d,
                    i,
                    speed,
                    accel,
                    overload,
                    bounds,
                    outputs,
                    adc,
                    count: MotionCount::new(count).unwrap(),
                    position10,
                }
            },
        )
}

/// What a well-behaved module answers to `cmd`.
fn device_reply(cmd: &Command, s: &DeviceState) -> Option<Reply> {
    Some(match *cmd {
        Command::Move { .. } | Command::StatusRead { .. } => Reply::Status {
            load: s.load,
            position: s.position,
        },
        Command::Passive { .. } => Reply::Passive {
            position: s.position,
        },
        Command::Wheel { .. } => Reply::Wheel {
            rotations: s.rotations,
            position: s.position,
        },
        Command::Break => Reply::Break {
            id: s.id,
            position: s.position,
        },
        Command::BaudSet { baud, .. } => Reply::Baud(baud),
        Command::GainSet { p, d, .. } | Command::RuntimeGainSet { p, d, .. } => {
            Reply::Gains { p, d }
        }
        Command::GainRead { .. } => Reply::Gains { p: s.p, d: s.d },
        Command::IGainSet { i, .. } | Command::RuntimeIGainSet { i, .. } => Reply::IGain(i),
        Command::IGainRead { .. } => Reply::IGain(s.i),
        Command::IdSet { new_id, .. } => Reply::Id(new_id),
        Command::SpeedSet { speed, accel, .. } => Reply::SpeedAccel { speed, accel },
        Command::SpeedRead { .. } => Reply::SpeedAccel {
            speed: s.speed,
            accel: s.accel,
        },
        Command::OverloadSet { overload, .. } => Reply::Overload(overload),
        Command::OverloadRead { .. } => Reply::Overload(s.overload),
        Command::BoundarySet { bounds, .. } => Reply::Boundaries(bounds),
        Command::BoundaryRead { .. } => Reply::Boundaries(s.bounds),
        Command::IoWrite { outputs, .. } => Reply::Outputs(outputs),
        Command::IoRead { .. } => Reply::Io {
            outputs: s.outputs,
            adc: s.adc,
        },
        Command::MotionWrite { ref program, .. } => Reply::MotionCount(program.count()),
        Command::MotionRead { .. } => Reply::MotionCount(s.count),
        Command::Move10 { .. } | Command::Read10 { .. } => Reply::Position10(s.position10),
        Command::SyncMove(_) | Command::RuntimeSpeedSet { .. } => return None,
    })
}

/// The checksum rule of the wCK protocol notes, written independently of the crate.
fn reference_checksum_ok(packet: &[u8]) -> bool {
    let Some((&cs, body)) = packet.split_last() else {
        return false;
    };
    let sync = body.len() >= 3 && body[1] & 0x1F == 0x1F && body[1] >> 5 <= 4;
    let covered = if sync { &body[3..] } else { &body[1..] };
    covered.iter().fold(0u8, |a, b| a ^ b) & 0x7F == cs
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]

    #[test]
    fn every_command_encodes_then_decodes_device_side_to_itself(cmd in command()) {
        let packet = cmd.encode();
        prop_assert_eq!(packet.len(), cmd.encoded_len());
        prop_assert!(packet.len() <= robobus_wck::MAX_PACKET_LEN);
        prop_assert_eq!(packet[0], 0xFF);
        prop_assert!(packet[1..].iter().all(|&b| b != 0xFF), "0xFF inside {}", packet);
        prop_assert!(reference_checksum_ok(&packet), "checksum of {}", packet);
        prop_assert_eq!(decode_packet(&packet), Ok(cmd));
    }

    #[test]
    fn guard_rails_hold_for_every_command(cmd in command()) {
        let packet = cmd.encode();
        let code = (packet[1] >> 5 == 7).then(|| packet[2]);
        prop_assert_eq!(code == Some(0x0C), matches!(cmd, Command::IdSet { .. }));
        prop_assert_eq!(code == Some(0x09), matches!(cmd, Command::GainSet { .. }));
    }

    #[test]
    fn every_reply_decodes(cmd in command(), state in device_state()) {
        if let Some(reply) = device_reply(&cmd, &state) {
            prop_assert_eq!(cmd.reply_len(), 2);
            prop_assert_eq!(cmd.decode_reply(&reply.to_bytes()), Ok(reply));
        } else {
            prop_assert_eq!(cmd.reply_len(), 0);
        }
    }

    #[test]
    fn arbitrary_reply_bytes_never_panic_and_accepted_ones_re_encode(cmd in command(), a in any::<u8>(), b in any::<u8>(), extra in proptest::collection::vec(any::<u8>(), 0..3)) {
        if let Ok(reply) = cmd.decode_reply(&[a, b]) {
            prop_assert_eq!(cmd.decode_reply(&reply.to_bytes()), Ok(reply));
        }
        if !extra.is_empty() {
            let mut long = vec![a, b];
            long.extend(extra);
            prop_assert!(cmd.decode_reply(&long).is_err());
        }
    }

    #[test]
    fn arbitrary_streams_never_panic_nor_yield_a_bad_checksum(bytes in proptest::collection::vec(any::<u8>(), 0..400)) {
        let mut decoder = StreamDecoder::new();
        for &byte in &bytes {
            if let Some(event) = decoder.push(byte) {
                match event {
                    Ok(cmd) => {
                        let raw = decoder.last_packet();
                        prop_assert!(reference_checksum_ok(raw), "accepted {:02X?}", raw);
                        prop_assert_eq!(raw.len(), cmd.encoded_len());
                    }
                    Err(DecodeError::BadChecksum { computed, received }) => prop_assert_ne!(computed, received),
                    Err(_) => {}
                }
            }
        }
    }

    #[test]
    fn header_heavy_streams_never_panic(bytes in proptest::collection::vec(prop_oneof![Just(0xFFu8), Just(0xE0), Just(0x96), Just(0x1F), Just(0xC8), any::<u8>()], 0..200)) {
        let mut decoder = StreamDecoder::new();
        for &byte in &bytes {
            if let Some(Ok(cmd)) = decoder.push(byte) {
                let raw = decoder.last_packet();
                prop_assert!(reference_checksum_ok(raw), "accepted {:02X?}", raw);
                prop_assert_eq!(raw.len(), cmd.encoded_len());
            }
        }
    }

    #[test]
    fn commands_survive_noise_between_them(cmds in proptest::collection::vec(command(), 1..6), noise in proptest::collection::vec(0u8..=254, 0..5)) {
        let mut stream = noise.clone();
        for cmd in &cmds {
            stream.extend_from_slice(&cmd.encode());
            stream.extend_from_slice(&noise);
        }
        let mut decoder = StreamDecoder::new();
        let decoded: Vec<_> = decoder.feed(&stream).collect();
        let expected: Vec<_> = cmds.iter().copied().map(Ok).collect();
        prop_assert_eq!(decoded, expected);
    }

    #[test]
    fn program_text_round_trips(p in program()) {
        let text = p.to_string();
        prop_assert_eq!(text.parse::<Program>(), Ok(p));
        let bytes: Vec<u8> = p.pairs().flat_map(|(c, d)| [c, d]).collect();
        prop_assert_eq!(Program::from_bytes(&bytes), Ok(p));
    }

    #[test]
    fn program_parser_never_panics(text in "[a-z0-9 =<>#\n\t]{0,80}") {
        let _ = Program::parse(&text);
    }

    #[test]
    fn newtypes_accept_exactly_their_range(raw in any::<u8>()) {
        prop_assert_eq!(Position::new(raw).is_ok(), raw <= 254);
        prop_assert_eq!(ServoId::new(raw).is_ok(), raw <= 30);
        prop_assert_eq!(Accel::new(raw).is_ok(), (20..=100).contains(&raw));
        prop_assert_eq!(Overload::new(raw).is_ok(), (33..=199).contains(&raw));
        prop_assert_eq!(WheelSpeed::new(raw).is_ok(), raw <= 15);
        if let Err(e) = TorqueLevel::new(raw) {
            prop_assert_eq!(e.value, u32::from(raw));
            prop_assert_eq!((e.min, e.max), (0, 4));
        }
    }
}
