use std::string::ToString;

use super::*;
use crate::broadcast::{BroadcastPosition, BroadcastRegister, BroadcastStatus};
use crate::request::WriteData;

fn j(n: u8) -> JointId {
    JointId::new(n).unwrap()
}

#[test]
fn units_are_converted_once_with_the_joints_current_scale() {
    assert_eq!(
        Unit::Current.per_count(CurrentScale::TwoMilliamps),
        Some(2.0)
    );
    assert_eq!(Unit::SpeedLimit.per_count(CurrentScale::OneMilliamp), None);
    assert_eq!(
        Unit::Position.per_count(CurrentScale::OneMilliamp),
        Some(crate::units::POSITION_DEG_PER_COUNT)
    );
    let current = Request::CurrentServo {
        joint: j(2),
        target: crate::units::Current(250),
    };
    assert_eq!(
        current.to_string(),
        "J2 current servo target current 250 counts"
    );
    assert_eq!(
        std::format!("{current:#}"),
        "current servo target current 250 counts"
    );
    assert_eq!(
        current.display(CurrentScale::TwoMilliamps).to_string(),
        "J2 current servo target current 500 mA"
    );
}

#[test]
fn broadcast_frames_are_shown_slot_by_slot() {
    let mask = ReplyMask::only(j(1)).unwrap();
    let mut b = BroadcastPosition::new(mask)
        .with_target(j(1), Position(125_000))
        .unwrap();
    b.slots[2] = Some(crate::broadcast::PositionSlot {
        position: Position(0),
        speed_ff: 5,
        current_ff: 3,
    });
    let r = Request::BroadcastPosition(b);
    assert_eq!(
        r.to_string(),
        "broadcast position: J1 position 12.5000 °, J2 no data, J3 position 0.0000 °, \
         J3 speed feed-forward 0.010 RPM, J3 current feed-forward 6 mA, J4 no data, \
         J5 no data, J6 no data, J7 no data; replies from J1"
    );
    let fields = r.fields(CurrentScale::OneMilliamp);
    assert_eq!(fields.len(), 4);
    assert_eq!(fields.as_slice()[3].raw, 3);
    let reg = BroadcastRegister::new(ReplyMask::new(0).unwrap())
        .with_op(
            j(2),
            RegisterOp::Write {
                addr: registers::addr::SYS_ERROR,
                data: WriteData::Word(0x0002),
            },
        )
        .unwrap();
    let reg = Request::BroadcastRegister(reg);
    assert_eq!(
        reg.to_string(),
        "broadcast register: J2 write SYS_ERROR 2; no replies asked"
    );
    let fields = reg.fields(CurrentScale::OneMilliamp);
    assert_eq!(fields.as_slice()[0].to_string(), "J2 SYS_ERROR 2");
    assert_eq!(
        fields.errors().collect::<std::vec::Vec<_>>(),
        ["over-voltage"]
    );
    assert_eq!(
        Request::BroadcastStatus(BroadcastStatus::new(mask)).to_string(),
        "broadcast status query; replies from J1"
    );
}

#[test]
fn registers_are_named_in_their_units_and_reserved_ones_by_address() {
    let write = Request::Write {
        joint: j(1),
        addr: RegisterAddr::new(0x05).unwrap(),
        data: WriteData::Pair(0x0001_FFFF),
    };
    assert_eq!(
        write.to_string(),
        "J1 write SYS_VOLTAGE -0.01 V, SYS_TEMP 0.1 °C"
    );
    let reply = Reply::Read {
        joint: j(1),
        addr: RegisterAddr::new(0x14).unwrap(),
        words: crate::Words::from_slice(&[0x86A0, 0x0001, 7]).unwrap(),
    };
    assert_eq!(
        reply.to_string(),
        "J1 read reply: CUR_POSITION 10.0000 °, 0x16 7"
    );
    assert_eq!(
        Reply::WriteAck {
            joint: j(1),
            addr: registers::addr::SYS_ENABLE_DRIVER,
            status: WriteStatus::Unknown(5),
        }
        .to_string(),
        "J1 write ack SYS_ENABLE_DRIVER: unknown(5)"
    );
}
