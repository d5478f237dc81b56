//! Encode and decode cost per packet (`cargo bench -p robobus-wck`).

#![allow(clippy::unwrap_used)] // test and bench set-up: a failed unwrap is a failed run

use std::hint::black_box;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use robobus_wck::program::Program;
use robobus_wck::{
    Command, DGain, DataByte, ExtServoId, PGain, Position, Position10, ServoId, StreamDecoder,
    SyncMove, TorqueLevel,
};

fn commands() -> Vec<(&'static str, Command)> {
    let id = ServoId::new(3).unwrap();
    let pos = Position::new(127).unwrap();
    let torque = TorqueLevel::new(0).unwrap();
    vec![
        (
            "move (4 B)",
            Command::Move {
                id,
                torque,
                position: pos,
            },
        ),
        (
            "gain set (6 B)",
            Command::GainSet {
                id,
                p: PGain::DEFAULT,
                d: DGain::DEFAULT,
            },
        ),
        (
            "10-bit move (8 B)",
            Command::Move10 {
                id: ExtServoId::new(100).unwrap(),
                torque: DataByte::new(0).unwrap(),
                position: Position10::new(1000).unwrap(),
            },
        ),
        (
            "motion write (21 B)",
            Command::MotionWrite {
                id,
                program: Program::parse(
                    "move 82 torque 0\ndelay 266ms\nmove 172 torque 0\ndelay 266ms\n\
                     if adc >= 120\noutput 3\nrepeat forever\nend",
                )
                .unwrap(),
            },
        ),
        (
            "sync move 31 (35 B)",
            Command::SyncMove(SyncMove::new(torque, &[pos; 31]).unwrap()),
        ),
    ]
}

fn codec(c: &mut Criterion) {
    let mut encode = c.benchmark_group("encode");
    encode.throughput(Throughput::Elements(1));
    for (name, cmd) in commands() {
        encode.bench_function(name, |b| b.iter(|| black_box(black_box(&cmd).encode())));
    }
    encode.finish();

    let mut decode = c.benchmark_group("decode");
    decode.throughput(Throughput::Elements(1));
    for (name, cmd) in commands() {
        let packet = cmd.encode();
        let mut decoder = StreamDecoder::new();
        decode.bench_function(name, |b| {
            b.iter(|| {
                let mut out = None;
                for &byte in black_box(packet.as_bytes()) {
                    if let Some(event) = decoder.push(byte) {
                        out = Some(event);
                    }
                }
                black_box(out)
            });
        });
    }
    decode.finish();

    let mut reply = c.benchmark_group("reply");
    reply.throughput(Throughput::Elements(1));
    let status = Command::StatusRead {
        id: ServoId::new(3).unwrap(),
    };
    reply.bench_function("status read decode_reply", |b| {
        b.iter(|| black_box(black_box(&status).decode_reply(black_box(&[12, 90]))));
    });
    reply.finish();
}

criterion_group!(benches, codec);
criterion_main!(benches);
