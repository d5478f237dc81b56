//! robobus benchmarks: control loops against the modelled physical limit of the bus,
//! against what users would write instead (Python with pyserial / python-can), the
//! simulators' own speed, and the codec cost per packet.
//!
//! The program `robobus-bench` (run by `scripts/bench/run`) runs the suite and writes
//! `report.md` with SVG latency histograms to `target/bench-report/`; `--smoke` runs every
//! benchmark briefly, which is what the tests do. Method and formulas: `BENCHMARKS.md`
//! and the `timing` modules of `robobus_wck` and `robobus_whj`.
//!
//! Every control loop is reported as an efficiency: the modelled wire + device time of
//! what was exchanged (from `robobus_wck::timing` and `robobus_whj::timing`) divided by the
//! measured cycle time. The simulators release each reply when its last bit would leave
//! the wire, so a perfect client reaches 100 %.
//!
//! ```
//! use robobus_bench::stats::Summary;
//! use robobus_bench::wck::PollSpec;
//! use robobus_wck::BaudRate;
//!
//! // 31 servos at 115200 bit/s with the manual's turnaround: 31 × 1527.4 µs per cycle.
//! let spec = PollSpec {
//!     servos: 31,
//!     baud: BaudRate::B115200,
//!     manual_turnaround: true,
//!     wait: robobus_link::WaitMode::Sleep,
//!     memory: false,
//!     guard: true,
//! };
//! let cycle = spec.modelled_cycle().as_secs_f64();
//! assert!((1.0 / cycle - 21.1).abs() < 0.1);
//!
//! let s = Summary::of_us(&[10.0, 20.0, 30.0, 40.0]);
//! assert_eq!((s.p50, s.max), (20.0, 40.0));
//! ```

pub mod bridge;
pub mod codec;
pub mod cpu;
pub mod observe;
pub mod peers;
pub mod report;
pub mod simspeed;
pub mod slcan;
pub mod stats;
pub mod studio;
pub mod svg;
pub mod syscalls;
pub mod telemetry;
pub mod transport;
pub mod wck;
pub mod whj;

use std::fmt;
use std::path::PathBuf;
use std::time::Duration;

use robobus::whj::Protocol;
use robobus_link::WaitMode;
use robobus_wck::BaudRate;

/// A benchmark that could not run, with what it was doing.
#[derive(Debug)]
pub struct BenchError {
    context: String,
    source: Option<Box<dyn std::error::Error + Send + Sync>>,
}

impl BenchError {
    /// `context` failed because of `source`.
    pub fn new(
        context: impl Into<String>,
        source: impl Into<Box<dyn std::error::Error + Send + Sync>>,
    ) -> Self {
        Self {
            context: context.into(),
            source: Some(source.into()),
        }
    }

    /// A failure described by `message` alone.
    pub fn msg(message: impl Into<String>) -> Self {
        Self {
            context: message.into(),
            source: None,
        }
    }
}

impl fmt::Display for BenchError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match &self.source {
            Some(s) => write!(f, "{}: {s}", self.context),
            None => f.write_str(&self.context),
        }
    }
}

impl std::error::Error for BenchError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        self.source
            .as_deref()
            .map(|e| e as &(dyn std::error::Error + 'static))
    }
}

/// What to run.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Options {
    /// Run each benchmark briefly (checks that they run; numbers are not meaningful).
    pub smoke: bool,
    /// Report directory.
    pub out: PathBuf,
    /// Python with pyserial and python-can (the peers); `None` skips the peers.
    pub python: Option<PathBuf>,
    /// Whether the UDP multicast bus works here (a private network namespace with a
    /// multicast route on loopback); `false` skips the UDP runs.
    pub udp: bool,
    /// This program (started again as the WHJ simulator process for the UDP runs).
    pub exe: PathBuf,
    /// Criterion's output directory (`<target>/criterion`), to take the codec numbers
    /// from a criterion run.
    pub criterion: Option<PathBuf>,
}

/// The machine a run came from.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Machine {
    /// Logical CPUs.
    pub cpus: usize,
    /// CPU model (`/proc/cpuinfo`).
    pub model: String,
    /// Kernel release.
    pub kernel: String,
    /// `/proc/loadavg` at the start.
    pub load_before: String,
    /// `/proc/loadavg` at the end.
    pub load_after: String,
}

fn read_trim(path: &str) -> String {
    std::fs::read_to_string(path)
        .map(|s| s.trim().to_string())
        .unwrap_or_default()
}

impl Machine {
    /// This machine, now.
    pub fn probe() -> Self {
        let model = std::fs::read_to_string("/proc/cpuinfo")
            .ok()
            .and_then(|s| {
                s.lines()
                    .find(|l| l.starts_with("model name"))
                    .and_then(|l| l.split_once(':'))
                    .map(|(_, v)| v.trim().to_string())
            })
            .unwrap_or_else(|| "unknown".into());
        Self {
            cpus: std::thread::available_parallelism().map_or(1, std::num::NonZero::get),
            model,
            kernel: read_trim("/proc/sys/kernel/osrelease"),
            load_before: read_trim("/proc/loadavg"),
            load_after: String::new(),
        }
    }
}

/// Everything one run measured.
#[derive(Debug, Clone, Default)]
pub struct Results {
    /// Smoke mode.
    pub smoke: bool,
    /// Where it ran.
    pub machine: Machine,
    /// Codec cases.
    pub codec: Vec<codec::CodecCase>,
    /// wCK polling.
    pub polls: Vec<wck::PollResult>,
    /// wCK synchronized-move streaming.
    pub streams: Vec<wck::StreamResult>,
    /// WHJ free-running cycles on the memory bus.
    pub free: Vec<whj::FreeResult>,
    /// WHJ fixed-rate loops on the memory bus.
    pub fixed: Vec<whj::FixedResult>,
    /// WHJ free-running cycles on the UDP bus, with the python-can peer.
    pub udp: Vec<whj::FreeResult>,
    /// Simulator speed on the virtual clock.
    pub sims: Vec<simspeed::SimSpeed>,
    /// The telemetry stream with one subscriber and with eight (one never reading).
    pub telemetry: Vec<telemetry::FanOut>,
    /// The web studio: telemetry to its pages and jog latency.
    pub studio: Option<studio::StudioResult>,
    /// Zenoh bridges into one router: joint state latency, loss, rate and CPU.
    pub bridge: Option<bridge::BridgeResult>,
    /// System calls per transaction (full runs with `strace`).
    pub syscalls: Vec<syscalls::SyscallCase>,
    /// The transports' own round trip, both sides spinning: the pty, the memory bus.
    pub echo: Option<(stats::Summary, stats::Summary)>,
    /// Benchmarks that failed or were skipped, and why.
    pub notes: Vec<String>,
    /// How many benchmarks failed.
    pub failures: usize,
}

#[allow(clippy::too_many_lines)] // the suite, benchmark by benchmark
/// Runs the suite; `log` gets one line per benchmark as it starts.
pub fn run(opts: &Options, mut log: impl FnMut(&str)) -> Results {
    let smoke = opts.smoke;
    let mut r = Results {
        smoke,
        machine: Machine::probe(),
        ..Results::default()
    };
    let secs = |full: f64, quick: f64| Duration::from_secs_f64(if smoke { quick } else { full });

    log("codec");
    r.codec = codec::measure(if smoke { 20_000 } else { 2_000_000 });
    if let Some(dir) = &opts.criterion {
        codec::attach_criterion(&mut r.codec, dir);
    }

    // wCK polling.
    let bauds = [BaudRate::B115200, BaudRate::B921600];
    let mut polls: Vec<(wck::PollSpec, bool)> = Vec::new();
    // The low-latency mode: the client spins for its replies, the endpoint serves in its
    // precise mode; over the pty and over the in-process memory byte link (no kernel).
    let spin = |servos, baud, memory| wck::PollSpec {
        wait: WaitMode::SPIN,
        memory,
        ..spec(servos, baud, false)
    };
    if smoke {
        polls.push((spec(1, BaudRate::B921600, false), true));
        polls.push((spec(31, BaudRate::B115200, true), false));
        polls.push((spin(1, BaudRate::B921600, false), false));
        polls.push((spin(1, BaudRate::B921600, true), false));
    } else {
        for baud in bauds {
            for manual in [true, false] {
                for n in [1u8, 8, 16, 31] {
                    polls.push((spec(n, baud, manual), !manual && (n == 1 || n == 31)));
                }
            }
            for memory in [false, true] {
                for n in [1u8, 8, 31] {
                    polls.push((spin(n, baud, memory), !memory && n == 1));
                }
            }
        }
    }
    // Each case with the client's default guard after every reply, then with the guard
    // off (the report gives the ratio); the Python peer runs beside the default.
    let polls = polls
        .into_iter()
        .flat_map(|(s, with_peer)| [(s, with_peer), (wck::PollSpec { guard: false, ..s }, false)]);
    for (s, with_peer) in polls {
        let what = format!("wCK polling {}", s.label());
        log(&what);
        let py = if with_peer {
            opts.python.as_deref()
        } else {
            None
        };
        match wck::poll(s, secs(3.0, 0.15), py) {
            Ok(p) => r.polls.push(p),
            Err(e) => fail(&mut r, &mut log, &what, &e),
        }
    }
    let stream_bauds: &[BaudRate] = if smoke { &[BaudRate::B921600] } else { &bauds };
    for &baud in stream_bauds {
        let what = format!(
            "wCK sync-move streaming at {} bit/s",
            baud.bits_per_second()
        );
        log(&what);
        match wck::sync_stream(baud, secs(3.0, 0.1)) {
            Ok(s) => r.streams.push(s),
            Err(e) => fail(&mut r, &mut log, &what, &e),
        }
    }

    // WHJ on the memory bus: the present rows (sleep, collision window on), then both
    // wait modes without the collision window and the spin mode with it.
    let mut free: Vec<whj::ChainSpec> = Vec::new();
    let sizes: &[u8] = if smoke { &[1] } else { &[1, 7, 14] };
    for &n in sizes {
        free.push(chain(n, whj::DEFAULT_DELAY, false));
    }
    let variant = |n, wait, collision_window| whj::ChainSpec {
        wait,
        collision_window,
        ..chain(n, whj::DEFAULT_DELAY, false)
    };
    let sizes: &[u8] = if smoke { &[1] } else { &[1, 7] };
    for &n in sizes {
        free.push(variant(n, WaitMode::Sleep, false));
        free.push(variant(n, WaitMode::SPIN, false));
        if !smoke {
            free.push(variant(n, WaitMode::SPIN, true));
        }
    }
    // Pipelined (one `servo_many` batch a cycle), 7 joints, the check on and off, both
    // wait modes (the smoke run: one, to keep the row kind).
    let mut free: Vec<(whj::ChainSpec, bool)> = free.into_iter().map(|s| (s, false)).collect();
    if smoke {
        free.push((variant(1, WaitMode::Sleep, true), true));
    } else {
        for wait in [WaitMode::Sleep, WaitMode::SPIN] {
            for window in [true, false] {
                free.push((variant(7, wait, window), true));
            }
        }
    }
    for (spec, pipelined) in free {
        let what = format!(
            "WHJ free-running{}, {}, memory bus",
            if pipelined { " pipelined" } else { "" },
            spec.label()
        );
        log(&what);
        match whj::free_running_memory(spec, secs(3.0, 0.1), pipelined) {
            Ok(f) => r.free.push(f),
            Err(e) => fail(&mut r, &mut log, &what, &e),
        }
    }
    let mut fixed: Vec<(u8, u32, Protocol, WaitMode)> = Vec::new();
    if smoke {
        fixed.push((7, 1000, Protocol::PointToPoint, WaitMode::Sleep));
        fixed.push((7, 500, Protocol::Broadcast, WaitMode::Sleep));
        fixed.push((1, 1000, Protocol::PointToPoint, WaitMode::SPIN));
    } else {
        for hz in [500, 1000] {
            for n in [1u8, 7, 14] {
                fixed.push((n, hz, Protocol::PointToPoint, WaitMode::Sleep));
            }
            fixed.push((7, hz, Protocol::Broadcast, WaitMode::Sleep));
            for n in [1u8, 7] {
                fixed.push((n, hz, Protocol::PointToPoint, WaitMode::SPIN));
            }
        }
    }
    for (n, hz, p, wait) in fixed {
        let what = format!("WHJ fixed {hz} Hz, {n} joints, {p:?}, wait {wait}, memory bus");
        log(&what);
        let spec = whj::ChainSpec {
            wait,
            ..chain(n, whj::DEFAULT_DELAY, false)
        };
        match whj::fixed_rate(spec, hz, p, secs(5.0, 0.3)) {
            Ok(f) => r.fixed.push(f),
            Err(e) => fail(&mut r, &mut log, &what, &e),
        }
    }

    // WHJ over UDP with the python-can peer (zero processing delay).
    if opts.udp {
        let plain = |n, fast| chain(n, Duration::ZERO, fast);
        // Without the collision window (the peer has none), in both wait modes.
        let bare = |n, wait| whj::ChainSpec {
            wait,
            collision_window: false,
            ..plain(n, false)
        };
        let mut runs = vec![(plain(1, false), false)];
        if !smoke {
            runs.extend([
                (plain(7, false), false),
                (plain(1, true), false),
                (plain(7, true), false),
                (bare(1, WaitMode::Sleep), false),
                (bare(1, WaitMode::SPIN), false),
                // One servo_many batch a cycle, the check on, against python-can's loop.
                (plain(7, false), true),
            ]);
        }
        for (spec, pipelined) in runs {
            let what = format!(
                "WHJ free-running{} over UDP, {}, {}",
                if pipelined { " pipelined" } else { "" },
                spec.label(),
                if spec.fast_wire {
                    "wire off"
                } else {
                    "1 / 5 Mbit/s wire"
                }
            );
            log(&what);
            match whj::udp_compare(
                &opts.exe,
                spec,
                secs(3.0, 0.3),
                opts.python.as_deref(),
                pipelined,
            ) {
                Ok(f) => r.udp.push(f),
                Err(e) => fail(&mut r, &mut log, &what, &e),
            }
        }
    } else {
        r.notes
            .push("UDP runs skipped (no network namespace with a multicast route)".into());
    }
    log("transports: pty and memory bus echo");
    let echoes = if smoke { 200 } else { 5000 };
    match transport::pty_echo(echoes).and_then(|p| Ok((p, transport::memory_echo(echoes)?))) {
        Ok(e) => r.echo = Some(e),
        Err(e) => fail(&mut r, &mut log, "transport echo", &e),
    }
    if !smoke {
        if syscalls::strace_available() {
            log("system calls per transaction (strace)");
            let (cases, notes) = syscalls::measure(&opts.exe, opts.udp, opts.python.as_deref());
            r.syscalls = cases;
            r.notes.extend(notes);
        } else {
            r.notes
                .push("system calls not counted (strace not installed)".into());
        }
    }
    if opts.python.is_none() {
        r.notes
            .push("Python peers skipped (no Python given)".into());
    }

    for rate in if smoke {
        &[1000.0][..]
    } else {
        &[200.0, 1000.0][..]
    } {
        for subs in [1, 8] {
            let what = format!("telemetry at {rate} Hz, {subs} subscriber(s)");
            log(&what);
            match telemetry::fan_out(*rate, subs, secs(3.0, 0.3)) {
                Ok(t) => r.telemetry.push(t),
                Err(e) => fail(&mut r, &mut log, &what, &e),
            }
        }
    }

    let what = "studio: telemetry fan-out and jog latency";
    log(what);
    let pages: &[usize] = if smoke { &[1] } else { &[1, 4] };
    match studio::run(pages, secs(5.0, 0.5)) {
        Ok(s) => r.studio = Some(s),
        Err(e) => fail(&mut r, &mut log, what, &e),
    }

    let spec = if smoke {
        bridge::Spec::smoke()
    } else {
        bridge::Spec::full()
    };
    let what = format!(
        "bridge: {} bridges of {} joints at {} Hz into one Zenoh router",
        spec.bridges,
        bridge::JOINTS,
        spec.rate_hz
    );
    log(&what);
    match bridge::run(spec) {
        Ok(b) => r.bridge = Some(b),
        Err(e) => fail(&mut r, &mut log, &what, &e),
    }

    log("simulator speed");
    r.sims.push(simspeed::wck(secs(10.0, 0.3)));
    r.sims.push(simspeed::whj(secs(20.0, 0.3)));
    r.machine.load_after = read_trim("/proc/loadavg");
    r
}

fn fail(r: &mut Results, log: &mut impl FnMut(&str), what: &str, e: &BenchError) {
    log(&format!("FAILED {what}: {e}"));
    r.notes.push(format!("FAILED {what}: {e}"));
    r.failures += 1;
}

fn spec(servos: u8, baud: BaudRate, manual_turnaround: bool) -> wck::PollSpec {
    wck::PollSpec {
        servos,
        baud,
        manual_turnaround,
        wait: WaitMode::Sleep,
        memory: false,
        guard: true,
    }
}

fn chain(joints: u8, delay: Duration, fast_wire: bool) -> whj::ChainSpec {
    whj::ChainSpec {
        joints,
        delay,
        fast_wire,
        wait: WaitMode::Sleep,
        collision_window: true,
    }
}
