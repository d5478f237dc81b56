//! Sub-tick deadlines on real `SocketCAN`: inside User-Mode Linux (whose kernel ticks are
//! 12-20 ms long), `robobus sim whj --bus vcan0` (the built binary) answers 500 status
//! queries, each with a 5 ms reply timeout, first from a bare `SocketCanLink`, then through
//! the client library (`JointBus`, `Joint::status`). When either side waited with
//! `SO_RCVTIMEO`, which the kernel rounds up to whole ticks, the replies came one to two
//! ticks late and most of these queries timed out (343 of 500). A miss whose window saw the
//! whole guest stalled by the shared host is excused ([`StallWitness`]); of the rest at most
//! 2 % may miss (a stall of the simulator process alone is invisible from here).
//!
//! `bench_vcan0_round_trip_against_can_utils_echo` (ignored: a benchmark, run it by hand with
//! `--ignored --nocapture`) prints the median and p99 round trip of the simulator against
//! two can-utils echoes on the same `vcan0`: `cangw` (a kernel gateway rule) and
//! `canfdtest` (a user-space echo, classic CAN only).

// Test code: a failed unwrap is a failed test.
#![allow(
    clippy::unwrap_used,
    clippy::panic,
    clippy::cast_precision_loss,
    clippy::print_stdout
)]
#![cfg(target_os = "linux")]

use std::io::{BufRead as _, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use robobus::whj::{JointBus, JointBusConfig, WhjError};
use robobus_link::{FrameLink, IdFilter, SocketCanLink};
use robobus_whj::timing::{BitRates, frame_duration};
use robobus_whj::{CanFrame, JointId, Request};

const IN_UML_ENV: &str = "ROBOBUS_CLI_IN_UML";
const QUERIES: usize = 500;
const TIMEOUT: Duration = Duration::from_millis(5);

use robobus_testkit::Inner;
use robobus_testkit::workspace_root as workspace;

/// Runs this test binary's ignored test `inner` inside User-Mode Linux.
fn run_inner_in_uml(inner: &str) -> String {
    let uml = workspace().join("target/uml");
    // The guest is one host process whose virtual CPU runs the simulator and the client:
    // a higher host priority (root only; ignored otherwise) keeps the shared build machine's
    // other jobs from stalling it for whole milliseconds.
    Inner::exact(module_path!(), inner, IN_UML_ENV)
        .env(IN_UML_ENV, uml.as_os_str())
        .nice(-10)
        .in_uml()
        .expect_marker(&format!("{inner} OK"))
}

fn in_guest() {
    std::env::var(IN_UML_ENV)
        .expect("this test only runs inside the UML guest its outer test boots");
}

/// The simulator, started inside the guest; stopped (and its log printed) on drop.
struct Sim(Child, PathBuf);

impl Sim {
    fn start(dir: &Path) -> Self {
        let log = dir.join("sim.log");
        let child = Command::new(env!("CARGO_BIN_EXE_robobus"))
            .args(["sim", "whj", "--joints", "1", "--bus", "vcan0", "--no-iap"])
            .args(["--processing-delay-us", "20", "--current-noise-ma", "0"])
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(std::fs::File::create(&log).unwrap())
            .spawn()
            .unwrap();
        let deadline = Instant::now() + Duration::from_secs(20);
        while !std::fs::read_to_string(&log).unwrap().contains("serving") {
            assert!(Instant::now() < deadline, "simulator did not start");
            std::thread::sleep(Duration::from_millis(10));
        }
        Self(child, log)
    }
}

impl Drop for Sim {
    fn drop(&mut self) {
        let _ = Command::new("kill")
            .args(["-INT", &self.0.id().to_string()])
            .status();
        let _ = self.0.wait();
        print!("{}", std::fs::read_to_string(&self.1).unwrap_or_default());
    }
}

fn status_query() -> CanFrame {
    Request::StatusQuery {
        joint: JointId::new(1).unwrap(),
    }
    .to_frame()
}

/// Sends `query` `n` times and waits up to `timeout` for a frame with `reply_id`; returns
/// the round trips of the answered ones and the send instants of the unanswered ones.
fn round_trips(
    link: &mut SocketCanLink,
    query: &CanFrame,
    reply_id: u16,
    n: usize,
    timeout: Duration,
) -> (Vec<Duration>, Vec<Instant>) {
    link.set_filters(&[IdFilter::standard(reply_id)]).unwrap();
    let mut rts = Vec::with_capacity(n);
    let mut missed = Vec::new();
    for i in 0..n {
        let t0 = Instant::now();
        link.send(query).unwrap();
        match link.recv(t0 + timeout) {
            Ok(r) => {
                assert_eq!(r.frame.raw_id(), u32::from(reply_id));
                rts.push(t0.elapsed());
            }
            Err(e) if e.is_timeout() => {
                missed.push(t0);
                println!("query {i}: no reply within {timeout:?}");
                // A late reply must not be credited to the next query.
                while link
                    .recv(Instant::now() + Duration::from_millis(50))
                    .is_ok()
                {}
            }
            Err(e) => panic!("{e}"),
        }
    }
    (rts, missed)
}

/// `n` status queries of joint 1 through the client library (`Joint::status`, a
/// `reply_timeout` of `timeout` and no retries) on vcan0, after 5 unmeasured ones (the
/// joint's identity is cached on first use, and the guest schedules the client for the
/// first time): the round trips of the answered ones, the send instants of the timed-out
/// ones, and any other failure.
fn client_round_trips(n: usize, timeout: Duration) -> (Vec<Duration>, Vec<Instant>, Vec<String>) {
    let config = JointBusConfig {
        reply_timeout: timeout,
        retries: 0,
        ..JointBusConfig::default()
    };
    let bus = JointBus::open_with(SocketCanLink::open("vcan0").unwrap(), config).unwrap();
    let joint = bus.joint_unchecked(JointId::new(1).unwrap());
    for _ in 0..5 {
        let _ = joint.status();
    }
    let mut failed = Vec::new();
    let mut missed = Vec::new();
    let mut rts = Vec::with_capacity(n);
    for i in 0..n {
        let t0 = Instant::now();
        match joint.status() {
            Ok(_) => rts.push(t0.elapsed()),
            Err(e) if e.is_timeout() => {
                println!("query {i}: {e}");
                missed.push(t0);
            }
            // The answer to the query before, which timed out, came during this one: this
            // one is not credited (right), and it is the earlier miss's consequence, counted
            // with the misses from the earlier query's start.
            Err(e @ WhjError::LateReply { .. }) => {
                println!("query {i}: {e}");
                missed.push(t0.checked_sub(timeout).unwrap_or(t0));
            }
            Err(e) => failed.push(format!("query {i}: {e}")),
        }
    }
    (rts, missed, failed)
}

fn percentile(sorted: &[Duration], p: f64) -> Duration {
    if sorted.is_empty() {
        return Duration::ZERO;
    }
    let i = ((sorted.len() - 1) as f64 * p).round();
    // In range by construction.
    #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
    sorted[i as usize]
}

/// Watches the guest's own scheduling: a thread that sleeps 1 ms at a time and records
/// every gap longer than [`STALL`]. The guest is one process on a shared build machine
/// whose CPU steal stalls it for milliseconds now and then (a 100 µs sleep there has a
/// p99 of 1-2 ms and wakes more than 2 ms late a few times in a thousand, on the host as
/// well as in the guest); a query whose 5 ms window saw such a stall says nothing about
/// the link. The witness does not see a late wake-up of the simulator or the client alone
/// (such as a timeout rounded up to the kernel tick): that still fails the test.
struct StallWitness {
    stop: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<Vec<(Instant, Instant)>>>,
}

const STALL: Duration = Duration::from_micros(2500);

impl StallWitness {
    fn start() -> Self {
        let stop = Arc::new(AtomicBool::new(false));
        let flag = Arc::clone(&stop);
        let thread = std::thread::spawn(move || {
            let mut gaps = Vec::new();
            let mut last = Instant::now();
            while !flag.load(Ordering::Relaxed) {
                std::thread::sleep(Duration::from_millis(1));
                let now = Instant::now();
                if now - last > STALL {
                    gaps.push((last, now));
                }
                last = now;
            }
            gaps
        });
        Self {
            stop,
            thread: Some(thread),
        }
    }

    /// Stops watching; returns the stalls seen.
    fn stop(mut self) -> Vec<(Instant, Instant)> {
        self.stop.store(true, Ordering::Relaxed);
        self.thread.take().unwrap().join().unwrap()
    }
}

/// The missed queries (sent at these instants) that no witnessed stall explains.
fn unexplained(missed: &[Instant], stalls: &[(Instant, Instant)], timeout: Duration) -> usize {
    missed
        .iter()
        .filter(|&&t0| {
            !stalls
                .iter()
                .any(|&(a, b)| b > t0 && a < t0 + timeout + Duration::from_millis(1))
        })
        .count()
}

fn summary(name: &str, mut rts: Vec<Duration>, missed: usize) -> (Duration, Duration) {
    rts.sort_unstable();
    let (median, p99) = (percentile(&rts, 0.5), percentile(&rts, 0.99));
    println!(
        "{name}: {} answered, {missed} timed out, median {:.1} µs, p99 {:.1} µs, max {:.1} µs",
        rts.len(),
        median.as_secs_f64() * 1e6,
        p99.as_secs_f64() * 1e6,
        rts.last().copied().unwrap_or_default().as_secs_f64() * 1e6,
    );
    (median, p99)
}

#[test]
fn whj_status_queries_with_a_5ms_timeout_on_vcan0_in_uml() {
    let out = run_inner_in_uml("inner_status_queries_5ms");
    eprintln!("{out}");
}

#[test]
#[ignore = "run by whj_status_queries_with_a_5ms_timeout_on_vcan0_in_uml inside User-Mode Linux"]
fn inner_status_queries_5ms() {
    in_guest();
    let dir = tempfile::tempdir().unwrap();
    let _sim = Sim::start(dir.path());

    // 1. A bare link: 500 queries, every reply within 5 ms.
    let mut link = SocketCanLink::open("vcan0").unwrap();
    let witness = StallWitness::start();
    let (rts, missed) = round_trips(&mut link, &status_query(), 0x701, QUERIES, TIMEOUT);
    let stalls = witness.stop();
    summary("SocketCanLink -> robobus sim whj", rts, missed.len());
    println!("guest stalls over {STALL:?} seen: {}", stalls.len());
    let unexcused = unexplained(&missed, &stalls, TIMEOUT);
    println!("misses no witnessed guest stall explains: {unexcused}");
    // A miss whose 5 ms window saw the guest stalled says nothing about the link (a loaded
    // build machine stalls the one guest CPU thousands of times a run). Of the others at
    // most 2 %: the guest can also stall the simulator process alone, which the witness
    // cannot see. A deadline rounded up to kernel ticks (12-20 ms in UML) misses most of
    // the 500 on a quiet machine (before the fix: 343).
    assert!(
        unexcused <= QUERIES / 50,
        "{unexcused} of {QUERIES} unanswered within {TIMEOUT:?} without a guest stall \
         ({} missed in all)",
        missed.len()
    );
    drop(link);

    // 2. The client library: Joint::status with a 5 ms reply timeout and no retries.
    let witness = StallWitness::start();
    let (rts, missed, failed) = client_round_trips(QUERIES, TIMEOUT);
    let stalls = witness.stop();
    summary("JointBus -> robobus sim whj", rts, missed.len());
    println!("guest stalls over {STALL:?} seen: {}", stalls.len());
    assert!(failed.is_empty(), "{failed:?}");
    let unexcused = unexplained(&missed, &stalls, TIMEOUT);
    println!("misses no witnessed guest stall explains: {unexcused}");
    // A miss whose 5 ms window saw the guest stalled says nothing about the link (a loaded
    // build machine stalls the one guest CPU thousands of times a run). Of the others at
    // most 2 %: the guest can also stall the simulator process alone, which the witness
    // cannot see. A deadline rounded up to kernel ticks (12-20 ms in UML) misses most of
    // the 500 on a quiet machine (before the fix: 343).
    assert!(
        unexcused <= QUERIES / 50,
        "{unexcused} of {QUERIES} unanswered within {TIMEOUT:?} without a guest stall \
         ({} missed in all)",
        missed.len()
    );
    println!("inner_status_queries_5ms OK");
}

#[test]
#[ignore = "benchmark: boots User-Mode Linux and prints round trips (run with --ignored --nocapture)"]
fn bench_vcan0_round_trip_against_can_utils_echo() {
    let out = run_inner_in_uml("inner_bench_round_trip");
    eprintln!("{out}");
}

fn modprobe_can_gw() {
    let uml = PathBuf::from(std::env::var(IN_UML_ENV).unwrap());
    let found = Command::new("find")
        .arg(uml.join("kernel/pkg"))
        .args(["-name", "can-gw.ko"])
        .output()
        .unwrap();
    let path = String::from_utf8_lossy(&found.stdout)
        .lines()
        .next()
        .map(str::to_owned);
    let path = path.expect("can-gw.ko in the UML kernel's modules");
    let ok = Command::new(uml.join("root/bin/busybox"))
        .args(["insmod", &path])
        .status()
        .unwrap()
        .success();
    assert!(ok, "insmod {path} failed");
}

fn run(cmd: &str, args: &[&str]) {
    let st = Command::new(cmd).args(args).status().unwrap();
    assert!(st.success(), "{cmd} {args:?} failed");
}

#[test]
#[ignore = "run by bench_vcan0_round_trip_against_can_utils_echo inside User-Mode Linux"]
fn inner_bench_round_trip() {
    in_guest();
    let n = 2000;
    let timeout = Duration::from_millis(100);
    let mut link = SocketCanLink::open("vcan0").unwrap();
    let query = status_query();

    // can-utils echo 1: a cangw rule routes 0x601 back onto vcan0 as 0x701 (in the kernel).
    modprobe_can_gw();
    let set_id = format!("SET:I:701.0.0.{}", "0".repeat(128));
    run(
        "cangw",
        &[
            "-A", "-s", "vcan0", "-d", "vcan0", "-i", "-e", "-X", "-l", "1", "-f", "601:7FF", "-M",
            &set_id,
        ],
    );
    let (rts, missed) = round_trips(&mut link, &query, 0x701, n, timeout);
    let gw = summary("cangw echo (kernel)", rts, missed.len());
    run("cangw", &["-F"]);

    // can-utils echo 2: canfdtest as the device under test (user space, classic CAN only:
    // it answers ID + 1 with every data byte + 1).
    let mut echo = Command::new("canfdtest")
        .arg("vcan0")
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(Duration::from_millis(300));
    // It checks that each frame carries its ID (0x77) and consecutive data bytes.
    let classic = CanFrame::new_classic(
        CanFrame::standard_id(0x77).unwrap(),
        &[0, 1, 2, 3, 4, 5, 6, 7],
    )
    .unwrap();
    let (rts, missed) = round_trips(&mut link, &classic, 0x78, n, timeout);
    let user = summary("canfdtest echo (user space, classic)", rts, missed.len());
    let _ = echo.kill();
    let _ = echo.wait();
    if let Some(out) = echo.stdout.take() {
        for l in BufReader::new(out).lines().map_while(Result::ok).take(3) {
            println!("canfdtest: {l}");
        }
    }

    // The simulator.
    let dir = tempfile::tempdir().unwrap();
    let sim = Sim::start(dir.path());
    let (rts, missed) = round_trips(&mut link, &query, 0x701, n, timeout);
    let ours = summary("robobus sim whj", rts, missed.len());
    drop(link);

    // The same queries through the client library (`Joint::status`: request, matching,
    // decoding), against the same simulator.
    let (rts, missed, failed) = client_round_trips(n, timeout);
    let client = summary(
        "JointBus::status -> robobus sim whj",
        rts,
        missed.len() + failed.len(),
    );
    drop(sim);
    let ratio = |a: Duration, b: Duration| a.as_secs_f64() / b.as_secs_f64().max(1e-9);
    println!(
        "ratio sim / cangw: median {:.2}, p99 {:.2}; sim / canfdtest: median {:.2}, p99 {:.2}",
        ratio(ours.0, gw.0),
        ratio(ours.1, gw.1),
        ratio(ours.0, user.0),
        ratio(ours.1, user.1),
    );
    // The simulator holds each reply back until the modelled wire (1 / 5 Mbit/s) and the
    // joint's 20 µs processing would have let it go: an echo has no such floor.
    let reply = CanFrame::new_fd(CanFrame::standard_id(0x701).unwrap(), &[0x55; 16]).unwrap();
    let floor = frame_duration(&query, BitRates::WHJ)
        + frame_duration(&reply, BitRates::WHJ)
        + Duration::from_micros(20);
    println!(
        "modelled floor of the simulator's round trip (wire + processing): {:.1} µs; \
         sim median / floor {:.2}",
        floor.as_secs_f64() * 1e6,
        ratio(ours.0, floor)
    );
    println!(
        "ratio client / cangw: median {:.2}, p99 {:.2}; client / bare link: median {:.2}, p99 {:.2}",
        ratio(client.0, gw.0),
        ratio(client.1, gw.1),
        ratio(client.0, ours.0),
        ratio(client.1, ours.1),
    );
    println!("inner_bench_round_trip OK");
}
