//! Encode + decode cost per frame (criterion). Run: `cargo bench -p robobus-whj`.

// Test and bench code: a failed unwrap is a failed test.
#![allow(clippy::unwrap_used, clippy::panic)]

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use robobus_whj::broadcast::{BroadcastPosition, ReplyMask};
use robobus_whj::reply::ServoFeedback;
use robobus_whj::timing::{BitRates, frame_bits};
use robobus_whj::units::{ActualSpeed, Current, Position};
use robobus_whj::{ErrorCode, JointId, Reply, Request};

fn codec(c: &mut Criterion) {
    let j1 = JointId::new(1).unwrap();
    let servo = Request::PositionServo {
        joint: j1,
        target: Position(300_000),
    };
    c.bench_function("position servo request encode+decode", |b| {
        b.iter(|| Request::from_frame(&black_box(servo).to_frame()));
    });

    let feedback = Reply::ServoFeedback {
        joint: j1,
        feedback: ServoFeedback {
            current: Current(-64),
            speed: ActualSpeed(0),
            position: Position(200_000),
            enable: 1,
            error: ErrorCode::NONE,
        },
    };
    c.bench_function("servo feedback reply encode+decode", |b| {
        b.iter(|| Reply::from_frame(&black_box(feedback).to_frame()));
    });

    let write = Request::set_mode(j1, robobus_whj::WorkMode::Position);
    c.bench_function(
        "register write request encode+decode (with access check)",
        |b| {
            b.iter(|| Request::from_frame(&black_box(write).to_frame()));
        },
    );

    let mut bp = BroadcastPosition::new(ReplyMask::ALL);
    for j in 1..=7 {
        bp = bp
            .with_target(JointId::new(j).unwrap(), Position(i32::from(j) * 10_000))
            .unwrap();
    }
    let broadcast = Request::BroadcastPosition(bp);
    c.bench_function("broadcast position (64 B) encode+decode", |b| {
        b.iter(|| Request::from_frame(&black_box(broadcast).to_frame()));
    });

    let frame = feedback.to_frame();
    c.bench_function("frame time of a 16 B frame (bit stuffing)", |b| {
        b.iter(|| frame_bits(black_box(&frame)).duration(BitRates::WHJ));
    });
}

criterion_group!(benches, codec);
criterion_main!(benches);
