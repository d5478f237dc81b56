//! Every example packet of the manual's appendix A-1, host side (encode) and device side
//! (decode), with its reply where the manual prints one.
//!
//! Four examples print a wrong checksum; they are tested at the value the manual's own
//! formula gives, and the printed packet must be refused. See
//! the wCK protocol notes, "Misprints in the manual".

#![allow(clippy::unwrap_used)] // test and bench set-up: a failed unwrap is a failed run

use robobus_wck::program::Program;
use robobus_wck::{
    Accel, BaudRate, Boundaries, Command, DGain, DataByte, DecodeError, ExtServoId, IGain, IoBits,
    Load, MotionCount, Overload, PGain, Position, Position10, Reply, ReplyError, Rotation, ServoId,
    Speed, SyncMove, TorqueLevel, ValueError, WheelSpeed, decode_packet,
};

fn id0() -> ServoId {
    ServoId::new(0).unwrap()
}

fn pos(raw: u8) -> Position {
    Position::new(raw).unwrap()
}

/// Host encodes exactly `bytes`; device decodes `bytes` back to the same command.
#[track_caller]
fn vector(command: Command, bytes: &[u8]) {
    let packet = command.encode();
    assert_eq!(packet.as_bytes(), bytes, "{command}: encoded {packet}");
    assert_eq!(command.encoded_len(), bytes.len(), "{command}");
    assert_eq!(decode_packet(bytes), Ok(command), "{command}: device side");
}

/// A packet as printed with a wrong checksum: the device refuses it and names both values.
#[track_caller]
fn misprint(printed: &[u8], correct: u8) {
    let received = *printed.last().unwrap();
    assert_eq!(
        decode_packet(printed),
        Err(DecodeError::BadChecksum {
            computed: correct,
            received
        })
    );
}

#[test]
fn a1_1_position_move() {
    let cmd = Command::Move {
        id: id0(),
        torque: TorqueLevel::new(0).unwrap(),
        position: pos(0x7F),
    };
    vector(cmd, &[0xFF, 0x00, 0x7F, 0x7F]);
    assert_eq!(
        cmd.decode_reply(&[0x05, 0x7E]),
        Ok(Reply::Status {
            load: Load::new(5).unwrap(),
            position: pos(0x7E)
        })
    );
}

#[test]
fn a1_2_synchronized_position_move() {
    let cmd = Command::SyncMove(
        SyncMove::new(TorqueLevel::new(0).unwrap(), &[pos(0x7F), pos(0x7F)]).unwrap(),
    );
    // The checksum covers only the position bytes: 0x7F ^ 0x7F = 0x00.
    vector(cmd, &[0xFF, 0x1F, 0x02, 0x7F, 0x7F, 0x00]);
    assert_eq!(cmd.reply_len(), 0);
    assert_eq!(
        cmd.decode_reply(&[1, 2]),
        Err(ReplyError::NoReply {
            command: "synchronized position move"
        })
    );
}

#[test]
fn a1_3_status_read() {
    vector(Command::StatusRead { id: id0() }, &[0xFF, 0xA0, 0x00, 0x20]);
}

#[test]
fn a1_4_passive() {
    let cmd = Command::Passive { id: id0() };
    vector(cmd, &[0xFF, 0xC0, 0x10, 0x50]);
    assert_eq!(
        cmd.decode_reply(&[0x10, 0x40]),
        Ok(Reply::Passive {
            position: pos(0x40)
        })
    );
    assert_eq!(
        cmd.decode_reply(&[0x11, 0x40]),
        Err(ReplyError::Echo {
            command: "passive",
            what: "mode byte",
            sent: 0x10,
            received: 0x11
        })
    );
}

#[test]
fn a1_5_wheel() {
    let cmd = Command::Wheel {
        id: id0(),
        rotation: Rotation::Ccw,
        speed: WheelSpeed::new(15).unwrap(),
    };
    vector(cmd, &[0xFF, 0xC0, 0x3F, 0x7F]);
    assert_eq!(
        cmd.decode_reply(&[0xFF, 0x10]),
        Ok(Reply::Wheel {
            rotations: 255,
            position: pos(0x10)
        })
    );
}

#[test]
fn a1_6_break() {
    let cmd = Command::Break;
    vector(cmd, &[0xFF, 0xDF, 0x20, 0x7F]);
    assert_eq!(
        cmd.decode_reply(&[0x00, 0x33]),
        Ok(Reply::Break {
            id: id0(),
            position: pos(0x33)
        })
    );
    // The A-4 sample treats an answering ID of 31 or more as a receive error.
    assert!(matches!(
        cmd.decode_reply(&[31, 0x33]),
        Err(ReplyError::Invalid { .. })
    ));
}

#[test]
fn a1_7_baud_rate_set_and_its_reply_slip() {
    let cmd = Command::BaudSet {
        id: id0(),
        baud: BaudRate::B115200,
    };
    vector(cmd, &[0xFF, 0xE0, 0x08, 0x07, 0x07, 0x68]);
    // The manual prints the reply as 03 03, but the reply echoes the new code, 07 07
    // (the wCK protocol notes, "Other slips", (7)).
    assert_eq!(
        cmd.decode_reply(&[0x07, 0x07]),
        Ok(Reply::Baud(BaudRate::B115200))
    );
    assert_eq!(
        cmd.decode_reply(&[0x03, 0x03]),
        Err(ReplyError::Echo {
            command: "baud rate set",
            what: "baud code",
            sent: 7,
            received: 3
        })
    );
}

#[test]
fn a1_8_gain_set() {
    let cmd = Command::GainSet {
        id: id0(),
        p: PGain::new(100).unwrap(),
        d: DGain::new(100).unwrap(),
    };
    vector(cmd, &[0xFF, 0xE0, 0x09, 0x64, 0x64, 0x69]);
    assert_eq!(
        cmd.decode_reply(&[0x64, 0x64]),
        Ok(Reply::Gains {
            p: PGain::new(100).unwrap(),
            d: DGain::new(100).unwrap()
        })
    );
}

#[test]
fn a1_9_gain_read() {
    let cmd = Command::GainRead { id: id0() };
    vector(cmd, &[0xFF, 0xE0, 0x0A, 0x00, 0x00, 0x6A]);
    assert_eq!(
        cmd.decode_reply(&[20, 30]),
        Ok(Reply::Gains {
            p: PGain::DEFAULT,
            d: DGain::DEFAULT
        })
    );
    // P gain 0 is out of range: not a plausible reply.
    assert!(matches!(
        cmd.decode_reply(&[0, 30]),
        Err(ReplyError::Invalid { .. })
    ));
}

#[test]
fn a1_10_i_gain_set() {
    // The example sets 100 although the recommended range is 0..=10 (notes, "Other slips").
    let i = IGain::new(100).unwrap();
    assert!(!i.is_recommended());
    let cmd = Command::IGainSet { id: id0(), i };
    vector(cmd, &[0xFF, 0xE0, 0x15, 0x64, 0x64, 0x75]);
    assert_eq!(cmd.decode_reply(&[0x64, 0x64]), Ok(Reply::IGain(i)));
}

#[test]
fn a1_11_i_gain_read() {
    let cmd = Command::IGainRead { id: id0() };
    vector(cmd, &[0xFF, 0xE0, 0x16, 0x00, 0x00, 0x76]);
    assert_eq!(
        cmd.decode_reply(&[3, 4]),
        Err(ReplyError::Unequal {
            command: "I gain read",
            first: 3,
            second: 4
        })
    );
}

#[test]
fn a1_12_runtime_gain_set_misprinted_checksum() {
    let cmd = Command::RuntimeGainSet {
        id: id0(),
        p: PGain::new(100).unwrap(),
        d: DGain::new(100).unwrap(),
    };
    // Misprint: the manual prints checksum 0x69; (0xE0 ^ 0x0B ^ 0x64 ^ 0x64) & 0x7F = 0x6B.
    vector(cmd, &[0xFF, 0xE0, 0x0B, 0x64, 0x64, 0x6B]);
    misprint(&[0xFF, 0xE0, 0x0B, 0x64, 0x64, 0x69], 0x6B);
    assert!(cmd.decode_reply(&[0x64, 0x64]).is_ok());
}

#[test]
fn a1_13_runtime_i_gain_set() {
    let cmd = Command::RuntimeIGainSet {
        id: id0(),
        i: IGain::new(4).unwrap(),
    };
    vector(cmd, &[0xFF, 0xE0, 0x18, 0x04, 0x04, 0x78]);
    assert_eq!(
        cmd.decode_reply(&[0x04, 0x04]),
        Ok(Reply::IGain(IGain::new(4).unwrap()))
    );
}

#[test]
fn a1_14_id_set() {
    let new_id = ExtServoId::new(30).unwrap();
    let cmd = Command::IdSet { id: id0(), new_id };
    vector(cmd, &[0xFF, 0xE0, 0x0C, 0x1E, 0x1E, 0x6C]);
    assert_eq!(cmd.decode_reply(&[0x1E, 0x1E]), Ok(Reply::Id(new_id)));
    assert_eq!(
        cmd.decode_reply(&[0x00, 0x00]),
        Err(ReplyError::Echo {
            command: "ID set",
            what: "new id",
            sent: 30,
            received: 0
        })
    );
}

#[test]
fn a1_15_speed_set_misprinted_checksum() {
    let cmd = Command::SpeedSet {
        id: id0(),
        speed: Speed::new(30).unwrap(),
        accel: Accel::new(100).unwrap(),
    };
    // Misprint: the manual prints 0x1D; (0xE0 ^ 0x0D ^ 0x1E ^ 0x64) & 0x7F = 0x17.
    vector(cmd, &[0xFF, 0xE0, 0x0D, 0x1E, 0x64, 0x17]);
    misprint(&[0xFF, 0xE0, 0x0D, 0x1E, 0x64, 0x1D], 0x17);
    assert!(cmd.decode_reply(&[0x1E, 0x64]).is_ok());
}

#[test]
fn a1_16_speed_read() {
    let cmd = Command::SpeedRead { id: id0() };
    vector(cmd, &[0xFF, 0xE0, 0x0E, 0x00, 0x00, 0x6E]);
    assert_eq!(
        cmd.decode_reply(&[0, 60]),
        Ok(Reply::SpeedAccel {
            speed: Speed::DEFAULT,
            accel: Accel::DEFAULT
        })
    );
    assert!(matches!(
        cmd.decode_reply(&[0, 19]),
        Err(ReplyError::Invalid { .. })
    ));
}

#[test]
fn a1_17_runtime_speed_set_has_no_reply() {
    let cmd = Command::RuntimeSpeedSet {
        id: id0(),
        speed: Speed::new(30).unwrap(),
        accel: Accel::new(100).unwrap(),
    };
    vector(cmd, &[0xFF, 0xE0, 0x17, 0x1E, 0x64, 0x0D]);
    assert_eq!(cmd.reply_len(), 0);
}

#[test]
fn a1_18_overload_set() {
    let overload = Overload::from_milliamps(1000).unwrap();
    assert_eq!(overload.get(), 104);
    let cmd = Command::OverloadSet {
        id: id0(),
        overload,
    };
    vector(cmd, &[0xFF, 0xE0, 0x0F, 0x68, 0x68, 0x6F]);
    assert_eq!(
        cmd.decode_reply(&[0x68, 0x68]),
        Ok(Reply::Overload(overload))
    );
}

#[test]
fn a1_19_overload_read() {
    let cmd = Command::OverloadRead { id: id0() };
    vector(cmd, &[0xFF, 0xE0, 0x10, 0x00, 0x00, 0x70]);
    assert_eq!(
        cmd.decode_reply(&[33, 33]),
        Ok(Reply::Overload(Overload::DEFAULT))
    );
    assert!(matches!(
        cmd.decode_reply(&[32, 32]),
        Err(ReplyError::Invalid { .. })
    ));
}

#[test]
fn a1_20_boundary_set_misprinted_checksum_and_inverted_bounds() {
    // The manual's example sets lower 100 > upper 50. robobus will not build that...
    assert_eq!(
        Boundaries::new(pos(100), pos(50)),
        Err(ValueError::InvertedBoundaries {
            lower: 100,
            upper: 50
        })
    );
    // ...and a device refuses it after the checksum (misprint: the manual prints 0x20;
    // (0xE0 ^ 0x11 ^ 0x64 ^ 0x32) & 0x7F = 0x27).
    misprint(&[0xFF, 0xE0, 0x11, 0x64, 0x32, 0x20], 0x27);
    assert_eq!(
        decode_packet(&[0xFF, 0xE0, 0x11, 0x64, 0x32, 0x27]),
        Err(DecodeError::InvalidField {
            command: "boundary set",
            error: ValueError::InvertedBoundaries {
                lower: 100,
                upper: 50
            }
        })
    );
    // The same two values in order give the same (correct) checksum 0x27.
    let bounds = Boundaries::new(pos(50), pos(100)).unwrap();
    let cmd = Command::BoundarySet { id: id0(), bounds };
    vector(cmd, &[0xFF, 0xE0, 0x11, 0x32, 0x64, 0x27]);
    assert_eq!(
        cmd.decode_reply(&[0x32, 0x64]),
        Ok(Reply::Boundaries(bounds))
    );
}

#[test]
fn a1_21_boundary_read() {
    let cmd = Command::BoundaryRead { id: id0() };
    vector(cmd, &[0xFF, 0xE0, 0x12, 0x00, 0x00, 0x72]);
    assert_eq!(
        cmd.decode_reply(&[1, 254]),
        Ok(Reply::Boundaries(Boundaries::DEFAULT))
    );
    assert!(matches!(
        cmd.decode_reply(&[200, 100]),
        Err(ReplyError::Invalid { .. })
    ));
}

#[test]
fn a1_22_io_write() {
    let outputs = IoBits::from_outputs(true, true);
    let cmd = Command::IoWrite { id: id0(), outputs };
    vector(cmd, &[0xFF, 0xE0, 0x64, 0x03, 0x03, 0x04]);
    assert_eq!(cmd.decode_reply(&[0x03, 0x03]), Ok(Reply::Outputs(outputs)));
}

#[test]
fn a1_23_io_read_misprinted_checksum() {
    let cmd = Command::IoRead { id: id0() };
    // Misprint: the manual prints 0x04; (0xE0 ^ 0x65) & 0x7F = 0x05.
    vector(cmd, &[0xFF, 0xE0, 0x65, 0x00, 0x00, 0x05]);
    misprint(&[0xFF, 0xE0, 0x65, 0x00, 0x00, 0x04], 0x05);
    assert_eq!(
        cmd.decode_reply(&[0xFE, 0xFF]),
        Ok(Reply::Io {
            outputs: IoBits::new(2).unwrap(),
            adc: 255
        })
    );
}

#[test]
fn a1_24_motion_data_write() {
    let program =
        Program::parse("move 82 torque 0\ndelay 266ms\nmove 172 torque 0\ndelay 266ms").unwrap();
    let cmd = Command::MotionWrite { id: id0(), program };
    vector(
        cmd,
        &[
            0xFF, 0xE0, 0x96, 0x04, 0x10, 0x52, 0x31, 0x0A, 0x10, 0xAC, 0x31, 0x0A, 0x0C,
        ],
    );
    assert_eq!(
        cmd.decode_reply(&[0x04, 0x04]),
        Ok(Reply::MotionCount(MotionCount::new(4).unwrap()))
    );
    assert!(cmd.decode_reply(&[0x03, 0x03]).is_err());
}

#[test]
fn a1_25_motion_data_read() {
    let cmd = Command::MotionRead { id: id0() };
    vector(cmd, &[0xFF, 0xE0, 0x97, 0x00, 0x00, 0x77]);
    assert!(matches!(
        cmd.decode_reply(&[9, 9]),
        Err(ReplyError::Invalid { .. })
    ));
}

#[test]
fn a1_26_ten_bit_position_move() {
    let position = Position10::new(1000).unwrap();
    let cmd = Command::Move10 {
        id: ExtServoId::new(0).unwrap(),
        torque: DataByte::new(0).unwrap(),
        position,
    };
    vector(cmd, &[0xFF, 0xE0, 0xC8, 0x00, 0x00, 0x07, 0xD0, 0x7F]);
    assert_eq!(
        cmd.decode_reply(&[0x07, 0xD0]),
        Ok(Reply::Position10(position))
    );
    assert!(matches!(
        cmd.decode_reply(&[0x08, 0x00]),
        Err(ReplyError::Invalid { .. })
    ));
}

#[test]
fn a1_27_ten_bit_position_read_uses_the_table_checksum_rule() {
    let cmd = Command::Read10 {
        id: ExtServoId::new(0).unwrap(),
    };
    vector(cmd, &[0xFF, 0xE0, 0xC9, 0x00, 0x00, 0x29]);
    // The example's note says byte2 ^ byte3 ^ byte5; the protocol table says bytes 2..N.
    // They only agree for ID 0. With ID 100 the table's rule gives 0x29, the note's 0x4D.
    let id = ExtServoId::new(100).unwrap();
    vector(Command::Read10 { id }, &[0xFF, 0xE0, 0xC9, 100, 100, 0x29]);
    misprint(
        &[0xFF, 0xE0, 0xC9, 100, 100, (0xE0 ^ 0xC9 ^ 0x64) & 0x7F],
        0x29,
    );
}

#[test]
fn architecture_data_flow_example() {
    // `robobus wck move 3 127` encodes FF 03 7F 7C (architecture.md).
    let cmd = Command::Move {
        id: ServoId::new(3).unwrap(),
        torque: TorqueLevel::new(0).unwrap(),
        position: pos(127),
    };
    vector(cmd, &[0xFF, 0x03, 0x7F, 0x7C]);
}

/// One command of each of the 27 kinds.
fn one_of_each() -> [Command; 27] {
    let id = ServoId::new(7).unwrap();
    let ext = ExtServoId::new(200).unwrap();
    [
        Command::Move {
            id,
            torque: TorqueLevel::new(2).unwrap(),
            position: pos(12),
        },
        Command::SyncMove(SyncMove::new(TorqueLevel::MAX, &[pos(12); 31]).unwrap()),
        Command::StatusRead { id },
        Command::Passive { id },
        Command::Wheel {
            id,
            rotation: Rotation::Cw,
            speed: WheelSpeed::new(12).unwrap(),
        },
        Command::Break,
        Command::BaudSet {
            id,
            baud: BaudRate::B4800,
        },
        Command::GainSet {
            id,
            p: PGain::new(12).unwrap(),
            d: DGain::new(12).unwrap(),
        },
        Command::GainRead { id },
        Command::IGainSet {
            id,
            i: IGain::new(12).unwrap(),
        },
        Command::IGainRead { id },
        Command::RuntimeGainSet {
            id,
            p: PGain::new(12).unwrap(),
            d: DGain::new(12).unwrap(),
        },
        Command::RuntimeIGainSet {
            id,
            i: IGain::new(12).unwrap(),
        },
        Command::IdSet {
            id,
            new_id: ExtServoId::new(12).unwrap(),
        },
        Command::SpeedSet {
            id,
            speed: Speed::new(12).unwrap(),
            accel: Accel::new(20).unwrap(),
        },
        Command::SpeedRead { id },
        Command::RuntimeSpeedSet {
            id,
            speed: Speed::new(9).unwrap(),
            accel: Accel::new(20).unwrap(),
        },
        Command::OverloadSet {
            id,
            overload: Overload::new(44).unwrap(),
        },
        Command::OverloadRead { id },
        Command::BoundarySet {
            id,
            bounds: Boundaries::new(pos(12), pos(12)).unwrap(),
        },
        Command::BoundaryRead { id },
        Command::IoWrite {
            id,
            outputs: IoBits::new(3).unwrap(),
        },
        Command::IoRead { id },
        Command::MotionWrite {
            id,
            program: Program::parse("move 12 torque 0\nmove 9 torque 0").unwrap(),
        },
        Command::MotionRead { id },
        Command::Move10 {
            id: ext,
            torque: DataByte::new(12).unwrap(),
            position: Position10::new(12).unwrap(),
        },
        Command::Read10 { id: ext },
    ]
}

#[test]
fn guard_rails_only_id_set_sends_0x0c_and_only_gain_set_sends_0x09() {
    // The A-4 sample sends 0x0C from GainRead and 0x0A from IdSet; public libraries copied
    // it and renamed servos while reading gains. Here each code has exactly one command.
    let commands = one_of_each();
    let mut names: Vec<&str> = commands.iter().map(Command::name).collect();
    names.sort_unstable();
    names.dedup();
    assert_eq!(names.len(), 27, "27 distinct commands");
    for cmd in commands {
        let packet = cmd.encode();
        assert_eq!(decode_packet(&packet), Ok(cmd), "{cmd}");
        let is_set_family = packet[1] >> 5 == 7;
        let code = if is_set_family { Some(packet[2]) } else { None };
        assert_eq!(code, cmd.code(), "{cmd}");
        assert_eq!(
            code == Some(0x0C),
            matches!(cmd, Command::IdSet { .. }),
            "{cmd}: {packet}"
        );
        assert_eq!(
            code == Some(0x09),
            matches!(cmd, Command::GainSet { .. }),
            "{cmd}: {packet}"
        );
    }
    assert_eq!(Command::GainRead { id: id0() }.encode()[2], 0x0A);
}

#[test]
fn device_side_errors_are_values() {
    // Unknown code.
    assert_eq!(
        decode_packet(&[0xFF, 0xE0, 0x13, 0, 0, 0x73]),
        Err(DecodeError::UnknownCode { code: 0x13 })
    );
    // Truncated: a header arrives mid-packet; the new packet then decodes.
    let mut d = robobus_wck::StreamDecoder::new();
    let events: Vec<_> = d
        .feed(&[0xFF, 0xE0, 0x0A, 0xFF, 0xA0, 0x00, 0x20])
        .collect();
    assert_eq!(
        events,
        [
            Err(DecodeError::Truncated {
                received: 3,
                expected: Some(6)
            }),
            Ok(Command::StatusRead { id: id0() })
        ]
    );
    // A 0xFF where the checksum belongs is a new header too.
    let events: Vec<_> = d.feed(&[0xFF, 0xA0, 0x00, 0xFF]).collect();
    assert_eq!(
        events,
        [Err(DecodeError::Truncated {
            received: 3,
            expected: Some(4)
        })]
    );
    assert!(!d.is_idle());
    d.reset();
}

#[test]
fn device_side_field_errors_are_values() {
    // Status read to the broadcast ID and an undefined mode-6 nibble.
    assert_eq!(
        decode_packet(&[0xFF, 0xBF, 0x00, 0x3F]),
        Err(DecodeError::UnknownOperation { d1: 0xBF, d2: 0 })
    );
    assert_eq!(
        decode_packet(&[0xFF, 0xC0, 0x70, 0x30]),
        Err(DecodeError::UnknownOperation { d1: 0xC0, d2: 0x70 })
    );
    // Field values: P gain 0, baud code 2, ID set copies that differ, 10-bit ID 254.
    assert!(matches!(
        decode_packet(&[0xFF, 0xE0, 0x09, 0, 5, 0x6C]),
        Err(DecodeError::InvalidField {
            command: "P, D gain set",
            ..
        })
    ));
    assert_eq!(
        decode_packet(&[0xFF, 0xE0, 0x08, 2, 2, 0x68]),
        Err(DecodeError::InvalidField {
            command: "baud rate set",
            error: ValueError::BaudCode { code: 2 }
        })
    );
    assert_eq!(
        decode_packet(&[0xFF, 0xE0, 0x0C, 1, 2, (0xE0 ^ 0x0C ^ 1 ^ 2) & 0x7F]),
        Err(DecodeError::Mismatch {
            command: "ID set",
            first: 1,
            second: 2
        })
    );
    assert!(matches!(
        decode_packet(&[0xFF, 0xE0, 0xC9, 254, 254, 0x29]),
        Err(DecodeError::InvalidField { .. })
    ));
    // Motion write with 9 instructions, sync move to 0 servos.
    assert!(matches!(
        decode_packet(&[0xFF, 0xE0, 0x96, 9]),
        Err(DecodeError::InvalidField {
            command: "motion data write",
            ..
        })
    ));
    assert!(matches!(
        decode_packet(&[0xFF, 0x1F, 0x00]),
        Err(DecodeError::InvalidField {
            command: "synchronized position move",
            ..
        })
    ));
    // A bad instruction inside a motion write.
    let body = [0xE0, 0x96, 0x01, 0x90, 0x00];
    let cs = robobus_wck::xor7(&body);
    let mut packet = vec![0xFF];
    packet.extend_from_slice(&body);
    packet.push(cs);
    assert_eq!(
        decode_packet(&packet),
        Err(DecodeError::BadInstruction {
            index: 0,
            error: robobus_wck::program::InstructionError::UnknownMain {
                command: 0x90,
                main: 9
            }
        })
    );
    // Error messages carry the facts.
    assert_eq!(
        DecodeError::BadChecksum {
            computed: 0x6B,
            received: 0x69
        }
        .to_string(),
        "bad checksum: computed 0x6b, received 0x69"
    );
    assert_eq!(
        DecodeError::Truncated {
            received: 3,
            expected: Some(6)
        }
        .to_string(),
        "truncated packet: new header after 3 bytes of 6"
    );
}
