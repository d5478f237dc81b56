//! How fast is the WHJ simulator? (issue 6: "Measured".)
//!
//! 1. Virtual clock: seven WHJ30 joints, the host streams a position servo frame to each
//!    every millisecond (14 frames per 1 ms cycle on the exact 1 / 5 Mbit/s wire); prints
//!    simulated seconds per wall-clock second.
//! 2. Wall clock: `serve` on a frame link (in-memory, and python-can's UDP bus on loopback)
//!    with N joints; a client thread sends one position servo frame per joint per
//!    millisecond and reads the feedback. The wire is made fast (1 Gbit/s) so that only the
//!    simulator's CPU limits; the server thread's CPU time (from `/proc/thread-self/stat`)
//!    gives the CPU cost per joint per 1 ms cycle and so the number of joints one core can
//!    serve at 1 kHz. (On the real 1 / 5 Mbit/s wire, one bus carries at most 8 joints at
//!    1 kHz: the wire-timing notes.)
//!
//! Run: `cargo run --release -p robobus-sim --example whj_capacity`.

#![allow(
    clippy::print_stdout,
    clippy::unwrap_used,
    clippy::cast_precision_loss,
    clippy::cast_possible_truncation,
    clippy::cast_sign_loss
)] // A measurement program: prints its results, aborts on setup failures.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread;
use std::time::{Duration, Instant};

use robobus_link::udp::{UdpBus, UdpBusConfig};
use robobus_link::{FrameLink, MemoryBus};
use robobus_sim::whj::{JointConfig, WhjBus, WhjModel, serve};
use robobus_whj::CanFrame;
use robobus_whj::timing::BitRates;

fn pos_cmd(id: u8, counts: i32) -> CanFrame {
    CanFrame::new_fd(
        CanFrame::standard_id(0x200 + u16::from(id)).unwrap(),
        &counts.to_le_bytes(),
    )
    .unwrap()
}

fn target(k: u64, id: u8) -> i32 {
    (100_000.0 * (k as f64 / 1000.0 + f64::from(id)).sin()) as i32
}

fn chain(n: u8) -> WhjBus {
    WhjBus::with_configs(
        (1..=n).map(|id| JointConfig::new(id, WhjModel::Whj30).without_iap()),
        1,
    )
}

fn broadcast_position(k: u64) -> CanFrame {
    let mut d = [0u8; 64];
    for id in 1..=7u8 {
        let at = 8 * usize::from(id - 1);
        d[at..at + 4].copy_from_slice(&target(k, id).to_le_bytes());
    }
    d[56..63].fill(0xFF);
    d[63] = 0x0F; // every joint answers
    CanFrame::new_fd(CanFrame::standard_id(0x2F).unwrap(), &d).unwrap()
}

fn virtual_clock(seconds: u64, broadcast: bool) {
    let mut bus = chain(7);
    let start = Instant::now();
    let mut replies = 0usize;
    for k in 0..seconds * 1000 {
        let now = bus.now();
        if broadcast {
            bus.submit(broadcast_position(k), now);
        } else {
            for id in 1..=7 {
                bus.submit(pos_cmd(id, target(k, id)), now);
            }
        }
        replies += bus.run_until(now + Duration::from_millis(1)).len();
    }
    let wall = start.elapsed().as_secs_f64();
    let busy = bus.stats().busy.as_secs_f64() / seconds as f64;
    let what = if broadcast {
        "0x2F broadcast position + 7 feedback frames"
    } else {
        "point-to-point position servo (14 frames)"
    };
    println!(
        "virtual clock, 7 joints, 1 kHz {what}: {seconds} s simulated in {wall:.3} s wall = {:.1} simulated s per wall s ({replies} replies, wire {:.1} % busy)",
        seconds as f64 / wall,
        busy * 100.0
    );
}

/// CPU time (user + system) of the calling thread.
fn thread_cpu() -> Duration {
    let stat = std::fs::read_to_string("/proc/thread-self/stat").unwrap_or_default();
    let fields: Vec<&str> = stat
        .rsplit(')')
        .next()
        .unwrap_or("")
        .split_whitespace()
        .collect();
    let ticks: u64 = fields
        .get(11..13)
        .map_or(0, |f| f.iter().filter_map(|t| t.parse::<u64>().ok()).sum());
    // USER_HZ is 100 on Linux.
    Duration::from_millis(ticks * 10)
}

fn wall_clock<L: FrameLink + Send + 'static>(
    name: &str,
    n: u8,
    seconds: u64,
    mut sim_link: L,
    mut client: impl FrameLink + Send + 'static,
) {
    let stop = Arc::new(AtomicBool::new(false));
    let flag = Arc::clone(&stop);
    let server = thread::spawn(move || {
        let mut bus = chain(n).with_rates(BitRates::new(1_000_000_000, 1_000_000_000).unwrap());
        let cpu0 = thread_cpu();
        let stats = serve(&mut bus, &mut sim_link, &flag).unwrap();
        (stats, thread_cpu().saturating_sub(cpu0))
    });
    thread::sleep(Duration::from_millis(100));
    let start = Instant::now();
    let (mut sent, mut got) = (0u64, 0u64);
    let mut worst_cycle = Duration::ZERO;
    let mut on_time = 0u64;
    for k in 0..seconds * 1000 {
        let slot = start + Duration::from_millis(k);
        // Sleep (not spin) so that a shared core stays free for the server.
        let left = slot.saturating_duration_since(Instant::now());
        if left > Duration::from_micros(200) {
            thread::sleep(left.saturating_sub(Duration::from_micros(150)));
        }
        while Instant::now() < slot {
            std::hint::spin_loop();
        }
        for id in 1..=n {
            client.send(&pos_cmd(id, target(k, id))).unwrap();
            sent += 1;
        }
        // Collect this cycle's feedback before the next slot.
        let deadline = slot + Duration::from_micros(950);
        let mut this = 0;
        while this < n {
            match client.recv(deadline) {
                Ok(_) => {
                    got += 1;
                    this += 1;
                }
                Err(_) => break,
            }
        }
        if this == n {
            worst_cycle = worst_cycle.max(slot.elapsed());
            on_time += 1;
        }
    }
    let wall = start.elapsed();
    thread::sleep(Duration::from_millis(100));
    while client
        .recv(Instant::now() + Duration::from_millis(20))
        .is_ok()
    {
        got += 1;
    }
    stop.store(true, Ordering::Relaxed);
    let (stats, cpu) = server.join().unwrap();
    let load = cpu.as_secs_f64() / wall.as_secs_f64();
    let per_joint_us = cpu.as_secs_f64() * 1e6 / (f64::from(n) * seconds as f64 * 1000.0);
    println!(
        "wall clock, {name}, {n} joints at 1 kHz: sent {sent}, feedback {got}, cycles complete within 950 µs {:.2} %, worst complete cycle {} µs, server lateness max {} µs, server CPU {:.1} % of a core = {per_joint_us:.2} µs per joint per cycle -> about {} joints per core at 1 kHz",
        on_time as f64 * 100.0 / (seconds * 1000) as f64,
        worst_cycle.as_micros(),
        stats.max_lateness.as_micros(),
        load * 100.0,
        (1000.0 / per_joint_us).max(0.0) as u64
    );
}

fn main() {
    virtual_clock(20, false);
    virtual_clock(20, true);
    for n in [7u8, 30] {
        let bus = MemoryBus::new();
        wall_clock("in-memory link", n, 3, bus.endpoint(), bus.endpoint());
    }
    let cfg = UdpBusConfig {
        port: 43_777,
        ..UdpBusConfig::default()
    };
    for n in [7u8, 30] {
        match (UdpBus::open(&cfg), UdpBus::open(&cfg)) {
            (Ok(a), Ok(b)) => wall_clock("UDP multicast on loopback", n, 3, a, b),
            (Err(e), _) | (_, Err(e)) => println!("UDP bus unavailable: {e}"),
        }
    }
}
