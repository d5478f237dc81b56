//! `robobus-bench`: runs the benchmark suite and writes the report.
//!
//! ```text
//! robobus-bench [--smoke] [--out DIR] [--python PATH] [--udp] [--criterion DIR]
//! robobus-bench serve-whj --joints N --delay-us D [--fast-wire] [--wait sleep|spin]
//! robobus-bench poll-wck --servos N --baud B --secs S [--turnaround] [--wait sleep|spin] [--memory|--tcp] [--no-guard]
//! robobus-bench slcan [--joints N] [--secs S]
//! robobus-bench telemetry --secs S
//! robobus-bench studio --secs S
//! robobus-bench bridge [--bridges N] [--rate HZ] [--secs S] [--smoke]
//! robobus-bench servo-whj --joints N --secs S [--delay-us D] [--fast-wire] [--wait sleep|spin] [--no-window] [--pipelined]
//! ```
//!
//! `telemetry` runs the telemetry fan-out cases alone and prints their section of the
//! report; `studio` runs the web studio case alone (1 and 4 pages, then the jog) and
//! prints its section; `bridge` runs the Zenoh bridge case alone (N bridges of 7 joints
//! into one router: latency, loss, rate, CPU per joint) and prints its section.
//! `poll-wck` runs the wCK polling case alone, once, and prints its rate as a share of the
//! wire (for a quick look, or under `strace`); `free-whj` the WHJ free-running case over
//! the memory bus. Both take `--wait sleep|spin` (spin: the client spins for its replies
//! and the simulator serves in its precise mode); `poll-wck --tcp` serves the simulator
//! over TCP on 127.0.0.1 instead of the pty, `poll-wck --no-guard` turns the client's
//! guard after each reply off (`WckConfig::guard: Some(0)`; the default guard otherwise). `syscalls` counts system calls per
//! transaction with `strace`; `echo` measures the pty's, TCP's and the memory bus's own
//! round trip.

use std::io::Write as _;
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

use robobus_bench::{Options, report, run, wck, whj};

fn usage() -> ExitCode {
    let _ = writeln!(
        std::io::stderr(),
        "usage: robobus-bench [--smoke] [--out DIR] [--python PATH] [--udp] [--criterion DIR]\n       robobus-bench serve-whj --joints N --delay-us D [--fast-wire] [--wait sleep|spin]\n       robobus-bench poll-wck --servos N --baud B --secs S [--turnaround] [--wait sleep|spin] [--memory|--tcp] [--no-guard]\n       robobus-bench telemetry --secs S\n       robobus-bench studio --secs S\n       robobus-bench bridge [--bridges N] [--rate HZ] [--secs S] [--smoke]\n       robobus-bench servo-whj --joints N --secs S [--delay-us D] [--fast-wire] [--wait sleep|spin] [--no-window] [--external-sim] [--pipelined] [--default-slack]\n       robobus-bench free-whj --joints N --secs S [--delay-us D] [--fast-wire] [--wait sleep|spin] [--no-window] [--pipelined] [--default-slack]\n       robobus-bench syscalls [--udp] [--python PATH]\n       robobus-bench echo\n       robobus-bench slcan [--joints N] [--secs S]"
    );
    ExitCode::from(2)
}

/// `--joints N --delay-us D [--fast-wire]` and, where `secs` is given, `--secs S`.
fn chain_args(args: &[String], mut secs: Option<&mut f64>) -> Option<whj::ChainSpec> {
    let mut spec = whj::ChainSpec {
        joints: 1,
        delay: whj::DEFAULT_DELAY,
        fast_wire: false,
        wait: robobus_link::WaitMode::Sleep,
        collision_window: true,
    };
    let mut it = args.iter();
    while let Some(a) = it.next() {
        match a.as_str() {
            "--joints" => match it.next().and_then(|v| v.parse().ok()) {
                Some(n) if (1..=30).contains(&n) => spec.joints = n,
                _ => return None,
            },
            "--delay-us" => match it.next().and_then(|v| v.parse::<u64>().ok()) {
                Some(us) if us <= 100_000 => spec.delay = Duration::from_micros(us),
                _ => return None,
            },
            "--secs" if secs.is_some() => match it.next().and_then(|v| v.parse::<f64>().ok()) {
                Some(v) if (0.01..=600.0).contains(&v) => **secs.as_mut()? = v,
                _ => return None,
            },
            "--fast-wire" => spec.fast_wire = true,
            "--no-window" => spec.collision_window = false,
            "--wait" => spec.wait = it.next()?.parse().ok()?,
            _ => return None,
        }
    }
    Some(spec)
}

fn serve_whj(args: &[String]) -> ExitCode {
    let Some(spec) = chain_args(args, None) else {
        return usage();
    };
    match whj::serve_whj_process(spec) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            let _ = writeln!(std::io::stderr(), "serve-whj: {e}");
            ExitCode::FAILURE
        }
    }
}

/// `slcan [--joints N] [--secs S]`: the client through an emulated slcan adapter on a pty.
fn slcan(args: &[String]) -> ExitCode {
    let mut joints = 7u8;
    let mut secs = 2.0_f64;
    let mut it = args.iter();
    while let Some(a) = it.next() {
        match a.as_str() {
            "--joints" => match it.next().and_then(|v| v.parse().ok()) {
                Some(n) if (1..=7).contains(&n) => joints = n,
                _ => return usage(),
            },
            "--secs" => match it.next().and_then(|v| v.parse().ok()) {
                Some(s) if (0.1..=600.0).contains(&s) => secs = s,
                _ => return usage(),
            },
            _ => return usage(),
        }
    }
    let period = Duration::from_millis(4);
    match robobus_bench::slcan::run(joints, 500, period, Duration::from_secs_f64(secs)) {
        Ok(r) => {
            let _ = writeln!(std::io::stdout(), "{}", r.lines());
            ExitCode::SUCCESS
        }
        Err(e) => {
            let _ = writeln!(std::io::stderr(), "slcan: {e}");
            ExitCode::FAILURE
        }
    }
}

fn poll_wck(args: &[String]) -> ExitCode {
    let mut spec = wck::PollSpec {
        servos: 1,
        baud: robobus_wck::BaudRate::B115200,
        manual_turnaround: false,
        wait: robobus_link::WaitMode::Sleep,
        memory: false,
        guard: true,
    };
    let mut secs = 1.0_f64;
    let mut tcp = false;
    let mut it = args.iter();
    while let Some(a) = it.next() {
        match a.as_str() {
            "--servos" => match it.next().and_then(|v| v.parse().ok()) {
                Some(n) if (1..=31).contains(&n) => spec.servos = n,
                _ => return usage(),
            },
            "--baud" => match it
                .next()
                .and_then(|v| v.parse().ok())
                .and_then(|b| robobus_wck::BaudRate::from_bits_per_second(b).ok())
            {
                Some(b) => spec.baud = b,
                None => return usage(),
            },
            "--secs" => match it.next().and_then(|v| v.parse().ok()) {
                Some(s) if (0.01..=600.0).contains(&s) => secs = s,
                _ => return usage(),
            },
            "--turnaround" => spec.manual_turnaround = true,
            "--memory" => spec.memory = true,
            "--no-guard" => spec.guard = false,
            "--tcp" => tcp = true,
            "--wait" => match it.next().map(|v| v.parse()) {
                Some(Ok(w)) => spec.wait = w,
                Some(Err(e)) => {
                    let _ = writeln!(std::io::stderr(), "poll-wck: --wait: {e}");
                    return ExitCode::from(2);
                }
                None => return usage(),
            },
            _ => return usage(),
        }
    }
    let duration = Duration::from_secs_f64(secs);
    let run = if tcp {
        wck::poll_tcp(spec, duration)
    } else {
        wck::poll(spec, duration, None)
    };
    match run {
        Ok(r) => {
            let _ = writeln!(
                std::io::stdout(),
                "{} servo(s) at {}, wait {}, guard {}: {} cycles, {} errors, {:.1} Hz, {:.1} % of the \
                 wire, client CPU {:.1} µs/cycle; simulator late p50 {} p99 {}",
                spec.servos,
                spec.baud,
                spec.wait,
                if spec.guard { "default" } else { "off" },
                r.cycles,
                r.errors,
                r.rate_hz(),
                r.efficiency() * 100.0,
                r.cpu_per_cycle_us(),
                report::opt_us(r.endpoint.lateness.p50),
                report::opt_us(r.endpoint.lateness.p99),
            );
            ExitCode::SUCCESS
        }
        Err(e) => {
            let _ = writeln!(std::io::stderr(), "poll-wck: {e}");
            ExitCode::FAILURE
        }
    }
}

/// `servo-whj`: the free-running servo cycle alone, ours over python-can's UDP multicast
/// bus against a simulator process (run it inside a network namespace with a multicast
/// route on loopback).
fn servo_whj(args: &[String]) -> ExitCode {
    let args = &default_slack_if_asked(args);
    let mut secs = 3.0;
    // With `--external-sim`, a simulator process serves already (counting system calls).
    let external = args.iter().any(|a| a == "--external-sim");
    // With `--pipelined`, each cycle's frames go out in one batch (`JointBus::servo_many`).
    let pipelined = args.iter().any(|a| a == "--pipelined");
    let args: Vec<String> = args
        .iter()
        .filter(|a| *a != "--external-sim" && *a != "--pipelined")
        .cloned()
        .collect();
    let Some(spec) = chain_args(&args, Some(&mut secs)) else {
        return usage();
    };
    if external {
        return match whj::udp_client(spec, Duration::from_secs_f64(secs), None, pipelined) {
            Ok(r) => {
                let _ = writeln!(
                    std::io::stdout(),
                    "servo-whj {} joint(s) UDP: {} cycles, {} errors",
                    spec.joints,
                    r.cycles,
                    r.errors
                );
                ExitCode::SUCCESS
            }
            Err(e) => {
                let _ = writeln!(std::io::stderr(), "servo-whj: {e}");
                ExitCode::FAILURE
            }
        };
    }
    let exe = match std::env::current_exe() {
        Ok(e) => e,
        Err(e) => {
            let _ = writeln!(std::io::stderr(), "servo-whj: {e}");
            return ExitCode::FAILURE;
        }
    };
    match whj::udp_compare(&exe, spec, Duration::from_secs_f64(secs), None, pipelined) {
        Ok(r) => {
            let _ = writeln!(
                std::io::stdout(),
                "servo-whj {} joint(s) UDP: {:.0} Hz, {} errors, client CPU {:.1} µs/cycle",
                spec.joints,
                r.rate_hz(),
                r.errors,
                r.cpu_per_cycle_us()
            );
            ExitCode::SUCCESS
        }
        Err(e) => {
            let _ = writeln!(std::io::stderr(), "servo-whj: {e}");
            ExitCode::FAILURE
        }
    }
}

/// `--default-slack` (for `free-whj` and `servo-whj`): the client's thread waits with
/// Linux's default timer slack (50 µs) instead of the 1 ns the library's first wait sets
/// (`robobus_link::wait::precise_timers`), to compare the two in one run; the simulator
/// keeps its own. Returns the other arguments.
fn default_slack_if_asked(args: &[String]) -> Vec<String> {
    if args.iter().any(|a| a == "--default-slack") {
        // The library sets it once per thread: set it first, then put the default back.
        robobus_link::wait::precise_timers();
        #[cfg(target_os = "linux")]
        if let Err(e) = nix::sys::prctl::set_timerslack(50_000) {
            let _ = writeln!(std::io::stderr(), "--default-slack: {e}");
        }
    }
    args.iter()
        .filter(|a| *a != "--default-slack")
        .cloned()
        .collect()
}

/// `free-whj`: the free-running servo cycle alone over the in-process memory bus.
fn free_whj(args: &[String]) -> ExitCode {
    let args = &default_slack_if_asked(args);
    let mut secs = 1.5;
    let pipelined = args.iter().any(|a| a == "--pipelined");
    let args: Vec<String> = args
        .iter()
        .filter(|a| *a != "--pipelined")
        .cloned()
        .collect();
    let Some(spec) = chain_args(&args, Some(&mut secs)) else {
        return usage();
    };
    let duration = Duration::from_secs_f64(secs);
    let run = whj::free_running_memory(spec, duration, pipelined);
    match run {
        Ok(r) => {
            let late = r.sim_lateness.unwrap_or_default();
            let _ = writeln!(
                std::io::stdout(),
                "free-whj {} joint(s) {}, wait {}, collision window {}: {:.0} cycles/s, \
                 {:.1} % of the wire, {} errors, client CPU {:.1} µs/cycle; simulator late \
                 p50 {} p99 {}",
                spec.joints,
                r.link,
                spec.wait,
                if spec.collision_window { "on" } else { "off" },
                r.rate_hz(),
                r.efficiency() * 100.0,
                r.errors,
                r.cpu_per_cycle_us(),
                report::opt_us(late.p50),
                report::opt_us(late.p99),
            );
            ExitCode::SUCCESS
        }
        Err(e) => {
            let _ = writeln!(std::io::stderr(), "free-whj: {e}");
            ExitCode::FAILURE
        }
    }
}

fn telemetry(args: &[String]) -> ExitCode {
    let secs = match args {
        [] => 3.0,
        [flag, v] if flag == "--secs" => match v.parse::<f64>() {
            Ok(s) if (0.01..=600.0).contains(&s) => s,
            _ => return usage(),
        },
        _ => return usage(),
    };
    let mut r = robobus_bench::Results::default();
    for rate in [200.0, 1000.0] {
        for subs in [1, 8] {
            match robobus_bench::telemetry::fan_out(rate, subs, Duration::from_secs_f64(secs)) {
                Ok(t) => r.telemetry.push(t),
                Err(e) => {
                    let _ = writeln!(std::io::stderr(), "telemetry: {e}");
                    return ExitCode::FAILURE;
                }
            }
        }
    }
    let _ = write!(std::io::stdout(), "{}", report::telemetry_markdown(&r));
    ExitCode::SUCCESS
}

fn studio(args: &[String]) -> ExitCode {
    let secs = match args {
        [] => 5.0,
        [flag, v] if flag == "--secs" => match v.parse::<f64>() {
            Ok(s) if (0.01..=600.0).contains(&s) => s,
            _ => return usage(),
        },
        _ => return usage(),
    };
    let mut machine = robobus_bench::Machine::probe();
    match robobus_bench::studio::run(&[1, 4], Duration::from_secs_f64(secs)) {
        Ok(s) => {
            machine.load_after = std::fs::read_to_string("/proc/loadavg")
                .map(|l| l.trim().to_owned())
                .unwrap_or_default();
            let r = robobus_bench::Results {
                studio: Some(s),
                machine,
                ..robobus_bench::Results::default()
            };
            let _ = write!(std::io::stdout(), "{}", report::studio_markdown(&r));
            ExitCode::SUCCESS
        }
        Err(e) => {
            let _ = writeln!(std::io::stderr(), "studio: {e}");
            ExitCode::FAILURE
        }
    }
}

/// `bridge`: N bridges into one Zenoh router (the full run's defaults, or smoke mode's
/// with `--smoke`; the other options override either).
fn bridge(args: &[String]) -> ExitCode {
    let mut spec = if args.iter().any(|a| a == "--smoke") {
        robobus_bench::bridge::Spec::smoke()
    } else {
        robobus_bench::bridge::Spec::full()
    };
    let mut it = args.iter();
    while let Some(a) = it.next() {
        match a.as_str() {
            "--smoke" => {}
            "--bridges" => match it.next().and_then(|v| v.parse().ok()) {
                Some(n) if robobus_bench::bridge::BRIDGES.contains(&n) => spec.bridges = n,
                _ => return usage(),
            },
            "--rate" => match it.next().and_then(|v| v.parse::<f64>().ok()) {
                Some(hz) if robobus::catalogue::telemetry::RATE_HZ.contains(&hz) => {
                    spec.rate_hz = hz;
                }
                _ => return usage(),
            },
            "--secs" => match it.next().and_then(|v| v.parse::<f64>().ok()) {
                Some(s) if (0.1..=600.0).contains(&s) => spec.secs = Duration::from_secs_f64(s),
                _ => return usage(),
            },
            _ => return usage(),
        }
    }
    let mut machine = robobus_bench::Machine::probe();
    match robobus_bench::bridge::run(spec) {
        Ok(b) => {
            machine.load_after = std::fs::read_to_string("/proc/loadavg")
                .map(|l| l.trim().to_owned())
                .unwrap_or_default();
            let m = &machine;
            let _ = writeln!(
                std::io::stdout(),
                "{}Machine: {} logical CPUs, {}, Linux {}; load average before: {}; after: {}.",
                robobus_bench::bridge::markdown(Some(&b), m),
                m.cpus,
                m.model,
                m.kernel,
                m.load_before,
                m.load_after
            );
            ExitCode::SUCCESS
        }
        Err(e) => {
            let _ = writeln!(std::io::stderr(), "bridge: {e}");
            ExitCode::FAILURE
        }
    }
}

/// Writes the bridge section into the suite's report, before its simulator section
/// (the report itself is `report::write`'s).
fn add_bridge_section(
    path: &std::path::Path,
    results: &robobus_bench::Results,
) -> std::io::Result<()> {
    let md = std::fs::read_to_string(path)?;
    let section = robobus_bench::bridge::markdown(results.bridge.as_ref(), &results.machine);
    let md = match md.find("## Simulator\n") {
        Some(at) => format!("{}{section}{}", &md[..at], &md[at..]),
        None => format!("{md}\n{section}"),
    };
    std::fs::write(path, md)
}

/// `syscalls [--udp]`: system calls per transaction, counted with `strace`.
fn syscalls(args: &[String]) -> ExitCode {
    let exe = std::env::current_exe().unwrap_or_else(|_| PathBuf::from("robobus-bench"));
    let udp = args.iter().any(|a| a == "--udp");
    let python = args
        .iter()
        .position(|a| a == "--python")
        .and_then(|i| args.get(i + 1))
        .map(PathBuf::from);
    if !robobus_bench::syscalls::strace_available() {
        let _ = writeln!(std::io::stderr(), "syscalls: strace is not installed");
        return ExitCode::FAILURE;
    }
    let (cases, notes) = robobus_bench::syscalls::measure(&exe, udp, python.as_deref());
    let r = robobus_bench::Results {
        syscalls: cases,
        notes,
        ..robobus_bench::Results::default()
    };
    let _ = write!(std::io::stdout(), "{}", report::syscalls_markdown(&r));
    ExitCode::SUCCESS
}

/// `echo`: the pty's, TCP's and the memory bus's own round trip, both sides spinning.
fn echo() -> ExitCode {
    for (what, r) in [
        ("pty", robobus_bench::transport::pty_echo(5000)),
        ("TCP (127.0.0.1)", robobus_bench::transport::tcp_echo(5000)),
        ("memory bus", robobus_bench::transport::memory_echo(5000)),
    ] {
        match r {
            Ok(s) => {
                let _ = writeln!(
                    std::io::stdout(),
                    "{what} echo, both sides spinning: p50 {:.1} µs, p99 {:.1} µs",
                    s.p50,
                    s.p99
                );
            }
            Err(e) => {
                let _ = writeln!(std::io::stderr(), "echo: {e}");
                return ExitCode::FAILURE;
            }
        }
    }
    ExitCode::SUCCESS
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let rest = args.get(1..).unwrap_or_default();
    match args.first().map(String::as_str) {
        Some("serve-whj") => return serve_whj(rest),
        Some("servo-whj") => return servo_whj(rest),
        Some("free-whj") => return free_whj(rest),
        Some("telemetry") => return telemetry(rest),
        Some("studio") => return studio(rest),
        Some("bridge") => return bridge(rest),
        Some("poll-wck") => return poll_wck(rest),
        Some("slcan") => return slcan(rest),
        Some("syscalls") => return syscalls(rest),
        Some("echo") => return echo(),
        _ => {}
    }
    let mut opts = Options {
        smoke: false,
        out: PathBuf::from("target/bench-report"),
        python: None,
        udp: false,
        exe: std::env::current_exe().unwrap_or_else(|_| PathBuf::from("robobus-bench")),
        criterion: None,
    };
    let mut it = args.iter();
    while let Some(a) = it.next() {
        match a.as_str() {
            "--smoke" => opts.smoke = true,
            "--udp" => opts.udp = true,
            "--out" => match it.next() {
                Some(v) => opts.out = v.into(),
                None => return usage(),
            },
            "--python" => match it.next() {
                Some(v) => opts.python = Some(v.into()),
                None => return usage(),
            },
            "--criterion" => match it.next() {
                Some(v) => opts.criterion = Some(v.into()),
                None => return usage(),
            },
            _ => return usage(),
        }
    }
    let results = run(&opts, |line| {
        let _ = writeln!(std::io::stderr(), "bench: {line}");
    });
    match report::write(&results, &opts.out) {
        Ok(path) => {
            if let Err(e) = add_bridge_section(&path, &results) {
                let _ = writeln!(std::io::stderr(), "bench: {}: {e}", path.display());
                return ExitCode::FAILURE;
            }
            let _ = writeln!(std::io::stdout(), "{}", path.display());
        }
        Err(e) => {
            let _ = writeln!(std::io::stderr(), "bench: {e}");
            return ExitCode::FAILURE;
        }
    }
    if results.failures > 0 {
        let _ = writeln!(
            std::io::stderr(),
            "bench: {} benchmark(s) failed",
            results.failures
        );
        return ExitCode::FAILURE;
    }
    ExitCode::SUCCESS
}
