//! The wCK simulator over TCP against the simulator on a pty, for the same transactions:
//! the transports' own echo round trip, then sequential status polling with the client
//! library (the same modules, rate, turnaround and wait mode on both), each as a ratio
//! to the wire limit (the modelled cycle) and TCP's as a ratio to the pty's.
//!
//! `cargo run --release -p robobus-bench --example tcp_vs_pty [SECONDS]` (default 2 per
//! case). Ratios only: wall-clock rates depend on the machine.

use std::io::Write as _;
use std::process::ExitCode;
use std::time::Duration;

use robobus_bench::transport::{pty_echo, tcp_echo};
use robobus_bench::wck::{PollResult, PollSpec, poll, poll_tcp};
use robobus_link::WaitMode;
use robobus_wck::BaudRate;

fn mean_cycle_us(r: &PollResult) -> f64 {
    1e6 / r.rate_hz().max(1e-9)
}

fn main() -> ExitCode {
    let secs: f64 = std::env::args()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .filter(|s| (0.1..=60.0).contains(s))
        .unwrap_or(2.0);
    let duration = Duration::from_secs_f64(secs);
    let mut out = std::io::stdout().lock();
    let (pty, tcp) = match (pty_echo(5000), tcp_echo(5000)) {
        (Ok(p), Ok(t)) => (p, t),
        (Err(e), _) | (_, Err(e)) => {
            let _ = writeln!(std::io::stderr(), "echo: {e}");
            return ExitCode::FAILURE;
        }
    };
    let _ = writeln!(
        out,
        "echo round trip, both sides spinning: pty p50 {:.1} µs, TCP p50 {:.1} µs, \
         TCP / pty {:.2}",
        pty.p50,
        tcp.p50,
        tcp.p50 / pty.p50.max(1e-9)
    );
    let _ = writeln!(
        out,
        "| case | wire cycle µs | pty cycle µs | TCP cycle µs | pty / wire | TCP / wire | \
         TCP / pty | errors pty, TCP |"
    );
    let _ = writeln!(out, "|---|---|---|---|---|---|---|---|");
    for (servos, baud, manual, wait) in [
        (4, BaudRate::B115200, true, WaitMode::Sleep),
        (4, BaudRate::B115200, false, WaitMode::Sleep),
        (4, BaudRate::B115200, false, WaitMode::SPIN),
        (8, BaudRate::B921600, false, WaitMode::Sleep),
        (8, BaudRate::B921600, false, WaitMode::SPIN),
    ] {
        let spec = PollSpec {
            servos,
            baud,
            manual_turnaround: manual,
            wait,
            memory: false,
            guard: false,
        };
        let (p, t) = match (poll(spec, duration, None), poll_tcp(spec, duration)) {
            (Ok(p), Ok(t)) => (p, t),
            (Err(e), _) | (_, Err(e)) => {
                let _ = writeln!(std::io::stderr(), "{}: {e}", spec.label());
                return ExitCode::FAILURE;
            }
        };
        let wire = spec.modelled_cycle().as_secs_f64() * 1e6;
        let (pc, tc) = (mean_cycle_us(&p), mean_cycle_us(&t));
        let _ = writeln!(
            out,
            "| {} | {wire:.0} | {pc:.0} | {tc:.0} | {:.2} | {:.2} | {:.2} | {}, {} |",
            spec.label().replace(", pty", ""),
            pc / wire,
            tc / wire,
            tc / pc,
            p.errors,
            t.errors
        );
    }
    ExitCode::SUCCESS
}
