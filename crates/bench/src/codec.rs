//! Codec cost per packet / frame: the work the client and the simulator do for each
//! wCK packet and WHJ frame, measured in a tight loop (the criterion bench
//! `benches/codec.rs` runs the same functions with statistics).

use std::hint::black_box;
use std::time::{Duration, Instant};

use robobus_wck::{Command, Position, ServoId, StreamDecoder, SyncMove, TorqueLevel};
use robobus_whj::broadcast::{BroadcastPosition, ReplyMask};
use robobus_whj::reply::ServoFeedback;
use robobus_whj::units::{ActualSpeed, Current, Position as JointPosition};
use robobus_whj::{ErrorCode, JointId, Reply, Request};

/// One wCK transaction's codec work: the host encodes `command`, the device side decodes
/// the packet byte by byte, the host decodes the 2-byte `reply` (if the command has
/// one). Returns whether everything decoded.
pub fn wck_transaction(command: &Command, decoder: &mut StreamDecoder, reply: [u8; 2]) -> bool {
    let packet = command.encode();
    let mut ok = false;
    for &b in packet.as_bytes() {
        if let Some(r) = decoder.push(b) {
            ok = r.is_ok();
        }
    }
    if command.reply_len() == 2 {
        ok &= command.decode_reply(&reply).is_ok();
    }
    ok
}

/// One WHJ request frame: encode and decode (device side).
pub fn whj_request(request: &Request) -> bool {
    Request::from_frame(&request.to_frame()).is_ok()
}

/// One WHJ reply frame: encode (device side) and decode (host side).
pub fn whj_reply(reply: &Reply) -> bool {
    Reply::from_frame(&reply.to_frame()).is_ok()
}

/// A measured case.
#[derive(Debug, Clone, PartialEq)]
pub struct CodecCase {
    /// What is measured.
    pub name: &'static str,
    /// Packets (or frames) handled per iteration.
    pub packets: u32,
    /// Nanoseconds per iteration (best of several batches).
    pub ns_per_iter: f64,
    /// The criterion estimate (mean, ns per iteration), if a criterion run was found.
    pub criterion_ns: Option<f64>,
}

impl CodecCase {
    /// Nanoseconds per packet.
    pub fn ns_per_packet(&self) -> f64 {
        self.criterion_ns.unwrap_or(self.ns_per_iter) / f64::from(self.packets.max(1))
    }
}

/// The commands and frames of the cases, shared with the criterion bench.
#[derive(Debug, Clone)]
pub struct Fixtures {
    /// wCK position move to servo 3 (4 B + 2 B reply).
    pub wck_move: Command,
    /// wCK status read of servo 3 (4 B + 2 B reply).
    pub wck_status: Command,
    /// wCK synchronized move to 31 servos (35 B, no reply).
    pub wck_sync: Command,
    /// WHJ position servo command to joint 1 (4 B).
    pub whj_servo: Request,
    /// WHJ servo feedback of joint 1 (16 B).
    pub whj_feedback: Reply,
    /// WHJ broadcast position for 7 joints (64 B).
    pub whj_broadcast: Request,
}

impl Default for Fixtures {
    fn default() -> Self {
        let id = ServoId::new(3).unwrap_or(ServoId::MAX);
        let pos = Position::new(127).unwrap_or(Position::MAX);
        let torque = TorqueLevel::new(0).unwrap_or(TorqueLevel::MAX);
        let sync =
            SyncMove::new(torque, &[pos; 31]).map_or(Command::StatusRead { id }, Command::SyncMove);
        let j1 = JointId::new(1).unwrap_or(JointId::MAX);
        let mut bp = BroadcastPosition::new(ReplyMask::ALL);
        for j in 1..=7u8 {
            let joint = JointId::new(j).unwrap_or(JointId::MAX);
            bp = bp
                .with_target(joint, JointPosition(i32::from(j) * 10_000))
                .unwrap_or(bp);
        }
        Self {
            wck_move: Command::Move {
                id,
                torque,
                position: pos,
            },
            wck_status: Command::StatusRead { id },
            wck_sync: sync,
            whj_servo: Request::PositionServo {
                joint: j1,
                target: JointPosition(300_000),
            },
            whj_feedback: Reply::ServoFeedback {
                joint: j1,
                feedback: ServoFeedback {
                    current: Current(-64),
                    speed: ActualSpeed(12),
                    position: JointPosition(200_000),
                    enable: 1,
                    error: ErrorCode::NONE,
                },
            },
            whj_broadcast: Request::BroadcastPosition(bp),
        }
    }
}

fn time_it(iters: u64, mut f: impl FnMut() -> bool) -> f64 {
    let mut best = f64::INFINITY;
    for _ in 0..7 {
        let t0 = Instant::now();
        let mut ok = 0u64;
        for _ in 0..iters {
            ok += u64::from(black_box(f()));
        }
        let ns = t0.elapsed().as_secs_f64() * 1e9 / iters.max(1) as f64;
        black_box(ok);
        best = best.min(ns);
    }
    best
}

/// Measures every case with `iters` iterations per batch (best of 7 batches).
pub fn measure(iters: u64) -> Vec<CodecCase> {
    let fx = Fixtures::default();
    let mut dec = StreamDecoder::new();
    let mut cases = Vec::new();
    let mut case = |name, packets, ns| {
        cases.push(CodecCase {
            name,
            packets,
            ns_per_iter: ns,
            criterion_ns: None,
        });
    };
    let r = [12, 90];
    let ns = time_it(iters, || {
        wck_transaction(black_box(&fx.wck_move), &mut dec, r)
    });
    case("wck_move", 2, ns);
    let ns = time_it(iters, || {
        wck_transaction(black_box(&fx.wck_status), &mut dec, r)
    });
    case("wck_status", 2, ns);
    let ns = time_it(iters, || {
        wck_transaction(black_box(&fx.wck_sync), &mut dec, r)
    });
    case("wck_sync31", 1, ns);
    let ns = time_it(iters, || whj_request(black_box(&fx.whj_servo)));
    case("whj_servo", 1, ns);
    let ns = time_it(iters, || whj_reply(black_box(&fx.whj_feedback)));
    case("whj_feedback", 1, ns);
    let ns = time_it(iters, || whj_request(black_box(&fx.whj_broadcast)));
    case("whj_broadcast", 1, ns);
    cases
}

/// What each case covers, for the report.
pub fn describe(name: &str) -> &'static str {
    match name {
        "wck_move" => "wCK position move: encode 4 B + device-side decode + 2 B reply decode",
        "wck_status" => "wCK status read: encode 4 B + device-side decode + 2 B reply decode",
        "wck_sync31" => "wCK synchronized move to 31 servos: encode 35 B + device-side decode",
        "whj_servo" => "WHJ position servo request (4 B): encode + decode",
        "whj_feedback" => "WHJ servo feedback reply (16 B): encode + decode",
        "whj_broadcast" => "WHJ broadcast position (64 B): encode + decode",
        _ => "",
    }
}

/// Fills in criterion's estimates (`<dir>/codec/<name>/new/estimates.json`, mean) where a
/// criterion run left them.
pub fn attach_criterion(cases: &mut [CodecCase], dir: &std::path::Path) {
    for c in cases {
        let path = dir.join("codec").join(c.name).join("new/estimates.json");
        let Ok(text) = std::fs::read_to_string(&path) else {
            continue;
        };
        let Ok(v) = serde_json::from_str::<serde_json::Value>(&text) else {
            continue;
        };
        c.criterion_ns = v
            .get("mean")
            .and_then(|m| m.get("point_estimate"))
            .and_then(serde_json::Value::as_f64);
    }
}

/// A duration as microseconds.
pub fn us(d: Duration) -> f64 {
    d.as_secs_f64() * 1e6
}
