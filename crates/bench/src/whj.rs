//! WHJ cyclic position servo against the simulator served on a frame link on the wall
//! clock (in-process memory bus, or python-can's UDP multicast bus), and the python-can
//! peer on the same UDP simulator.

use std::io::{BufRead as _, BufReader, Write as _};
use std::path::Path;
use std::process::{Child, ChildStdin, Command, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use robobus::whj::{CyclicConfig, Feedback, JointBus, JointBusConfig, Protocol};
use robobus_link::{FrameLink, FrameLinkError, MemoryBus, UdpBus, UdpBusConfig, WaitMode};
use robobus_sim::LatenessSummary;
use robobus_sim::whj::{JointConfig, ServeStats, Served, WhjBus, WhjModel, serve, serve_precise};
use robobus_whj::broadcast::{BroadcastFeedback, BroadcastPosition, ReplyMask};
use robobus_whj::reply::ServoFeedback;
use robobus_whj::timing::{BitRates, frame_duration};
use robobus_whj::units::{ActualSpeed, Current, Position, Temperature, Voltage};
use robobus_whj::{CanFrame, ErrorCode, JointId, Reply, Request, WorkMode};

use crate::observe::ObservedLink;
use crate::peers::{self, PeerResult};
use crate::stats::Summary;
use crate::{BenchError, cpu};

/// The simulated joints' processing delay by default (`robobus_sim`'s `JointConfig`).
pub const DEFAULT_DELAY: Duration = Duration::from_micros(20);

/// How the simulated chain is built.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ChainSpec {
    /// Joints 1..=joints (WHJ30).
    pub joints: u8,
    /// Each joint's processing delay (received frame → reply ready).
    pub delay: Duration,
    /// Wire at 1 Gbit/s instead of 1 / 5 Mbit/s (takes the wire out of the measurement).
    pub fast_wire: bool,
    /// How the client waits; in [`WaitMode::Spin`] the simulator serves in its precise
    /// mode too.
    pub wait: WaitMode,
    /// Whether the client holds each reply for a second answer before crediting it
    /// (duplicate detection: one frame of the reply's length on the wire plus
    /// `JointBusConfig::collision_window`, the link's allowance), as by default.
    pub collision_window: bool,
}

impl ChainSpec {
    /// The bit rates of the wire.
    pub fn rates(&self) -> BitRates {
        if self.fast_wire {
            BitRates::new(1_000_000_000, 1_000_000_000).unwrap_or(BitRates::WHJ)
        } else {
            BitRates::WHJ
        }
    }

    /// The client's settings: [`JointBusConfig::simulated`] waiting in [`ChainSpec::wait`],
    /// without the collision window if so asked.
    pub fn client_config(&self) -> JointBusConfig {
        let base = JointBusConfig::simulated();
        JointBusConfig {
            wait: self.wait,
            collision_window: if self.collision_window {
                base.collision_window
            } else {
                Some(Duration::ZERO)
            },
            ..base
        }
    }

    /// `7 joints, wait spin, collision window off`.
    pub fn label(&self) -> String {
        format!(
            "{} joints, wait {}, collision window {}",
            self.joints,
            self.wait,
            if self.collision_window { "on" } else { "off" }
        )
    }

    /// The simulated bus.
    pub fn build(&self) -> WhjBus {
        let delay = self.delay;
        WhjBus::with_configs(
            (1..=self.joints).map(|id| {
                let mut c = JointConfig::new(id, WhjModel::Whj30).without_iap();
                c.processing_delay = delay;
                c
            }),
            1,
        )
        .with_rates(self.rates())
    }
}

/// The 3-bit intermission after every frame, at the nominal rate: part of each frame's
/// wire time in `robobus_whj::timing`, but a receiver has the frame at the end of its EOF,
/// before the intermission.
pub fn intermission(rates: BitRates) -> Duration {
    Duration::from_nanos(3_000_000_000 / u64::from(rates.nominal.get()))
}

/// The simulator served by a thread of this process.
#[derive(Debug)]
pub struct SimThread {
    stop: Arc<AtomicBool>,
    handle: JoinHandle<Result<SimReport, FrameLinkError>>,
}

/// What the serving thread did.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct SimReport {
    /// `serve`'s counters.
    pub stats: ServeStats,
    /// CPU time of the serving thread.
    pub cpu: Duration,
    /// How long it served.
    pub wall: Duration,
}

impl SimThread {
    /// Serves `bus` on `link` until stopped; in the precise mode if `wait` spins.
    pub fn spawn<L: FrameLink + Send + 'static>(
        mut bus: WhjBus,
        mut link: L,
        wait: WaitMode,
    ) -> Self {
        let stop = Arc::new(AtomicBool::new(false));
        let flag = Arc::clone(&stop);
        let handle = std::thread::spawn(move || {
            let cpu0 = cpu::thread();
            let t0 = Instant::now();
            let stats = if wait.spins() {
                serve_precise(&mut bus, &mut link, &flag)?
            } else {
                serve(&mut bus, &mut link, &flag)?
            };
            Ok(SimReport {
                stats,
                cpu: cpu::thread().saturating_sub(cpu0),
                wall: t0.elapsed(),
            })
        });
        Self { stop, handle }
    }

    /// Stops serving.
    pub fn stop(self) -> Result<SimReport, BenchError> {
        self.stop.store(true, Ordering::Relaxed);
        self.handle
            .join()
            .map_err(|_| BenchError::msg("the simulator thread panicked"))?
            .map_err(|e| BenchError::new("serving the WHJ simulator", e))
    }
}

fn jid(i: u8) -> JointId {
    JointId::new(i).unwrap_or(JointId::MAX)
}

/// Connects joints `1..=n`: position mode, enabled; returns each joint's position.
pub fn prepare(bus: &JointBus, n: u8) -> Result<Vec<(JointId, Position)>, BenchError> {
    (1..=n)
        .map(|i| {
            let j = bus
                .joint(jid(i))
                .map_err(|e| BenchError::new(format!("connecting joint {i}"), e))?;
            j.disable()
                .and_then(|()| j.set_mode(WorkMode::Position))
                .and_then(|()| j.enable())
                .map_err(|e| BenchError::new(format!("enabling joint {i}"), e))?;
            let p = j
                .position()
                .map_err(|e| BenchError::new(format!("reading joint {i}"), e))?;
            Ok((jid(i), p))
        })
        .collect()
}

/// A free-running cycle: one position servo frame per joint, each answered before the
/// next is sent (`Joint::command_position`), as fast as it goes.
#[derive(Debug, Clone)]
pub struct FreeResult {
    /// The chain.
    pub spec: ChainSpec,
    /// Link name.
    pub link: &'static str,
    /// Complete cycles.
    pub cycles: u64,
    /// Failed commands.
    pub errors: u64,
    /// Wall time.
    pub elapsed: Duration,
    /// CPU time of this process over the run (the client: its calling and bus threads;
    /// includes the simulator thread when it runs in-process, see `sim_cpu`).
    pub cpu: Duration,
    /// CPU of an in-process simulator thread over the run (subtract from `cpu`).
    pub sim_cpu: Duration,
    /// How late the simulator released its frames (p50 / p99), where it ran in this
    /// process.
    pub sim_lateness: Option<LatenessSummary>,
    /// Modelled cycle: Σ (command frame + processing delay + feedback frame − the one
    /// intermission the delay hides).
    pub modelled_cycle: Duration,
    /// Each cycle's duration, µs.
    pub cycle_us: Vec<f64>,
    /// The python-can peer on the same simulator, if it ran.
    pub peer: Option<PeerResult>,
}

impl FreeResult {
    /// Cycles per second.
    pub fn rate_hz(&self) -> f64 {
        self.cycles as f64 / self.elapsed.as_secs_f64().max(1e-9)
    }

    /// Modelled cycle / measured mean cycle.
    pub fn efficiency(&self) -> f64 {
        self.modelled_cycle.as_secs_f64() * self.rate_hz()
    }

    /// Client CPU per cycle, µs.
    pub fn cpu_per_cycle_us(&self) -> f64 {
        self.cpu.saturating_sub(self.sim_cpu).as_secs_f64() * 1e6 / self.cycles.max(1) as f64
    }
}

/// Free-running cycles on `bus` for `duration`: each cycle one position servo frame to
/// every joint, at its present position. One after another (`Joint::command_position`,
/// each reply waited for, its duplicate check included), or with `pipelined` in one batch
/// (`JointBus::servo_many`: every frame sent at once, each reply's check overlapping the
/// other joints' frames, only the last one's waited out alone). The model is each
/// joint's command and reply in turn, or, pipelined, the commands back to back, then the
/// replies.
pub fn free_running_on(
    bus: &JointBus,
    joints: &[(JointId, Position)],
    spec: ChainSpec,
    link: &'static str,
    duration: Duration,
    pipelined: bool,
) -> Result<FreeResult, BenchError> {
    let handles: Vec<_> = joints
        .iter()
        .map(|(id, p)| (bus.joint_unchecked(*id), *p))
        .collect();
    let requests: Vec<Request> = joints
        .iter()
        .map(|&(joint, target)| Request::PositionServo { joint, target })
        .collect();
    // Warm-up cycle, and the exact frames for the model.
    let rates = spec.rates();
    let warm = bus
        .servo_many(&requests)
        .map_err(|e| BenchError::new("warm-up position commands", e))?;
    let mut cmds = Vec::with_capacity(warm.len());
    let mut replies = Vec::with_capacity(warm.len());
    for (r, request) in warm.into_iter().zip(&requests) {
        let feedback = r.map_err(|e| BenchError::new("warm-up position command", e))?;
        let Some(joint) = request.joint() else {
            continue;
        };
        cmds.push(request.to_frame());
        replies.push(Reply::ServoFeedback { joint, feedback }.to_frame());
    }
    let modelled = if pipelined {
        p2p_round_trip(&cmds, &replies, spec)
    } else {
        // Steady state: the command waits out the intermission after the previous reply;
        // the joint starts replying once its delay has passed and the wire is free.
        let ifs = intermission(rates);
        cmds.iter()
            .zip(&replies)
            .map(|(cmd, reply)| {
                (frame_duration(cmd, rates) + spec.delay.max(ifs) + frame_duration(reply, rates))
                    .saturating_sub(ifs)
            })
            .sum()
    };
    let mut errors = 0u64;
    let mut cycles = 0u64;
    let mut cycle_us = Vec::with_capacity(1 << 16);
    let cpu0 = cpu::process();
    crate::syscalls::mark("start");
    let t0 = Instant::now();
    while t0.elapsed() < duration {
        let c0 = Instant::now();
        if pipelined {
            match bus.servo_many(&requests) {
                Ok(rs) => errors += rs.iter().filter(|r| r.is_err()).count() as u64,
                Err(_) => errors += requests.len() as u64,
            }
        } else {
            for (j, p) in &handles {
                if j.command_position(*p).is_err() {
                    errors += 1;
                }
            }
        }
        cycle_us.push(c0.elapsed().as_secs_f64() * 1e6);
        cycles += 1;
    }
    crate::syscalls::mark("end");
    Ok(FreeResult {
        spec,
        link,
        cycles,
        errors,
        elapsed: t0.elapsed(),
        cpu: cpu::process().saturating_sub(cpu0),
        sim_cpu: Duration::ZERO,
        sim_lateness: None,
        modelled_cycle: modelled,
        cycle_us,
        peer: None,
    })
}

/// Free-running cycles over the in-process memory bus ([`free_running_on`]).
pub fn free_running_memory(
    spec: ChainSpec,
    duration: Duration,
    pipelined: bool,
) -> Result<FreeResult, BenchError> {
    let wire = MemoryBus::new();
    let sim = SimThread::spawn(spec.build(), wire.endpoint(), spec.wait);
    let bus = JointBus::open_with(wire.endpoint(), spec.client_config())
        .map_err(|e| BenchError::new("JointBus", e))?;
    let joints = prepare(&bus, spec.joints)?;
    let link = if pipelined {
        "memory, pipelined"
    } else {
        "memory"
    };
    let mut r = free_running_on(&bus, &joints, spec, link, duration, pipelined)?;
    drop(bus);
    let report = sim.stop()?;
    r.sim_lateness = Some(report.stats.lateness);
    // The simulator's share of the process CPU over the run, pro rata.
    r.sim_cpu = Duration::from_secs_f64(
        report.cpu.as_secs_f64() * (r.elapsed.as_secs_f64() / report.wall.as_secs_f64().max(1e-9)),
    );
    Ok(r)
}

/// A fixed-rate cyclic loop (`JointBus::cyclic`).
#[derive(Debug, Clone)]
pub struct FixedResult {
    /// The chain.
    pub spec: ChainSpec,
    /// Point-to-point or broadcast.
    pub protocol: Protocol,
    /// Loop rate, Hz.
    pub hz: u32,
    /// Cycles run.
    pub cycles: u64,
    /// Cycles whose feedback was not complete by the next tick.
    pub deadline_misses: u64,
    /// Ticks the bus thread skipped because it was more than a period late.
    pub overruns: u64,
    /// Round trips (first frame sent → last feedback) of complete cycles, µs; only the
    /// physically possible ones (see `impossible`).
    pub round_trip_us: Vec<f64>,
    /// Complete cycles whose round trip was shorter than the wire allows (below 98 % of
    /// the modelled round trip): the client would have taken feedback of an earlier
    /// cycle for this cycle's. Left out of `round_trip_us`.
    pub impossible: u64,
    /// How late each cycle started, µs.
    pub lateness_us: Vec<f64>,
    /// Modelled round trip from the frames' exact wire time and the processing delay.
    pub modelled_round_trip: Duration,
    /// Round trips measured at the link (every feedback frame matched to the command it
    /// answers), complete cycles, µs.
    pub link_round_trip_us: Vec<f64>,
    /// Cycles seen at the link.
    pub link_cycles: u64,
    /// Cycles whose feedback was not complete at the link before the next cycle's first
    /// command.
    pub link_misses: u64,
    /// The simulator thread.
    pub sim: SimReport,
}

impl FixedResult {
    /// Whether the wire can carry a cycle within the period at all.
    pub fn feasible(&self) -> bool {
        self.modelled_round_trip < Duration::from_secs(1) / self.hz.max(1)
    }

    /// Modelled round trip / median round trip measured at the link.
    pub fn efficiency(&self) -> f64 {
        let p50 = Summary::of_us(&self.link_round_trip_us).p50;
        if p50 > 0.0 {
            self.modelled_round_trip.as_secs_f64() * 1e6 / p50
        } else {
            0.0
        }
    }
}

/// Modelled round trip of a point-to-point cycle from an idle wire: the commands go
/// first (lower IDs win arbitration), the first reply is ready `delay` after the first
/// command was received (end of its EOF), and the replies follow back to back; the last
/// one is received at the end of its EOF.
fn p2p_round_trip(cmds: &[CanFrame], replies: &[CanFrame], spec: ChainSpec) -> Duration {
    let rates = spec.rates();
    let ifs = intermission(rates);
    let first = cmds
        .first()
        .map_or(Duration::ZERO, |f| frame_duration(f, rates));
    let total_cmd: Duration = cmds.iter().map(|f| frame_duration(f, rates)).sum();
    let total_reply: Duration = replies.iter().map(|f| frame_duration(f, rates)).sum();
    total_cmd.max(first.saturating_sub(ifs) + spec.delay) + total_reply.saturating_sub(ifs)
}

/// Modelled round trip of a broadcast cycle: the 64-byte frame, the delay, then the
/// feedback frames back to back.
fn broadcast_round_trip(cmd: &CanFrame, replies: Duration, spec: ChainSpec) -> Duration {
    let rates = spec.rates();
    let ifs = intermission(rates);
    frame_duration(cmd, rates).saturating_sub(ifs)
        + spec.delay.max(ifs)
        + replies.saturating_sub(ifs)
}

#[allow(clippy::too_many_lines)] // set-up, run and model of one loop
/// Runs `JointBus::cyclic` at `hz` over the in-process memory bus for `duration`.
pub fn fixed_rate(
    spec: ChainSpec,
    hz: u32,
    protocol: Protocol,
    duration: Duration,
) -> Result<FixedResult, BenchError> {
    let wire = MemoryBus::new();
    let sim = SimThread::spawn(spec.build(), wire.endpoint(), spec.wait);
    let (link, observed) = ObservedLink::new(wire.endpoint());
    let bus = JointBus::open_with(link, spec.client_config())
        .map_err(|e| BenchError::new("JointBus", e))?;
    let joints = prepare(&bus, spec.joints)?;
    let period = Duration::from_secs(1) / hz.max(1);
    let mut config = CyclicConfig::position(joints.iter().map(|j| j.0).collect(), period);
    config.protocol = protocol;
    let cyc = bus
        .cyclic(config)
        .map_err(|e| BenchError::new("starting the cyclic loop", e))?;
    let mut round_trip_us = Vec::new();
    let mut lateness_us = Vec::new();
    let mut first = None;
    let t0 = Instant::now();
    while t0.elapsed() < duration {
        let Some(r) = cyc.next_report(Duration::from_millis(100)) else {
            continue;
        };
        lateness_us.push(r.start_lateness.as_secs_f64() * 1e6);
        if let Some(rt) = r.round_trip.filter(|_| !r.missed) {
            round_trip_us.push(rt.as_secs_f64() * 1e6);
            if first.is_none() {
                first = Some(r);
            }
        }
    }
    let stats = cyc.stop();
    drop(bus);
    let sim = sim.stop()?;
    let link_cycles = observed
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
        .cycles();
    let link_round_trip_us: Vec<f64> = link_cycles
        .iter()
        .filter_map(|c| c.round_trip)
        .map(|d| d.as_secs_f64() * 1e6)
        .collect();
    let link_misses = link_cycles.iter().filter(|c| !c.in_time).count() as u64;
    // The exact frames of the first complete cycle; if none was complete (a rate beyond
    // the wire's limit), the frames of a cycle holding every joint still.
    let (commanded, feedback) = match first {
        Some(r) => (r.commanded, r.feedback),
        None => (
            joints.iter().map(|(_, p)| p.raw()).collect(),
            joints
                .iter()
                .map(|(_, p)| {
                    Some(Feedback {
                        position: *p,
                        speed: ActualSpeed(0),
                        current: Current(0),
                        enabled: true,
                        error: ErrorCode::NONE,
                    })
                })
                .collect(),
        ),
    };
    let modelled_round_trip = {
        {
            let rates = spec.rates();
            let fbs: Vec<_> = feedback
                .iter()
                .zip(&joints)
                .filter_map(|(f, (id, _))| f.map(|f| (*id, f)))
                .collect();
            let targets = joints
                .iter()
                .zip(&commanded)
                .map(|((id, _), raw)| (*id, *raw));
            match protocol {
                Protocol::PointToPoint => {
                    let cmds: Vec<CanFrame> = targets
                        .map(|(joint, raw)| {
                            Request::PositionServo {
                                joint,
                                target: Position(raw),
                            }
                            .to_frame()
                        })
                        .collect();
                    let replies: Vec<CanFrame> = fbs
                        .iter()
                        .map(|(joint, f)| {
                            Reply::ServoFeedback {
                                joint: *joint,
                                feedback: ServoFeedback {
                                    current: f.current,
                                    speed: f.speed,
                                    position: f.position,
                                    enable: u16::from(f.enabled),
                                    error: f.error,
                                },
                            }
                            .to_frame()
                        })
                        .collect();
                    p2p_round_trip(&cmds, &replies, spec)
                }
                Protocol::Broadcast => {
                    let mut bp = BroadcastPosition::new(ReplyMask::ALL);
                    for (joint, raw) in targets {
                        bp = bp.with_target(joint, Position(raw)).unwrap_or(bp);
                    }
                    let cmd = Request::BroadcastPosition(bp).to_frame();
                    let replies: Duration = fbs
                        .iter()
                        .map(|(joint, f)| {
                            let frame = Reply::BroadcastFeedback {
                                joint: *joint,
                                feedback: BroadcastFeedback {
                                    current: f.current,
                                    speed: f.speed,
                                    position: f.position,
                                    error: f.error,
                                    voltage: Voltage(2400),
                                    temperature: Temperature(250),
                                    state: u8::from(f.enabled),
                                    encoder: 0,
                                    counter: 0,
                                },
                            }
                            .to_frame();
                            frame_duration(&frame, rates)
                        })
                        .sum();
                    broadcast_round_trip(&cmd, replies, spec)
                }
            }
        }
    };
    let floor = modelled_round_trip.as_secs_f64() * 1e6 * 0.98;
    let before = round_trip_us.len();
    round_trip_us.retain(|rt| *rt >= floor);
    let impossible = (before - round_trip_us.len()) as u64;
    Ok(FixedResult {
        spec,
        protocol,
        hz,
        impossible,
        link_round_trip_us,
        link_cycles: link_cycles.len() as u64,
        link_misses,
        cycles: stats.cycles,
        deadline_misses: stats.deadline_misses,
        overruns: stats.overruns,
        round_trip_us,
        lateness_us,
        modelled_round_trip,
        sim,
    })
}

/// A WHJ simulator in a child process (this program's `serve-whj` mode) on python-can's
/// UDP multicast bus, so that this process's CPU time is the client's alone.
#[derive(Debug)]
pub struct ChildSim {
    child: Child,
    stdin: Option<ChildStdin>,
    stdout: Option<BufReader<std::process::ChildStdout>>,
}

impl ChildSim {
    /// Starts `exe serve-whj` for `spec` and waits until it serves.
    pub fn start(exe: &Path, spec: ChainSpec) -> Result<Self, BenchError> {
        let mut cmd = Command::new(exe);
        cmd.args([
            "serve-whj",
            "--joints",
            &spec.joints.to_string(),
            "--delay-us",
            &spec.delay.as_micros().to_string(),
        ]);
        if spec.fast_wire {
            cmd.arg("--fast-wire");
        }
        cmd.args(["--wait", &spec.wait.to_string()]);
        let mut child = cmd
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .spawn()
            .map_err(|e| BenchError::new(format!("starting {} serve-whj", exe.display()), e))?;
        let stdin = child.stdin.take();
        let mut line = String::new();
        let mut stdout = child.stdout.take().map(BufReader::new);
        if let Some(out) = stdout.as_mut() {
            let _ = out.read_line(&mut line);
        }
        if !line.starts_with("READY") {
            let _ = child.kill();
            let _ = child.wait();
            return Err(BenchError::msg(format!(
                "the WHJ simulator process did not start: {line:?}"
            )));
        }
        Ok(Self {
            child,
            stdin,
            stdout,
        })
    }

    /// Stops the child (closing its stdin) and waits for it; returns how late it released
    /// its frames (its last line, `LATENESS releases p50 p99 max` in ns, `-` for none).
    pub fn stop(mut self) -> Result<Option<LatenessSummary>, BenchError> {
        self.halt()
    }

    fn halt(&mut self) -> Result<Option<LatenessSummary>, BenchError> {
        if let Some(mut s) = self.stdin.take() {
            let _ = s.flush();
        }
        let mut lateness = None;
        if let Some(out) = self.stdout.take() {
            for line in out.lines().map_while(Result::ok).take(16) {
                if let Some(l) = parse_lateness(&line) {
                    lateness = Some(l);
                }
            }
        }
        let status = self
            .child
            .wait()
            .map_err(|e| BenchError::new("waiting for the simulator process", e))?;
        if status.success() {
            Ok(lateness)
        } else {
            Err(BenchError::msg(format!("simulator process: {status}")))
        }
    }
}

/// `LATENESS releases p50 p99 max`, nanoseconds (`-`: none), as `serve-whj` prints it.
fn lateness_line(l: &LatenessSummary) -> String {
    let ns = |d: Option<Duration>| d.map_or_else(|| "-".to_owned(), |d| d.as_nanos().to_string());
    format!(
        "LATENESS {} {} {} {}",
        l.releases,
        ns(l.p50),
        ns(l.p99),
        l.max.as_nanos()
    )
}

fn parse_lateness(line: &str) -> Option<LatenessSummary> {
    let mut it = line.strip_prefix("LATENESS ")?.split_whitespace();
    let ns = |w: Option<&str>| -> Option<Option<Duration>> {
        match w? {
            "-" => Some(None),
            n => n.parse().ok().map(|n| Some(Duration::from_nanos(n))),
        }
    };
    let releases = it.next()?.parse().ok()?;
    let p50 = ns(it.next())?;
    let p99 = ns(it.next())?;
    let max = ns(it.next())??;
    Some(LatenessSummary {
        releases,
        p50,
        p99,
        max,
    })
}

impl Drop for ChildSim {
    fn drop(&mut self) {
        if self.stdin.is_some() {
            let _ = self.halt();
        }
    }
}

/// `serve-whj`: serves `spec` on python-can's default UDP multicast group and port until
/// stdin closes; prints `READY` once it listens.
pub fn serve_whj_process(spec: ChainSpec) -> Result<(), BenchError> {
    let link = UdpBus::open(&UdpBusConfig::default()).map_err(|e| BenchError::new("UDP bus", e))?;
    let served = if spec.wait.spins() {
        Served::spawn_precise("bench-serve-whj", spec.build(), link)
    } else {
        Served::spawn("bench-serve-whj", spec.build(), link)
    }
    .map_err(|e| BenchError::new("starting the simulator", e))?;
    let mut out = std::io::stdout();
    let _ = writeln!(out, "READY");
    let _ = out.flush();
    let mut sink = String::new();
    while std::io::stdin().read_line(&mut sink).is_ok_and(|n| n > 0) {
        sink.clear();
    }
    let (_, stats) = served.stop().map_err(|e| BenchError::new("serving", e))?;
    let _ = writeln!(out, "{}", lateness_line(&stats.lateness));
    let _ = out.flush();
    Ok(())
}

/// Ours and the python-can peer, one after the other, against one simulator process on
/// the UDP multicast bus: free-running cycles over `spec.joints` joints. Needs a network
/// namespace with a multicast route on loopback.
pub fn udp_compare(
    exe: &Path,
    spec: ChainSpec,
    duration: Duration,
    python: Option<&Path>,
    pipelined: bool,
) -> Result<FreeResult, BenchError> {
    let sim = ChildSim::start(exe, spec)?;
    let mut r = udp_client(spec, duration, python, pipelined)?;
    r.sim_lateness = sim.stop()?;
    Ok(r)
}

/// The client side of [`udp_compare`], against a simulator process that already serves
/// `spec` on the UDP multicast bus.
pub fn udp_client(
    spec: ChainSpec,
    duration: Duration,
    python: Option<&Path>,
    pipelined: bool,
) -> Result<FreeResult, BenchError> {
    let link = UdpBus::open(&UdpBusConfig::default()).map_err(|e| BenchError::new("UDP bus", e))?;
    let bus = JointBus::open_with(link, spec.client_config())
        .map_err(|e| BenchError::new("JointBus", e))?;
    let joints = prepare(&bus, spec.joints)?;
    let link = if pipelined { "UDP, pipelined" } else { "UDP" };
    let mut r = free_running_on(&bus, &joints, spec, link, duration, pipelined)?;
    drop(bus);
    if let Some(py) = python {
        r.peer = Some(peers::whj_servo(py, spec.joints, duration)?);
    }
    Ok(r)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Back-to-back transactions (each command sent when the previous feedback arrived)
    /// take command + max(delay, intermission) + feedback − intermission each, as the
    /// free-running model says.
    #[test]
    fn the_simulator_process_reports_its_lateness_in_one_line() {
        let l = LatenessSummary {
            releases: 12,
            p50: Some(Duration::from_micros(3)),
            p99: None,
            max: Duration::from_millis(25),
        };
        let line = lateness_line(&l);
        assert_eq!(line, "LATENESS 12 3000 - 25000000");
        assert_eq!(parse_lateness(&line), Some(l));
        assert_eq!(parse_lateness("READY"), None);
    }

    #[test]
    fn free_running_model_matches_the_virtual_wire() {
        for delay in [DEFAULT_DELAY, Duration::ZERO] {
            let spec = ChainSpec {
                joints: 1,
                delay,
                fast_wire: false,
                wait: WaitMode::Sleep,
                collision_window: true,
            };
            let rates = spec.rates();
            let ifs = intermission(rates);
            let mut bus = spec.build();
            let _ = bus.advance(Duration::from_millis(500));
            let cmd = Request::PositionServo {
                joint: jid(1),
                target: Position(0),
            }
            .to_frame();
            let mut at = bus.now();
            let mut times = Vec::new();
            for _ in 0..4 {
                bus.submit(cmd, at);
                // Step from event to event so that the bus stops at the feedback.
                let mut d = Vec::new();
                while d.is_empty() {
                    let next = bus.next_event().unwrap();
                    d = bus.run_until(next);
                }
                assert_eq!(d.len(), 1);
                let reply = d[0].frame;
                times.push((
                    d[0].at.saturating_sub(at),
                    (frame_duration(&cmd, rates) + delay.max(ifs) + frame_duration(&reply, rates))
                        .saturating_sub(ifs),
                ));
                at = d[0].at;
            }
            // The first transaction starts on an idle wire; the others wait out the
            // intermission after the previous feedback.
            for (simulated, model) in times.iter().skip(1) {
                let diff = (simulated.as_secs_f64() - model.as_secs_f64()).abs() * 1e6;
                assert!(
                    diff < 0.01,
                    "delay {delay:?}: simulated {simulated:?}, modelled {model:?}"
                );
            }
        }
    }

    /// The modelled round trip agrees with the simulator's exact wire model on the virtual
    /// clock for the very frames it delivered.
    #[test]
    fn point_to_point_model_matches_the_virtual_wire() {
        for n in [1u8, 7, 14] {
            let spec = ChainSpec {
                joints: n,
                delay: DEFAULT_DELAY,
                fast_wire: false,
                wait: WaitMode::Sleep,
                collision_window: true,
            };
            let mut bus = spec.build();
            let _ = bus.advance(Duration::from_millis(500));
            let t = bus.now();
            let cmds: Vec<CanFrame> = (1..=n)
                .map(|i| {
                    Request::PositionServo {
                        joint: jid(i),
                        target: Position(1000 * i32::from(i)),
                    }
                    .to_frame()
                })
                .collect();
            for f in &cmds {
                bus.submit(*f, t);
            }
            let delivered = bus.run_until(t + Duration::from_millis(5));
            assert_eq!(delivered.len(), usize::from(n));
            let last = delivered
                .iter()
                .map(|d| d.at)
                .max()
                .unwrap()
                .saturating_sub(t);
            let replies: Vec<CanFrame> = delivered.iter().map(|d| d.frame).collect();
            let model = p2p_round_trip(&cmds, &replies, spec);
            let diff = (last.as_secs_f64() - model.as_secs_f64()).abs() * 1e6;
            assert!(
                diff < 1.0,
                "{n} joints: simulated {last:?}, modelled {model:?}"
            );
        }
    }
}
