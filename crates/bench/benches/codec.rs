//! Codec cost per packet / frame (criterion): the same cases as the report's codec table
//! (`robobus_bench::codec`). Run: `cargo bench -p robobus-bench --bench codec`.

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use robobus_bench::codec::{Fixtures, wck_transaction, whj_reply, whj_request};
use robobus_wck::StreamDecoder;

fn codec(c: &mut Criterion) {
    let fx = Fixtures::default();
    let mut g = c.benchmark_group("codec");
    let mut dec = StreamDecoder::new();
    let reply = [12, 90];
    g.bench_function("wck_move", |b| {
        b.iter(|| wck_transaction(black_box(&fx.wck_move), &mut dec, reply));
    });
    g.bench_function("wck_status", |b| {
        b.iter(|| wck_transaction(black_box(&fx.wck_status), &mut dec, reply));
    });
    g.bench_function("wck_sync31", |b| {
        b.iter(|| wck_transaction(black_box(&fx.wck_sync), &mut dec, reply));
    });
    g.bench_function("whj_servo", |b| {
        b.iter(|| whj_request(black_box(&fx.whj_servo)));
    });
    g.bench_function("whj_feedback", |b| {
        b.iter(|| whj_reply(black_box(&fx.whj_feedback)));
    });
    g.bench_function("whj_broadcast", |b| {
        b.iter(|| whj_request(black_box(&fx.whj_broadcast)));
    });
    g.finish();
}

criterion_group!(benches, codec);
criterion_main!(benches);
