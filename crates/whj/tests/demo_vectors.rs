//! Every frame of the usage demo (the vendor's CAN FD usage demo) and of the broadcast
//! protocol's worked examples (V1.1 §二, decoded in the WHJ joint protocol reference §8.11) as test
//! vectors in both directions, with the engineering values the documents state.

// Test and bench code: a failed unwrap is a failed test.
#![allow(clippy::unwrap_used, clippy::panic)]

use robobus_whj::broadcast::{
    BroadcastCurrent, BroadcastPosition, BroadcastRegister, BroadcastStatus,
};
use robobus_whj::registers::addr;
use robobus_whj::units::{Current, CurrentScale, Position, TargetSpeed};
use robobus_whj::{
    BroadcastRegisterReply, CanFrame, JointId, RegisterAddr, RegisterOp, Reply, ReplyMask, Request,
    WorkMode, WriteData, WriteStatus,
};

fn frame(id: u16, data: &[u8]) -> CanFrame {
    CanFrame::new_fd(CanFrame::standard_id(id).unwrap(), data).unwrap()
}

fn j1() -> JointId {
    JointId::new(1).unwrap()
}

/// The request encodes to exactly `wire` and `wire` decodes to exactly the request.
fn request_both_ways(req: Request, id: u16, wire: &[u8]) {
    let f = frame(id, wire);
    assert_eq!(req.to_frame(), f, "encode {req:?}");
    assert_eq!(Request::from_frame(&f).unwrap(), req, "decode {f:?}");
}

/// The reply decodes from `wire` and encodes back to exactly `wire`; returns it.
fn reply_both_ways(id: u16, wire: &[u8]) -> Reply {
    let f = frame(id, wire);
    let reply = Reply::from_frame(&f).unwrap();
    assert_eq!(reply.to_frame(), f, "re-encode {reply:?}");
    reply
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() < 1e-9
}

fn ack(id: u16, index: u8, status: u8) -> (RegisterAddr, WriteStatus) {
    match reply_both_ways(id, &[0x02, index, status]) {
        Reply::WriteAck {
            joint,
            addr,
            status,
        } => {
            assert_eq!(joint.get(), u8::try_from(id & 0xFF).unwrap());
            (addr, status)
        }
        other => panic!("not an ack: {other:?}"),
    }
}

#[test]
fn read_current_position() {
    request_both_ways(
        Request::read(j1(), addr::CUR_POSITION, 2).unwrap(),
        0x001,
        &[0x01, 0x14, 0x02],
    );
    assert_eq!(
        Request::read_position(j1()),
        Request::read(j1(), addr::CUR_POSITION, 2).unwrap()
    );
    let reply = reply_both_ways(0x101, &[0x01, 0x14, 0x10, 0x27, 0x00, 0x00]);
    let Reply::Read {
        joint,
        addr: start,
        words,
    } = reply
    else {
        panic!("{reply:?}")
    };
    assert_eq!(
        (joint, start, words.as_slice()),
        (j1(), addr::CUR_POSITION, &[0x2710, 0][..])
    );
    let pos = Position(reply.read_i32(addr::CUR_POSITION).unwrap());
    assert!(close(pos.degrees(), 1.0), "{pos:?}");
}

#[test]
fn write_target_position_normal_mode() {
    let req = Request::set_target_position(j1(), Position::from_degrees(1.0).unwrap());
    request_both_ways(req, 0x001, &[0x02, 0x36, 0x10, 0x27, 0x00, 0x00]);
    assert_eq!(
        Request::write_i32(j1(), addr::TAG_POSITION, 10_000).unwrap(),
        req
    );
    assert_eq!(
        ack(0x101, 0x36, 0x01),
        (addr::TAG_POSITION, WriteStatus::Ok)
    );
}

#[test]
fn position_servo_mode_1_degree() {
    let req = Request::PositionServo {
        joint: j1(),
        target: Position::from_degrees(1.0).unwrap(),
    };
    request_both_ways(req, 0x201, &[0x10, 0x27, 0x00, 0x00]);
    let wire = [0x64, 0, 0, 0, 0, 0, 0, 0, 0x10, 0x20, 0, 0, 0x01, 0, 0, 0];
    let Reply::ServoFeedback { joint, feedback } = reply_both_ways(0x501, &wire) else {
        panic!()
    };
    assert_eq!(joint, j1());
    assert_eq!(feedback.current.milliamps(CurrentScale::OneMilliamp), 100);
    assert_eq!(feedback.speed.raw(), 0);
    // 0x2010 = 8208 (C23: 0x2710 may have been meant).
    assert!(close(feedback.position.degrees(), 0.8208));
    assert!(feedback.is_enabled());
    assert!(feedback.error.is_empty());
}

#[test]
fn iap_flag_required_operation() {
    request_both_ways(Request::start_application(j1()), 0x001, &[0x02, 0x49, 0x00]);
    assert_eq!(ack(0x101, 0x49, 0x01), (addr::IAP_FLAG, WriteStatus::Ok));
}

#[test]
fn get_joint_status() {
    request_both_ways(Request::StatusQuery { joint: j1() }, 0x601, &[]);
    let wire = [
        0x00, 0x00, 0xFC, 0x08, 0xEA, 0x01, 0x01, 0x00, 0x61, 0x0D, 0x03, 0x00, 0xFA, 0xFF, 0xFF,
        0xFF,
    ];
    let Reply::Status { joint, status } = reply_both_ways(0x701, &wire) else {
        panic!()
    };
    assert_eq!(joint, j1());
    assert!(status.error.is_empty());
    assert_eq!(status.voltage.millivolts(), 23_000);
    assert!((status.voltage.volts() - 23.0).abs() < 1e-4);
    assert!((status.temperature.celsius() - 49.0).abs() < 1e-4);
    assert!(status.is_enabled() && !status.brake_locked());
    assert!(close(status.position.degrees(), 20.0033));
    assert_eq!(
        status.current.unwrap().milliamps(CurrentScale::OneMilliamp),
        -6
    );
}

#[test]
fn old_12_byte_status_is_accepted() {
    let wire = [
        0x00, 0x00, 0xFC, 0x08, 0xEA, 0x01, 0x01, 0x00, 0x61, 0x0D, 0x03, 0x00,
    ];
    let Reply::Status { status, .. } = reply_both_ways(0x701, &wire) else {
        panic!()
    };
    assert_eq!(status.current, None);
    assert!(close(status.position.degrees(), 20.0033));
}

#[test]
fn set_modes() {
    for (mode, byte) in [
        (WorkMode::Position, 3),
        (WorkMode::Current, 1),
        (WorkMode::Speed, 2),
    ] {
        request_both_ways(Request::set_mode(j1(), mode), 0x001, &[0x02, 0x30, byte]);
        assert_eq!(
            ack(0x101, 0x30, 0x01),
            (addr::TAG_WORK_MODE, WriteStatus::Ok)
        );
    }
}

#[test]
fn position_servo_20_to_30_degrees() {
    let req = Request::PositionServo {
        joint: j1(),
        target: Position::from_degrees(30.0).unwrap(),
    };
    request_both_ways(req, 0x201, &[0xE0, 0x93, 0x04, 0x00]);
    let wire = [
        0xC0, 0xFF, 0xFF, 0xFF, 0, 0, 0, 0, 0x40, 0x0D, 0x03, 0x00, 0x01, 0, 0, 0,
    ];
    let Reply::ServoFeedback { feedback, .. } = reply_both_ways(0x501, &wire) else {
        panic!()
    };
    assert_eq!(feedback.current.milliamps(CurrentScale::OneMilliamp), -64);
    assert_eq!(feedback.speed.raw(), 0);
    assert!(close(feedback.position.degrees(), 20.0));
    assert!(feedback.is_enabled() && feedback.error.is_empty());
}

#[test]
fn current_servo_500_ma() {
    let target = Current::from_milliamps(500.0, CurrentScale::OneMilliamp).unwrap();
    request_both_ways(
        Request::CurrentServo {
            joint: j1(),
            target,
        },
        0x401,
        &[0xF4, 0x01, 0x00, 0x00],
    );
    let wire = [
        0xF3, 0xFF, 0xFF, 0xFF, 0x02, 0, 0, 0, 0xBB, 0xB0, 0x09, 0x00, 0x01, 0, 0, 0,
    ];
    let Reply::ServoFeedback { feedback, .. } = reply_both_ways(0x501, &wire) else {
        panic!()
    };
    assert_eq!(feedback.current.milliamps(CurrentScale::OneMilliamp), -13);
    assert!(close(feedback.speed.rpm(), 0.04));
    assert!(close(feedback.position.degrees(), 63.5067));
    // The same bytes on a 2 mA joint (Joint 60): 1000 mA target.
    assert_eq!(target.milliamps(CurrentScale::TwoMilliamps), 1000);
}

#[test]
fn speed_servo_5_rpm() {
    let target = TargetSpeed::from_rpm(5.0).unwrap();
    request_both_ways(
        Request::SpeedServo {
            joint: j1(),
            target,
        },
        0x301,
        &[0xC4, 0x09, 0x00, 0x00],
    );
    assert!(close(target.rpm(), 5.0));
    let wire = [
        0xC0, 0xFF, 0xFF, 0xFF, 0, 0, 0, 0, 0x76, 0x14, 0x03, 0x00, 0x01, 0, 0, 0,
    ];
    let Reply::ServoFeedback { feedback, .. } = reply_both_ways(0x501, &wire) else {
        panic!()
    };
    assert_eq!(feedback.current.raw(), -64);
    assert!(close(feedback.position.degrees(), 20.1846));
}

#[test]
fn clear_error_set_zero_enable_disable() {
    request_both_ways(Request::clear_error(j1()), 0x001, &[0x02, 0x0F, 0x01]);
    assert_eq!(
        ack(0x101, 0x0F, 0x01),
        (addr::SYS_CLEAR_ERROR, WriteStatus::Ok)
    );
    request_both_ways(Request::set_zero(j1()), 0x001, &[0x02, 0x0E, 0x01]);
    assert_eq!(
        ack(0x101, 0x0E, 0x01),
        (addr::SYS_SET_ZERO_POS, WriteStatus::Ok)
    );
    request_both_ways(Request::enable(j1(), true), 0x001, &[0x02, 0x0A, 0x01]);
    request_both_ways(Request::enable(j1(), false), 0x001, &[0x02, 0x0A, 0x00]);
    // Both are acknowledged with status 1.
    assert_eq!(
        ack(0x101, 0x0A, 0x01),
        (addr::SYS_ENABLE_DRIVER, WriteStatus::Ok)
    );
}

#[test]
fn fw519_registers_use_one_byte_writes() {
    for (reg, value) in [(0x69, 1), (0x79, 0), (0x1F, 1)] {
        let addr = RegisterAddr::new(reg).unwrap();
        let req = Request::Write {
            joint: j1(),
            addr,
            data: WriteData::Byte(value),
        };
        request_both_ways(req, 0x001, &[0x02, reg, value]);
        assert!(addr.info().unwrap().firmware.is_some());
    }
}

// ----- broadcast protocol V1.1 worked examples -----

fn bytes(parts: &[&[u8]]) -> Vec<u8> {
    parts.concat()
}

#[test]
fn broadcast_status_query() {
    let wire = bytes(&[&[0; 23], &[0x07]]);
    request_both_ways(
        Request::BroadcastStatus(BroadcastStatus::new(ReplyMask::only(j1()).unwrap())),
        0x7F,
        &wire,
    );
    let fb = [
        0x8F, 0xFF, 0xFF, 0xFF, 0, 0, 0, 0, 0xE0, 0x44, 0x0B, 0, 0, 0, 0xFC, 0x08, 0xFA, 0x00,
        0x01, 0, 0, 0, 0, 0x15,
    ];
    let Reply::BroadcastFeedback { joint, feedback } = reply_both_ways(0x82, &fb) else {
        panic!()
    };
    assert_eq!(joint, j1());
    assert_eq!(feedback.current.raw(), -113);
    assert_eq!(feedback.speed.raw(), 0);
    assert!(close(feedback.position.degrees(), 73.8528));
    assert!(feedback.error.is_empty());
    assert_eq!(feedback.voltage.millivolts(), 23_000);
    assert!((feedback.temperature.celsius() - 25.0).abs() < 1e-4);
    assert!(feedback.is_enabled() && !feedback.brake_locked());
    assert_eq!(feedback.counter, 21);
}

fn register_frame(slot: [u8; 7]) -> Vec<u8> {
    bytes(&[&slot, &[0xFF; 42], &[0xFF], &[0xFF; 13], &[0x07]])
}

#[test]
fn broadcast_register_writes() {
    let cases = [
        (addr::TAG_WORK_MODE, 0x03),
        (addr::TAG_WORK_MODE, 0x01),
        (addr::SYS_CLEAR_ERROR, 0x01),
        (addr::SYS_SET_ZERO_POS, 0x01),
        (addr::SYS_ENABLE_DRIVER, 0x01),
        (addr::SYS_ENABLE_DRIVER, 0x00),
    ];
    for (reg, value) in cases {
        let op = RegisterOp::Write {
            addr: reg,
            data: WriteData::Byte(value),
        };
        let req = BroadcastRegister::new(ReplyMask::only(j1()).unwrap())
            .with_op(j1(), op)
            .unwrap();
        let wire = register_frame([0x03, 0x02, reg.get(), value, 0xFF, 0xFF, 0xFF]);
        request_both_ways(Request::BroadcastRegister(req), 0x0F, &wire);
        let reply = reply_both_ways(0xF2, &[0x02, reg.get(), 0x01]);
        assert_eq!(
            reply,
            Reply::BroadcastRegister {
                joint: j1(),
                reply: BroadcastRegisterReply::WriteAck {
                    addr: reg,
                    status: WriteStatus::Ok
                }
            }
        );
    }
}

#[test]
fn broadcast_position() {
    let no_data = [0xFF, 0xFF, 0xFF, 0x7F, 0xFF, 0xFF, 0xFF, 0xFF];
    let mut wire = vec![0x10, 0x27, 0, 0, 0, 0, 0, 0];
    for _ in 0..6 {
        wire.extend_from_slice(&no_data);
    }
    wire.extend_from_slice(&[0xFF; 7]);
    wire.push(0x07);
    let req = BroadcastPosition::new(ReplyMask::only(j1()).unwrap())
        .with_target(j1(), Position::from_degrees(1.0).unwrap())
        .unwrap();
    request_both_ways(Request::BroadcastPosition(req), 0x2F, &wire);
    let fb = [
        0x20, 0, 0, 0, 0, 0, 0, 0, 0x00, 0x27, 0, 0, 0, 0, 0xFC, 0x08, 0xAE, 0x01, 0x01, 0, 0, 0,
        0, 0x1F,
    ];
    let Reply::BroadcastFeedback { feedback, .. } = reply_both_ways(0x82, &fb) else {
        panic!()
    };
    assert_eq!(feedback.current.raw(), 32);
    assert!(close(feedback.position.degrees(), 0.9984));
    assert!((feedback.temperature.celsius() - 43.0).abs() < 1e-4);
    assert_eq!(feedback.counter, 31);
}

#[test]
fn broadcast_current() {
    let mut wire = vec![0xF4, 0x01, 0x00, 0x00];
    for _ in 0..6 {
        wire.extend_from_slice(&[0xFF, 0xFF, 0xFF, 0x7F]);
    }
    wire.extend_from_slice(&[0xFF; 19]);
    wire.push(0x07);
    let req = BroadcastCurrent::new(ReplyMask::only(j1()).unwrap())
        .with_target(j1(), Current(500))
        .unwrap();
    request_both_ways(Request::BroadcastCurrent(req), 0x4F, &wire);
    let fb = [
        0, 0, 0, 0, 0, 0, 0, 0, 0x36, 0x4E, 0, 0, 0, 0, 0xFC, 0x08, 0xAE, 0x01, 0x01, 0, 0, 0, 0,
        0x27,
    ];
    let Reply::BroadcastFeedback { feedback, .. } = reply_both_ways(0x82, &fb) else {
        panic!()
    };
    assert_eq!(feedback.current.raw(), 0);
    assert!(close(feedback.position.degrees(), 2.0022));
    assert_eq!(feedback.counter, 39);
}

#[test]
fn joint_15_and_broadcast_register_share_0x0f() {
    let j15 = JointId::new(15).unwrap();
    let req = Request::read(j15, addr::SYS_ERROR, 1).unwrap();
    assert_eq!(req.to_frame().raw_id(), 0x0F);
    assert_eq!(Request::from_frame(&req.to_frame()).unwrap(), req);
    let b = Request::BroadcastRegister(BroadcastRegister::new(ReplyMask::NONE));
    assert_eq!(Request::from_frame(&b.to_frame()).unwrap(), b);
}

#[test]
fn padded_read_reply() {
    // 4 registers = 10 bytes, padded to 12: the decoder sees 5 words.
    let range = robobus_whj::ReadRange::new(addr::SIGNATURE, 4).unwrap();
    let reply = Reply::read(j1(), range, &[0x1314, 1, 4, 0xD522]).unwrap();
    let f = reply.to_frame();
    assert_eq!(f.len(), 12);
    let Reply::Read { words, .. } = Reply::from_frame(&f).unwrap() else {
        panic!()
    };
    assert_eq!(words.as_slice(), &[0x1314, 1, 4, 0xD522, 0]);
    assert_eq!(words.truncated(4).as_slice(), &[0x1314, 1, 4, 0xD522]);
}

#[test]
fn typed_register_views() {
    use robobus_whj::units::{FirmwareVersion, Model};
    let identity = Request::read_identity(j1());
    assert_eq!(identity.to_frame().data(), &[0x01, 0x00, 0x04]);
    let range = robobus_whj::ReadRange::new(addr::SIGNATURE, 4).unwrap();
    let reply = Reply::read(j1(), range, &[0x1314, 1, 0x04, 0xD522]).unwrap();
    let reply = Reply::from_frame(&reply.to_frame()).unwrap();
    assert_eq!(reply.model(), Some(Model::Joint60));
    assert_eq!(
        reply.model().unwrap().current_scale(),
        CurrentScale::TwoMilliamps
    );
    assert_eq!(reply.firmware_version(), Some(FirmwareVersion(0xD522)));
    assert_eq!(reply.joint_id_register(), Some(1));
    assert_eq!(reply.actual_position(), None, "not covered by this read");

    let uid = Reply::read(
        j1(),
        robobus_whj::ReadRange::new(addr::MOT_MODEL_ID, 6).unwrap(),
        &[0x1111, 0x2222, 0x3333, 0x4444, 0x5555, 0x6666],
    )
    .unwrap();
    assert_eq!(
        uid.unique_id().unwrap().to_string(),
        "666655554444333322221111"
    );

    let limits = Reply::read(
        j1(),
        robobus_whj::ReadRange::new(addr::LIT_MIN_POSITION, 4).unwrap(),
        &robobus_whj::registers::split_i32(-3_600_000)
            .into_iter()
            .chain(robobus_whj::registers::split_i32(3_600_000))
            .collect::<Vec<_>>(),
    )
    .unwrap();
    let (lo, hi) = limits.position_limits().unwrap();
    assert!(close(lo.degrees(), -360.0) && close(hi.degrees(), 360.0));

    // A malformed frame's CMD_ERR reply, as a joint would send it.
    let bad = Request::from_frame(&frame(0x001, &[0x07, 0x30, 0x01])).unwrap_err();
    assert_eq!(bad.reply().unwrap().to_frame(), frame(0x101, &[0xFF, 0x01]));
}
