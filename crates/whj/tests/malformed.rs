//! Device-side rejection of malformed requests (what a joint answers with `CMD_ERR`),
//! host-side rejection of malformed replies, and host-side refusal of bad input.

// Test and bench code: a failed unwrap is a failed test.
#![allow(clippy::unwrap_used, clippy::panic)]

use robobus_whj::registers::addr;
use robobus_whj::{
    CanFrame, CmdError, Function, JointId, MalformedReason, RegisterAddr, Reply, ReplyErrorReason,
    Request, RequestError, WriteData,
};

fn frame(id: u16, data: &[u8]) -> CanFrame {
    CanFrame::new_fd(CanFrame::standard_id(id).unwrap(), data).unwrap()
}

fn j1() -> JointId {
    JointId::new(1).unwrap()
}

fn reason(id: u16, data: &[u8]) -> MalformedReason {
    Request::from_frame(&frame(id, data)).unwrap_err().reason
}

#[test]
fn format_errors() {
    let cases: [(&[u8], MalformedReason); 9] = [
        (&[0x01, 0x14], MalformedReason::TooShort { len: 2 }),
        (&[], MalformedReason::TooShort { len: 0 }),
        (
            &[0x03, 0x14, 0x02],
            MalformedReason::UnknownCommand { cmd: 0x03 },
        ),
        (&[0x01, 0x14, 0x00], MalformedReason::ReadCount { count: 0 }),
        (&[0x01, 0x14, 32], MalformedReason::ReadCount { count: 32 }),
        (
            &[0x01, 0x90, 0x03],
            MalformedReason::ReadPastEnd {
                addr: 0x90,
                count: 3,
            },
        ),
        (
            &[0x01, 0x14, 0x02, 0x00],
            MalformedReason::ReadLength { len: 4 },
        ),
        (
            &[0x02, 0x30, 0x03, 0x00, 0x00],
            MalformedReason::WriteLength { data_len: 3 },
        ),
        (
            &[0x02, 0xA0, 0x01],
            MalformedReason::AddressOutOfTable { addr: 0xA0 },
        ),
    ];
    for (data, want) in cases {
        let err = Request::from_frame(&frame(0x001, data)).unwrap_err();
        assert_eq!(err.reason, want, "{data:02X?}");
        assert_eq!(
            err.response(),
            Some((j1(), CmdError::Format)),
            "{data:02X?}"
        );
    }
    // A 4-byte write at the last address would spill past the table.
    assert_eq!(
        reason(0x001, &[0x02, 0x91, 1, 2, 3, 4]),
        MalformedReason::AddressOutOfTable { addr: 0x92 }
    );
    assert_eq!(
        reason(0x201, &[0x10, 0x27, 0x00]),
        MalformedReason::ServoLength {
            function: Function::PositionServo,
            len: 3
        }
    );
    assert_eq!(
        reason(0x601, &[0x00]),
        MalformedReason::StatusQueryLength { len: 1 }
    );
}

#[test]
fn permission_error_for_read_only_registers() {
    let err = Request::from_frame(&frame(0x003, &[0x02, 0x14, 0x00, 0x00])).unwrap_err();
    assert_eq!(err.reason, MalformedReason::ReadOnly { addr: 0x14 });
    assert_eq!(
        err.response(),
        Some((JointId::new(3).unwrap(), CmdError::Permission))
    );
    // A pair write whose high word is read-only.
    assert_eq!(
        reason(0x001, &[0x02, 0x15, 0, 0, 0, 0]),
        MalformedReason::ReadOnly { addr: 0x15 }
    );
    // decode() skips the access check.
    let req = Request::decode(&frame(0x001, &[0x02, 0x14, 0x00, 0x00])).unwrap();
    assert_eq!(
        req,
        Request::Write {
            joint: j1(),
            addr: addr::CUR_POSITION,
            data: WriteData::Word(0)
        }
    );
    // Reserved addresses are not errors (the joint acknowledges them with "failed").
    assert!(Request::from_frame(&frame(0x001, &[0x02, 0x16, 0x01])).is_ok());
}

#[test]
fn silently_ignored_frames() {
    let ignored = |f: CanFrame, want: MalformedReason| {
        let err = Request::from_frame(&f).unwrap_err();
        assert_eq!(err.reason, want, "{f:?}");
        assert_eq!(err.response(), None, "{f:?}");
    };
    ignored(
        frame(0x101, &[0x02, 0x30, 0x01]),
        MalformedReason::NotARequest,
    );
    ignored(frame(0x501, &[0; 16]), MalformedReason::NotARequest);
    ignored(
        frame(0x000, &[0x01, 0x14, 0x02]),
        MalformedReason::InterfaceBoard,
    );
    ignored(
        frame(0x01F, &[0x01, 0x14, 0x02]),
        MalformedReason::NotARequest,
    ); // node 31
    ignored(
        frame(0x2F, &[0; 48]),
        MalformedReason::BroadcastLength {
            len: 48,
            expected: 64,
        },
    );
    ignored(
        CanFrame::new_classic(CanFrame::standard_id(0x001).unwrap(), &[0x01, 0x14, 0x02]).unwrap(),
        MalformedReason::ClassicFrame,
    );
    ignored(
        CanFrame::new_fd(CanFrame::extended_id(0x001).unwrap(), &[0x01, 0x14, 0x02]).unwrap(),
        MalformedReason::ExtendedId,
    );
}

#[test]
fn errors_name_value_and_range() {
    let msg = Request::from_frame(&frame(0x001, &[0x01, 0x14, 40]))
        .unwrap_err()
        .to_string();
    assert!(
        msg.contains("40") && msg.contains("1..=31") && msg.contains("0x001"),
        "{msg}"
    );
    let msg = Request::write(j1(), addr::TAG_WORK_MODE, 7)
        .unwrap_err()
        .to_string();
    assert!(
        msg.contains('7') && msg.contains("0..=3") && msg.contains("TAG_WORK_MODE"),
        "{msg}"
    );
    let msg = RegisterAddr::new(0xA0).unwrap_err().to_string();
    assert!(msg.contains("0xa0") && msg.contains("0x91"), "{msg}");
}

#[test]
fn host_refuses_bad_requests() {
    assert_eq!(
        Request::read(j1(), addr::SIGNATURE, 0),
        Err(RequestError::ReadCount { count: 0, max: 31 })
    );
    assert_eq!(
        Request::read(j1(), RegisterAddr::new(0x80).unwrap(), 31),
        Err(RequestError::ReadPastEnd {
            addr: 0x80,
            count: 31
        })
    );
    assert_eq!(
        Request::write(j1(), addr::SYS_MODEL_TYPE, 2),
        Err(RequestError::ReadOnly {
            addr: 0x02,
            name: "SYS_MODEL_TYPE"
        })
    );
    assert_eq!(
        Request::write(j1(), addr::TAG_POSITION, 1),
        Err(RequestError::HalfOfPair { addr: 0x36 })
    );
    assert_eq!(
        Request::write_i32(j1(), addr::TAG_WORK_MODE, 1),
        Err(RequestError::NotAPair { addr: 0x30 })
    );
    assert!(matches!(
        Request::write(j1(), addr::SYS_ID, 31),
        Err(RequestError::ValueOutOfRange {
            value: 31,
            min: 1,
            max: 30,
            ..
        })
    ));
    assert_eq!(
        Request::write(j1(), addr::TAG_WORK_MODE, 3)
            .unwrap()
            .to_frame()
            .data(),
        &[0x02, 0x30, 0x03, 0x00],
        "checked writes use the spec's 2-byte form"
    );
}

#[test]
fn malformed_replies() {
    let err = |id: u16, data: &[u8]| Reply::from_frame(&frame(id, data)).unwrap_err().reason;
    assert_eq!(
        err(0x501, &[0; 12]),
        ReplyErrorReason::Length {
            what: "servo feedback",
            len: 12,
            allowed: "16"
        }
    );
    assert_eq!(
        err(0x701, &[0; 8]),
        ReplyErrorReason::Length {
            what: "status feedback",
            len: 8,
            allowed: "12 or 16"
        }
    );
    assert_eq!(
        err(0x101, &[0x05, 0x30, 0x01]),
        ReplyErrorReason::UnknownCommand { cmd: 5, len: 3 }
    );
    assert!(matches!(
        err(0x101, &[0x01, 0x14, 0x10]),
        ReplyErrorReason::Length { .. }
    ));
    assert!(matches!(
        err(0x101, &[0x02, 0x30, 0x01, 0x00]),
        ReplyErrorReason::Length { .. }
    ));
    assert_eq!(
        err(0x101, &[0x02, 0xA0, 0x01]),
        ReplyErrorReason::Address { addr: 0xA0 }
    );
    assert_eq!(err(0x201, &[0; 4]), ReplyErrorReason::NotAReply);
    assert_eq!(err(0x87, &[0; 24]), ReplyErrorReason::NotAReply);
    // CMD_ERR is recognised by its length whatever the command byte is.
    assert_eq!(
        Reply::from_frame(&frame(0x101, &[0xFF, 0x02])).unwrap(),
        Reply::CmdErr {
            joint: j1(),
            code: 0xFF,
            error: CmdError::Permission
        }
    );
    assert_eq!(
        Reply::from_frame(&frame(0x101, &[0x01, 0x01])).unwrap(),
        Reply::CmdErr {
            joint: j1(),
            code: 0x01,
            error: CmdError::Format
        }
    );
}

#[test]
fn broadcast_read_reply_forms() {
    use robobus_whj::BroadcastRegisterReply;
    // V1.1 form [01 idx data…] and GRIP's [len 01 idx data…] (C19).
    let plain = Reply::from_frame(&frame(0xF2, &[0x01, 0x14, 0x10, 0x27, 0x00, 0x00])).unwrap();
    let Reply::BroadcastRegister {
        reply:
            BroadcastRegisterReply::Read {
                addr,
                words,
                length_prefix,
            },
        ..
    } = plain
    else {
        panic!("{plain:?}")
    };
    assert_eq!(
        (addr, words.as_slice(), length_prefix),
        (addr::CUR_POSITION, &[0x2710, 0][..], None)
    );
    let grip = Reply::from_frame(&frame(
        0x3FE,
        &[0x06, 0x01, 0x14, 0x10, 0x27, 0x00, 0x00, 0x00],
    ))
    .unwrap();
    assert_eq!(grip.joint().get(), 6);
    let Reply::BroadcastRegister {
        reply:
            BroadcastRegisterReply::Read {
                addr,
                words,
                length_prefix,
            },
        ..
    } = grip
    else {
        panic!("{grip:?}")
    };
    assert_eq!((addr, length_prefix), (addr::CUR_POSITION, Some(6)));
    assert_eq!(&words.as_slice()[..2], &[0x2710, 0]);
}
