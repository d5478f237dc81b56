//! Property tests: request and reply round trips; arbitrary frames never panic the decoders.

// Test and bench code: a failed unwrap is a failed test.
#![allow(clippy::unwrap_used, clippy::panic)]

use proptest::prelude::*;
use robobus_whj::broadcast::{
    BroadcastCurrent, BroadcastPosition, BroadcastRegister, BroadcastStatus, FeedForwardBits,
    PositionSlot, RegisterOp, RegisterSlot, ReplyMask, is_no_data,
};
use robobus_whj::reply::{JointStatus, ServoFeedback};
use robobus_whj::timing::{BitRates, frame_bits};
use robobus_whj::units::{ActualSpeed, Current, Position, TargetSpeed, Temperature, Voltage};
use robobus_whj::{
    BroadcastFeedback, BroadcastRegisterReply, CanFrame, CmdError, ErrorCode, JointId, ReadRange,
    RegisterAddr, Reply, Request, WriteData, WriteStatus,
};

fn joint() -> impl Strategy<Value = JointId> {
    (1u8..=30).prop_map(|j| JointId::new(j).unwrap())
}

fn broadcast_joint() -> impl Strategy<Value = JointId> {
    (1u8..=7).prop_map(|j| JointId::new(j).unwrap())
}

fn read_range() -> impl Strategy<Value = ReadRange> {
    (0u8..=0x91).prop_flat_map(|a| {
        let max = (0x92 - u16::from(a)).min(31) as u8;
        (Just(a), 1..=max)
            .prop_map(|(a, n)| ReadRange::new(RegisterAddr::new(a).unwrap(), n).unwrap())
    })
}

fn write_op() -> impl Strategy<Value = (RegisterAddr, WriteData)> {
    prop_oneof![
        (0u8..=0x91, any::<u8>())
            .prop_map(|(a, b)| (RegisterAddr::new(a).unwrap(), WriteData::Byte(b))),
        (0u8..=0x91, any::<u16>())
            .prop_map(|(a, w)| (RegisterAddr::new(a).unwrap(), WriteData::Word(w))),
        (0u8..=0x90, any::<i32>())
            .prop_map(|(a, v)| (RegisterAddr::new(a).unwrap(), WriteData::Pair(v))),
    ]
}

fn mask() -> impl Strategy<Value = ReplyMask> {
    (0u8..16).prop_map(|m| ReplyMask::new(m).unwrap())
}

fn target() -> impl Strategy<Value = i32> {
    any::<i32>().prop_filter("no-data marker", |v| !is_no_data(*v))
}

fn request() -> impl Strategy<Value = Request> {
    let position_slot = (target(), any::<i16>(), any::<i16>()).prop_map(|(p, s, c)| PositionSlot {
        position: Position(p),
        speed_ff: s,
        current_ff: c,
    });
    let register_slot = prop_oneof![
        Just(RegisterSlot::Empty),
        read_range().prop_map(|r| RegisterSlot::Op(RegisterOp::Read(r))),
        write_op().prop_map(|(addr, data)| RegisterSlot::Op(RegisterOp::Write { addr, data })),
    ];
    prop_oneof![
        (joint(), read_range()).prop_map(|(joint, range)| Request::Read { joint, range }),
        (joint(), write_op()).prop_map(|(joint, (addr, data))| Request::Write {
            joint,
            addr,
            data
        }),
        (joint(), any::<i32>()).prop_map(|(joint, v)| Request::PositionServo {
            joint,
            target: Position(v)
        }),
        (joint(), any::<i32>()).prop_map(|(joint, v)| Request::SpeedServo {
            joint,
            target: TargetSpeed(v)
        }),
        (joint(), any::<i32>()).prop_map(|(joint, v)| Request::CurrentServo {
            joint,
            target: Current(v)
        }),
        joint().prop_map(|joint| Request::StatusQuery { joint }),
        (
            proptest::array::uniform7(proptest::option::of(position_slot)),
            any::<[u8; 7]>(),
            0u8..16,
            mask()
        )
            .prop_map(|(slots, end_board, ff, mask)| Request::BroadcastPosition(
                BroadcastPosition {
                    slots,
                    end_board,
                    feed_forward: FeedForwardBits::from_nibble(ff),
                    mask,
                }
            )),
        (
            proptest::array::uniform7(proptest::option::of(target())),
            any::<[u8; 19]>(),
            mask()
        )
            .prop_map(|(slots, end_board, mask)| Request::BroadcastCurrent(
                BroadcastCurrent {
                    slots: slots.map(|s| s.map(Current)),
                    end_board,
                    mask,
                }
            )),
        (
            proptest::array::uniform7(register_slot),
            any::<[u8; 13]>(),
            mask()
        )
            .prop_map(|(slots, end_board, mask)| Request::BroadcastRegister(
                BroadcastRegister {
                    slots,
                    end_board,
                    mask
                }
            )),
        (any::<[u8; 23]>(), mask()).prop_map(|(end_board, mask)| Request::BroadcastStatus(
            BroadcastStatus { end_board, mask }
        )),
    ]
}

fn words() -> impl Strategy<Value = Vec<u16>> {
    proptest::collection::vec(any::<u16>(), 1..=31)
}

fn reply() -> impl Strategy<Value = Reply> {
    let servo = (
        any::<i32>(),
        any::<i32>(),
        any::<i32>(),
        any::<u16>(),
        any::<u16>(),
    )
        .prop_map(|(c, s, p, e, err)| ServoFeedback {
            current: Current(c),
            speed: ActualSpeed(s),
            position: Position(p),
            enable: e,
            error: ErrorCode(err),
        });
    let status = (
        any::<u16>(),
        any::<i16>(),
        any::<i16>(),
        any::<u8>(),
        any::<u8>(),
        any::<i32>(),
        proptest::option::of(any::<i32>()),
    )
        .prop_map(|(e, v, t, en, br, p, c)| JointStatus {
            error: ErrorCode(e),
            voltage: Voltage(v),
            temperature: Temperature(t),
            enable: en,
            brake: br,
            position: Position(p),
            current: c.map(Current),
        });
    let bfb = any::<[u8; 24]>().prop_map(|b| BroadcastFeedback::decode(&b));
    let addr = (0u8..=0x91).prop_map(|a| RegisterAddr::new(a).unwrap());
    let breg = prop_oneof![
        (addr.clone(), any::<u8>()).prop_map(|(addr, s)| BroadcastRegisterReply::WriteAck {
            addr,
            status: WriteStatus::from_raw(s)
        }),
        (addr.clone(), words(), proptest::option::of(3u8..=255)).prop_map(|(addr, w, p)| {
            BroadcastRegisterReply::Read {
                addr,
                words: robobus_whj::Words::from_slice(if p.is_some() {
                    &w[..w.len().min(30)]
                } else {
                    &w
                })
                .unwrap(),
                length_prefix: p,
            }
        }),
    ];
    prop_oneof![
        (joint(), addr.clone(), words()).prop_map(|(joint, addr, w)| Reply::Read {
            joint,
            addr,
            words: robobus_whj::Words::from_slice(&w).unwrap()
        }),
        (joint(), addr, any::<u8>()).prop_map(|(joint, addr, s)| Reply::WriteAck {
            joint,
            addr,
            status: WriteStatus::from_raw(s)
        }),
        (joint(), any::<u8>(), any::<u8>()).prop_map(|(joint, code, e)| Reply::CmdErr {
            joint,
            code,
            error: CmdError::from_raw(e)
        }),
        (joint(), servo).prop_map(|(joint, feedback)| Reply::ServoFeedback { joint, feedback }),
        (joint(), status).prop_map(|(joint, status)| Reply::Status { joint, status }),
        (broadcast_joint(), bfb)
            .prop_map(|(joint, feedback)| Reply::BroadcastFeedback { joint, feedback }),
        (broadcast_joint(), breg)
            .prop_map(|(joint, reply)| Reply::BroadcastRegister { joint, reply }),
    ]
}

/// Read replies may gain zero words from padding; compare the original words as a prefix.
fn same_reply(sent: &Reply, got: &Reply) -> bool {
    use BroadcastRegisterReply as B;
    match (sent, got) {
        (
            Reply::Read {
                joint: j1,
                addr: a1,
                words: w1,
            },
            Reply::Read {
                joint: j2,
                addr: a2,
                words: w2,
            },
        ) => {
            j1 == j2
                && a1 == a2
                && w2.truncated(w1.len()) == *w1
                && w2.as_slice()[w1.len()..].iter().all(|w| *w == 0)
        }
        (
            Reply::BroadcastRegister {
                joint: j1,
                reply:
                    B::Read {
                        addr: a1,
                        words: w1,
                        length_prefix: p1,
                    },
            },
            Reply::BroadcastRegister {
                joint: j2,
                reply:
                    B::Read {
                        addr: a2,
                        words: w2,
                        length_prefix: p2,
                    },
            },
        ) => j1 == j2 && a1 == a2 && p1 == p2 && w2.truncated(w1.len()) == *w1,
        _ => sent == got,
    }
}

fn any_frame() -> impl Strategy<Value = CanFrame> {
    let lens = prop_oneof![
        0usize..=8,
        Just(12),
        Just(16),
        Just(20),
        Just(24),
        Just(32),
        Just(48),
        Just(64)
    ];
    let id = prop_oneof![
        4 => (0u16..=0x7FF).prop_map(|r| CanFrame::standard_id(r).unwrap()),
        4 => prop_oneof![Just(0x0Fu16), Just(0x2F), Just(0x4F), Just(0x7F), Just(0x82), Just(0xF2), Just(0x5FE), Just(0x3FE), 0x001u16..=0x01E, 0x101u16..=0x11E, 0x501u16..=0x51E, 0x701u16..=0x71E]
            .prop_map(|r| CanFrame::standard_id(r).unwrap()),
        1 => (0u32..=0x1FFF_FFFF).prop_map(|r| CanFrame::extended_id(r).unwrap()),
    ];
    (
        id,
        lens.prop_flat_map(|n| proptest::collection::vec(any::<u8>(), n)),
        any::<bool>(),
        any::<bool>(),
    )
        .prop_map(|(id, data, classic, brs)| {
            if classic && data.len() <= 8 {
                CanFrame::new_classic(id, &data).unwrap()
            } else {
                CanFrame::new_fd(id, &data).unwrap().with_brs(brs)
            }
        })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]

    #[test]
    fn requests_round_trip(req in request()) {
        let frame = req.to_frame();
        prop_assert_eq!(Request::decode(&frame).unwrap(), req);
        match Request::from_frame(&frame) {
            Ok(r) => prop_assert_eq!(r, req),
            Err(e) => prop_assert!(matches!(e.reason, robobus_whj::MalformedReason::ReadOnly { .. }), "{e}"),
        }
        prop_assert_eq!(u32::from(req.can_id()), frame.raw_id());
    }

    #[test]
    fn replies_round_trip(reply in reply()) {
        let frame = reply.to_frame();
        let got = Reply::from_frame(&frame).unwrap();
        prop_assert!(same_reply(&reply, &got), "sent {:?}\n got {:?}", reply, got);
        prop_assert_eq!(got.joint(), reply.joint());
    }

    #[test]
    fn arbitrary_frames_never_panic(frame in any_frame()) {
        let _ = frame_bits(&frame).duration(BitRates::WHJ);
        if let Ok(req) = Request::decode(&frame) {
            // Decoding is idempotent through a re-encode.
            prop_assert_eq!(Request::decode(&req.to_frame()).unwrap(), req);
        }
        if let Err(e) = Request::from_frame(&frame) {
            let _ = e.response();
        }
        if let Ok(reply) = Reply::from_frame(&frame) {
            prop_assert_eq!(Reply::from_frame(&reply.to_frame()).unwrap(), reply);
        }
    }

    #[test]
    fn register_slots_never_panic(slot in any::<[u8; 7]>()) {
        let decoded = RegisterSlot::decode(slot);
        prop_assert_eq!(RegisterSlot::decode(decoded.encode()), decoded);
    }
}
