//! Many `robobus-bridge`s into one Zenoh router, in-process: N bridges, each serving its
//! own station of [`JOINTS`] simulated WHJ30 joints on the wall clock (the in-process
//! memory bus, 1 / 5 Mbit/s wire, 20 µs processing delay, as `Station::simulated_live`
//! builds its WHJ arm) under its own namespace (`bot0`, `bot1`, ...), publishing
//! `NS/joint_states` at the asked rate, a Zenoh **client** (`--mode client`) of one
//! router (a Zenoh session in router mode on a free `tcp/127.0.0.1` port, scouting off);
//! one subscriber on `*/joint_states`, also a client of the router: the topology the
//! bridge's guide gives for a site's router.
//!
//! Clients, because in Zenoh 1.10 a router puts the peers connected to it in one region
//! that it takes for a full mesh and does not forward between them: with gossip off, a
//! peer-mode subscriber connected to the router receives nothing from peer-mode bridges
//! that listen on nothing (tried: not one sample in 2 s, on `**` either).
//!
//! - **Latency**: the subscriber's wall clock when the message reached its callback − the
//!   message's `header.stamp` (the wall-clock instant the bus read of that sample
//!   completed), so it covers the telemetry hand-off, the CDR encoding, the bridge's
//!   Zenoh session, TCP to the router, the router, TCP to the subscriber and its session.
//! - **Loss**: per bridge, over the whole run, the states it counted as published
//!   (`Bridge::health().states.published`) against the messages the subscriber received.
//!   To make the count exact, the publishing ends cleanly after the window: each
//!   station's bus link is closed (a wrapper around the memory-bus endpoint that
//!   passes everything through until then), so every later sample fails at once and
//!   nothing more is published; once every count has stood still, and after a drain, the
//!   counts are compared.
//! - **Rate**: states published per second per bridge, against the asked rate and the
//!   buses' own limit for one sample stream, as the bridge computes it from their timing
//!   ([`robobus_bridge::Capacity`]: the same 14 request/reply transactions per sample of 7
//!   joints, each reply held for a second answer).
//! - **The built-in robot**: one bridge on `Station::simulated_live` (16 wCK servos at
//!   115200 bit/s, 7 WHJ joints), no command stream, asked for the default 50 Hz and for
//!   90 % of its buses' limit ([`BuiltinRun`]): the rate published over the window against
//!   the rate asked and the limit, and the samples its health counted lost.
//! - **CPU**: `getrusage` of the whole process over the window (the simulators, the
//!   bridges, the router and the subscriber all run in it), and of it the simulators'
//!   serving threads, the bridges' own threads (`robobus-*`, `whj-bus`) and this thread
//!   (from `/proc/self/task/*/stat`, 10 ms ticks); the rest is the Zenoh runtime, which
//!   the bridges' sessions, the router and the subscriber share.

use std::collections::HashMap;
use std::fmt::Write as _;
use std::net::TcpListener;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
use std::thread;
use std::time::{Duration, Instant, SystemTime};

use robobus::RobotConfig;
use robobus::ops::StopToken;
use robobus::station::Station;
use robobus::whj::{JointBus, JointBusConfig};
use robobus_bridge::cdr::JointState;
use robobus_bridge::{Bridge, BridgeConfig, ZenohMode};
use robobus_link::{FrameLink, FrameLinkError, IdFilter, MemoryBus, Received as LinkReceived};
use robobus_sim::whj::{Served, WhjBus, WhjModel};
use robobus_whj::CanFrame;
use zenoh::Wait as _;

use crate::stats::Summary;
use crate::{BenchError, cpu};

mod markdown;

pub use markdown::markdown;

/// Joints of each bridge's robot.
pub const JOINTS: u8 = 7;
/// Bridges of a full run.
pub const DEFAULT_BRIDGES: usize = 10;
/// Joint state rate each bridge is asked for, Hz.
pub const DEFAULT_RATE_HZ: f64 = 100.0;
/// Bridges accepted.
pub const BRIDGES: std::ops::RangeInclusive<usize> = 1..=64;
/// The built-in robot's runs: the bridge's default rate, and this share of its buses'
/// limit.
pub const BUILTIN_SHARE_OF_LIMIT: f64 = 0.9;
/// How long every bridge has to deliver its first message.
const READY_TIMEOUT: Duration = Duration::from_secs(15);
/// How long the subscriber goes on reading after the last state was published.
const DRAIN: Duration = Duration::from_millis(500);
/// How long every published count must stand still after the buses closed.
const SETTLE: Duration = Duration::from_millis(200);
/// How long the counts may take to settle.
const SETTLE_TIMEOUT: Duration = Duration::from_secs(5);

/// What to run.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Spec {
    /// Bridges (each its own station, simulator and Zenoh session).
    pub bridges: usize,
    /// Joint state rate asked of each, Hz.
    pub rate_hz: f64,
    /// Run after every bridge delivered its first message, before the window.
    pub warmup: Duration,
    /// The measured window.
    pub secs: Duration,
}

impl Spec {
    /// The full run: [`DEFAULT_BRIDGES`] bridges at [`DEFAULT_RATE_HZ`] for 10 s.
    pub fn full() -> Self {
        Self {
            bridges: DEFAULT_BRIDGES,
            rate_hz: DEFAULT_RATE_HZ,
            warmup: Duration::from_secs(1),
            secs: Duration::from_secs(10),
        }
    }

    /// Smoke mode: two bridges for 1.5 s.
    pub fn smoke() -> Self {
        Self {
            bridges: 2,
            rate_hz: DEFAULT_RATE_HZ,
            warmup: Duration::from_millis(300),
            secs: Duration::from_millis(1500),
        }
    }

    /// The sample period asked for.
    pub fn period(&self) -> Duration {
        Duration::from_secs_f64(1.0 / self.rate_hz.max(1e-9))
    }
}

/// One bridge.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Bot {
    /// Its namespace.
    pub namespace: String,
    /// States it counted as published in the window.
    pub published: u64,
    /// Messages the subscriber received stamped in the window.
    pub received: u64,
    /// States it counted as published over the whole run.
    pub published_total: u64,
    /// Messages the subscriber received from it over the whole run.
    pub received_total: u64,
    /// Of the messages received in the window, those with fewer than [`JOINTS`] joints.
    pub partial: u64,
    /// Joints left out of its messages in the window (their reading failed).
    pub joints_left_out: u64,
    /// Samples whose read failed as a whole in the window.
    pub failed_samples: u64,
    /// Samples its publisher did not keep up with in the window.
    pub lost_samples: u64,
    /// Receive time − stamp of each message received in the window, µs.
    pub latency_us: Vec<f64>,
    /// The time between consecutive stamps received in the window, µs (how long a
    /// sample took, bus read and wait for its slot).
    pub interval_us: Vec<f64>,
}

impl Bot {
    /// Published states a second in the window.
    pub fn rate_hz(&self, wall: Duration) -> f64 {
        self.published as f64 / wall.as_secs_f64().max(1e-9)
    }

    /// States published over the run that the subscriber did not receive.
    pub fn missing(&self) -> u64 {
        self.published_total.saturating_sub(self.received_total)
    }

    /// [`Bot::missing`] / published over the run.
    pub fn loss(&self) -> f64 {
        self.missing() as f64 / (self.published_total as f64).max(1.0)
    }
}

/// One run of the bridge on the built-in simulated robot.
#[derive(Debug, Clone, PartialEq)]
pub struct BuiltinRun {
    /// The joint state rate asked, Hz.
    pub asked_hz: f64,
    /// What its buses carry, as the bridge computed it.
    pub capacity: robobus_bridge::Capacity,
    /// The measured window.
    pub wall: Duration,
    /// States published in the window.
    pub published: u64,
    /// Slots its health counted lost in the window.
    pub lost: u64,
    /// Samples failed whole in the window.
    pub failed: u64,
    /// Its health's `achieved_hz` at the window's end (the last 2 s).
    pub achieved_hz: Option<f64>,
}

impl BuiltinRun {
    /// States published a second in the window.
    pub fn rate_hz(&self) -> f64 {
        self.published as f64 / self.wall.as_secs_f64().max(1e-9)
    }

    /// The buses' limit, Hz.
    pub fn limit_hz(&self) -> f64 {
        self.capacity.states_hz().unwrap_or(f64::INFINITY)
    }

    /// What it can reach: the rate asked, or the buses' limit if lower.
    pub fn reachable_hz(&self) -> f64 {
        self.asked_hz.min(self.limit_hz())
    }
}

/// Everything one run measured.
#[derive(Debug, Clone, PartialEq)]
pub struct BridgeResult {
    /// What ran.
    pub spec: Spec,
    /// The router's endpoint.
    pub router: String,
    /// What one bridge's buses carry (the bridge's own computation from their timing).
    pub capacity: robobus_bridge::Capacity,
    /// The bridge on the built-in robot, at the default rate and at 90 % of its limit.
    pub builtin: Vec<BuiltinRun>,
    /// The measured window.
    pub wall: Duration,
    /// Each bridge.
    pub bots: Vec<Bot>,
    /// Payloads on `*/joint_states` that were not a `JointState` (whole run).
    pub undecodable: u64,
    /// Whether every bridge's count stood still after its bus was closed (if not, the
    /// loss counts are not exact).
    pub settled: bool,
    /// CPU time of the whole process over the window.
    pub process_cpu: Duration,
    /// Of it, the simulators' serving threads.
    pub sims_cpu: Duration,
    /// Of it, the bridges' own threads (telemetry, states, health, commands, queries,
    /// guard, WHJ bus threads).
    pub bridge_threads_cpu: Duration,
    /// Of it, this benchmark's thread (waiting).
    pub main_cpu: Duration,
}

impl BridgeResult {
    /// Joints of all bridges.
    pub fn joints(&self) -> usize {
        self.bots.len() * usize::from(JOINTS)
    }

    /// The Zenoh runtime: the process less the simulators, the bridges' own threads and
    /// this thread (the bridges' sessions, the router and the subscriber share it).
    pub fn zenoh_cpu(&self) -> Duration {
        self.process_cpu
            .saturating_sub(self.sims_cpu)
            .saturating_sub(self.bridge_threads_cpu)
            .saturating_sub(self.main_cpu)
    }

    /// The bridges, the router and the subscriber: the process less the simulators and
    /// this thread.
    pub fn bridging_cpu(&self) -> Duration {
        self.process_cpu
            .saturating_sub(self.sims_cpu)
            .saturating_sub(self.main_cpu)
    }

    /// Share of one core, `d` over the window.
    pub fn share(&self, d: Duration) -> f64 {
        d.as_secs_f64() / self.wall.as_secs_f64().max(1e-9)
    }

    /// States published by all bridges in the window.
    pub fn published(&self) -> u64 {
        self.bots.iter().map(|b| b.published).sum()
    }

    /// States published by all bridges over the run.
    pub fn published_total(&self) -> u64 {
        self.bots.iter().map(|b| b.published_total).sum()
    }

    /// Messages received from all bridges over the run.
    pub fn received_total(&self) -> u64 {
        self.bots.iter().map(|b| b.received_total).sum()
    }

    /// Published over the run and not received, all bridges.
    pub fn missing(&self) -> u64 {
        self.bots.iter().map(Bot::missing).sum()
    }

    /// `d` per joint per published state, µs.
    pub fn per_joint_sample_us(&self, d: Duration) -> f64 {
        d.as_secs_f64() * 1e6 / (self.published() as f64 * f64::from(JOINTS)).max(1.0)
    }

    /// Every bridge's time between consecutive stamps, µs.
    pub fn intervals(&self) -> Summary {
        let all: Vec<f64> = self
            .bots
            .iter()
            .flat_map(|b| b.interval_us.iter().copied())
            .collect();
        Summary::of_us(&all)
    }

    /// Every message's latency, µs.
    pub fn latencies(&self) -> Summary {
        let all: Vec<f64> = self
            .bots
            .iter()
            .flat_map(|b| b.latency_us.iter().copied())
            .collect();
        Summary::of_us(&all)
    }
}

// ---------------------------------------------------------------------------------------
// Setup
// ---------------------------------------------------------------------------------------

/// The robot file of each station: joints `j1..j7` on `sim-whj`.
fn robot_file() -> String {
    let mut t =
        String::from("watchdog_timeout = 0.5\n\n[buses.sim-whj]\nkind = \"whj-external\"\n");
    for id in 1..=JOINTS {
        let _ = write!(
            t,
            "\n[[joints]]\nname = \"j{id}\"\nbus = \"sim-whj\"\nid = {id}\nlimits = [-2.0, 2.0]\n\
             max_velocity = 2.0\nmax_acceleration = 20.0\n"
        );
    }
    t
}

/// A frame link that passes everything through until its gate closes, and then fails
/// every call at once as closed (the WHJ bus then fails every request without waiting).
struct Gated<L> {
    inner: L,
    closed: Arc<AtomicBool>,
}

impl<L: FrameLink> Gated<L> {
    fn check(&self) -> Result<(), FrameLinkError> {
        if self.closed.load(Ordering::Relaxed) {
            return Err(FrameLinkError::Closed {
                context: "the benchmark closed the bus".into(),
            });
        }
        Ok(())
    }
}

impl<L: FrameLink> FrameLink for Gated<L> {
    fn send(&mut self, frame: &CanFrame) -> Result<(), FrameLinkError> {
        self.check()?;
        self.inner.send(frame)
    }

    fn recv(&mut self, deadline: Instant) -> Result<LinkReceived, FrameLinkError> {
        self.check()?;
        self.inner.recv(deadline)
    }

    fn set_filters(&mut self, filters: &[IdFilter]) -> Result<(), FrameLinkError> {
        self.inner.set_filters(filters)
    }

    robobus_link::forward_frame_link_clock!(inner);
}

/// One bridge's station: [`JOINTS`] WHJ30 joints on `sim-whj`, served on the wall clock by
/// a thread named `bench-sim-{i}`, with its robot file; its simulator, and the gate of
/// its bus link.
fn station(i: usize) -> Result<(Station, Served, Arc<AtomicBool>), BenchError> {
    let wire = MemoryBus::new();
    let served = Served::spawn(
        &format!("bench-sim-{i}"),
        WhjBus::chain(1..=JOINTS, WhjModel::Whj30, 11),
        wire.endpoint(),
    )
    .map_err(|e| BenchError::new("starting a simulated WHJ arm", e))?;
    let closed = Arc::new(AtomicBool::new(false));
    let link = Gated {
        inner: wire.endpoint(),
        closed: Arc::clone(&closed),
    };
    let bus = JointBus::open_with(link, JointBusConfig::simulated())
        .map_err(|e| BenchError::new("JointBus", e))?;
    let mut s = Station::new();
    s.add_whj("sim-whj", bus);
    let robot = RobotConfig::from_toml_str(&robot_file())
        .map_err(|e| BenchError::new("the robot file", e))?;
    s.set_robot(robot)
        .map_err(|e| BenchError::new("the robot file", e))?;
    Ok((s, served, closed))
}

/// A free TCP port on loopback (bound and released; the router binds it right after).
fn free_port() -> Result<u16, BenchError> {
    let l = TcpListener::bind(("127.0.0.1", 0))
        .map_err(|e| BenchError::new("finding a free port", e))?;
    Ok(l.local_addr()
        .map_err(|e| BenchError::new("finding a free port", e))?
        .port())
}

/// A Zenoh configuration: `mode`, exactly these endpoints, scouting off.
fn zconfig(mode: &str, listen: &[String], connect: &[String]) -> Result<zenoh::Config, BenchError> {
    let mut z = zenoh::Config::default();
    let list = |l: &[String]| serde_json::to_string(l).unwrap_or_else(|_| "[]".into());
    for (key, value) in [
        ("mode", format!("\"{mode}\"")),
        ("listen/endpoints", list(listen)),
        ("connect/endpoints", list(connect)),
        ("scouting/multicast/enabled", "false".to_owned()),
        ("scouting/gossip/enabled", "false".to_owned()),
    ] {
        z.insert_json5(key, &value)
            .map_err(|e| BenchError::new(format!("zenoh configuration {key}"), e))?;
    }
    Ok(z)
}

fn unix_ms() -> f64 {
    SystemTime::now()
        .duration_since(SystemTime::UNIX_EPOCH)
        .map_or(0.0, |d| d.as_secs_f64() * 1e3)
}

/// One message the subscriber received.
#[derive(Debug, Clone, Copy)]
struct Message {
    /// Its stamp, Unix ms.
    stamp_ms: f64,
    /// Receive time − stamp, µs.
    latency_us: f64,
    /// Joints in it.
    joints: usize,
}

/// What the subscriber received, by namespace.
#[derive(Debug, Default)]
struct Inbox {
    by_ns: Mutex<HashMap<String, Vec<Message>>>,
    undecodable: AtomicU64,
}

impl Inbox {
    fn take(&self, sample: &zenoh::sample::Sample) {
        let now = unix_ms();
        let key = sample.key_expr().as_str();
        let ns = key.strip_suffix("/joint_states").unwrap_or(key);
        match JointState::decode(&sample.payload().to_bytes()) {
            Ok(m) => {
                let stamp_ms = f64::from(m.stamp.sec) * 1e3 + f64::from(m.stamp.nanosec) / 1e6;
                self.by_ns
                    .lock()
                    .unwrap_or_else(PoisonError::into_inner)
                    .entry(ns.to_owned())
                    .or_default()
                    .push(Message {
                        stamp_ms,
                        latency_us: (now - stamp_ms) * 1e3,
                        joints: m.name.len(),
                    });
            }
            Err(_) => {
                self.undecodable.fetch_add(1, Ordering::Relaxed);
            }
        }
    }

    /// Namespaces that have delivered at least one message.
    fn heard(&self) -> usize {
        self.by_ns
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .len()
    }
}

// ---------------------------------------------------------------------------------------
// CPU time per thread
// ---------------------------------------------------------------------------------------

fn is_sim(name: &str) -> bool {
    name.starts_with("bench-sim-")
}

/// The bridges' threads (`robobus-telemetry` shows as `robobus-telemet`), not this
/// program's main thread (`robobus-bench`).
fn is_bridge_thread(name: &str) -> bool {
    (name.starts_with("robobus-") && name != "robobus-bench") || name == "whj-bus"
}

// ---------------------------------------------------------------------------------------
// The run
// ---------------------------------------------------------------------------------------

/// Each bridge's state counts: (published, joints left out, failed, lost).
type Counts = (u64, u64, u64, u64);

/// One end of the window.
struct Cut {
    unix_ms: f64,
    at: Instant,
    counts: Vec<Counts>,
    process: Duration,
    main: Duration,
    tasks: cpu::Tasks,
}

impl Cut {
    fn now(bridges: &[Bridge]) -> Self {
        let (process, main, tasks) = (cpu::process(), cpu::thread(), cpu::tasks());
        let unix_ms = unix_ms();
        let at = Instant::now();
        let counts = bridges
            .iter()
            .map(|b| {
                let s = b.health().states;
                (
                    s.published,
                    s.joints_left_out,
                    s.failed_samples,
                    s.lost_samples,
                )
            })
            .collect();
        Self {
            unix_ms,
            at,
            counts,
            process,
            main,
            tasks,
        }
    }
}

/// The router, the subscriber, the simulated arms and their bridges, running.
/// Dropped (on an error) in the order of its fields: the bridges before their
/// simulators (a bridge whose joints went silent would wait out its reads' timeouts
/// before it stops), then the subscriber and the router.
struct Rig {
    bridges: Vec<Bridge>,
    gates: Vec<Arc<AtomicBool>>,
    sims: Vec<Served>,
    subscriber: zenoh::pubsub::Subscriber<()>,
    inbox: Arc<Inbox>,
    client: zenoh::Session,
    router: zenoh::Session,
    router_ep: String,
}

impl Rig {
    /// Starts the router, the subscriber, then `spec.bridges` arms and bridges.
    fn start(spec: &Spec) -> Result<Self, BenchError> {
        let router_ep = format!("tcp/127.0.0.1:{}", free_port()?);
        let endpoint = std::slice::from_ref(&router_ep);
        let router = zenoh::open(zconfig("router", endpoint, &[])?)
            .wait()
            .map_err(|e| BenchError::new(format!("the router on {router_ep}"), e))?;
        let client = zenoh::open(zconfig("client", &[], endpoint)?)
            .wait()
            .map_err(|e| BenchError::new("the subscriber's session", e))?;
        let inbox = Arc::new(Inbox::default());
        let sink = Arc::clone(&inbox);
        let subscriber = client
            .declare_subscriber("*/joint_states")
            .callback(move |sample| sink.take(&sample))
            .wait()
            .map_err(|e| BenchError::new("subscribing */joint_states", e))?;
        let mut rig = Self {
            router_ep,
            router,
            client,
            subscriber,
            inbox,
            sims: Vec::new(),
            gates: Vec::new(),
            bridges: Vec::new(),
        };
        for i in 0..spec.bridges {
            let (station, served, gate) = station(i)?;
            rig.sims.push(served);
            rig.gates.push(gate);
            let bridge = Bridge::start(
                station,
                None,
                BridgeConfig {
                    namespace: Some(format!("bot{i}")),
                    rate_hz: spec.rate_hz,
                    listen: vec![],
                    connect: vec![rig.router_ep.clone()],
                    mode: ZenohMode::Client,
                    ..BridgeConfig::default()
                },
            )
            .map_err(|e| BenchError::new(format!("starting bridge bot{i}"), e))?;
            rig.bridges.push(bridge);
        }
        Ok(rig)
    }

    /// Waits until every bridge has delivered a message (at most [`READY_TIMEOUT`]).
    fn ready(&self) -> Result<(), BenchError> {
        let n = self.bridges.len();
        let by = Instant::now() + READY_TIMEOUT;
        while self.inbox.heard() < n {
            if Instant::now() > by {
                return Err(BenchError::msg(format!(
                    "only {} of {n} bridges delivered a joint state within {} s",
                    self.inbox.heard(),
                    READY_TIMEOUT.as_secs()
                )));
            }
            thread::sleep(Duration::from_millis(20));
        }
        Ok(())
    }

    /// Each bridge's published count now.
    fn published(&self) -> Vec<u64> {
        self.bridges
            .iter()
            .map(|b| b.health().states.published)
            .collect()
    }

    /// Ends the publishing: closes every bus link, waits until no count has moved for
    /// [`SETTLE`] (at most [`SETTLE_TIMEOUT`]), then the [`DRAIN`]; each bridge's final
    /// count, and whether they settled.
    fn quiesce(&self) -> (Vec<u64>, bool) {
        for g in &self.gates {
            g.store(true, Ordering::Relaxed);
        }
        let by = Instant::now() + SETTLE_TIMEOUT;
        let mut last = self.published();
        let mut still = Instant::now();
        let mut settled = false;
        while Instant::now() < by {
            thread::sleep(Duration::from_millis(20));
            let now = self.published();
            if now == last {
                if still.elapsed() >= SETTLE {
                    settled = true;
                    break;
                }
            } else {
                last = now;
                still = Instant::now();
            }
        }
        thread::sleep(DRAIN);
        let last = self.published();
        (last, settled)
    }

    /// Stops the bridges (each `Bridge::run` on its own thread, told to stop at once),
    /// then the subscriber, the router and the simulators; what the subscriber received.
    fn stop(self) -> Result<HashMap<String, Vec<Message>>, BenchError> {
        let stop = StopToken::new();
        stop.stop();
        let stopping: Vec<_> = self
            .bridges
            .into_iter()
            .map(|b| {
                let stop = stop.clone();
                thread::spawn(move || b.run(&stop).map_err(|e| e.to_string()))
            })
            .collect();
        let mut error = None;
        for t in stopping {
            match t.join() {
                Ok(Ok(())) => {}
                Ok(Err(e)) => error = Some(BenchError::msg(format!("stopping a bridge: {e}"))),
                Err(_) => error = Some(BenchError::msg("a bridge's thread panicked")),
            }
        }
        drop(self.subscriber);
        let _ = self.client.close().wait();
        let _ = self.router.close().wait();
        for s in self.sims {
            let _ = s.stop();
        }
        if let Some(e) = error {
            return Err(e);
        }
        Ok(std::mem::take(
            &mut *self
                .inbox
                .by_ns
                .lock()
                .unwrap_or_else(PoisonError::into_inner),
        ))
    }
}

/// Each bridge: the window between `c0` and `c1`, the whole run up to `totals`, from what
/// was `received`.
fn bots(c0: &Cut, c1: &Cut, totals: &[u64], received: &HashMap<String, Vec<Message>>) -> Vec<Bot> {
    c0.counts
        .iter()
        .zip(&c1.counts)
        .zip(totals)
        .enumerate()
        .map(|(i, ((a, b), total))| {
            let namespace = format!("bot{i}");
            let all = received.get(&namespace).map_or(&[][..], Vec::as_slice);
            let msgs: Vec<&Message> = all
                .iter()
                .filter(|m| m.stamp_ms > c0.unix_ms && m.stamp_ms <= c1.unix_ms)
                .collect();
            Bot {
                namespace,
                published: b.0.saturating_sub(a.0),
                received: msgs.len() as u64,
                published_total: *total,
                received_total: all.len() as u64,
                partial: msgs
                    .iter()
                    .filter(|m| m.joints < usize::from(JOINTS))
                    .count() as u64,
                joints_left_out: b.1.saturating_sub(a.1),
                failed_samples: b.2.saturating_sub(a.2),
                lost_samples: b.3.saturating_sub(a.3),
                latency_us: msgs.iter().map(|m| m.latency_us).collect(),
                interval_us: intervals(&msgs),
            }
        })
        .collect()
}

/// The time between consecutive stamps, µs.
fn intervals(msgs: &[&Message]) -> Vec<f64> {
    let mut stamps: Vec<f64> = msgs.iter().map(|m| m.stamp_ms).collect();
    stamps.sort_by(f64::total_cmp);
    stamps.windows(2).map(|w| (w[1] - w[0]) * 1e3).collect()
}

/// One bridge on the built-in simulated robot at `asked_hz` for `spec`'s warm-up and
/// window.
fn builtin_run(spec: &Spec, asked_hz: f64) -> Result<BuiltinRun, BenchError> {
    let (station, live) = Station::simulated_live(None)
        .map_err(|e| BenchError::new("the built-in simulated robot", e))?;
    let bridge = Bridge::start(
        station,
        Some(live),
        BridgeConfig {
            namespace: Some("builtin".into()),
            rate_hz: asked_hz,
            listen: vec![],
            ..BridgeConfig::default()
        },
    )
    .map_err(|e| BenchError::new("starting the built-in robot's bridge", e))?;
    let by = Instant::now() + READY_TIMEOUT;
    while bridge.health().states.published == 0 {
        if Instant::now() > by {
            return Err(BenchError::msg(
                "the built-in robot's bridge published no joint state",
            ));
        }
        thread::sleep(Duration::from_millis(10));
    }
    thread::sleep(spec.warmup);
    let (a, t0) = (bridge.health().states, Instant::now());
    thread::sleep(spec.secs);
    let (b, t1) = (bridge.health().states, Instant::now());
    let run = BuiltinRun {
        asked_hz,
        capacity: bridge.capacity().clone(),
        wall: t1.duration_since(t0),
        published: b.published.saturating_sub(a.published),
        lost: b.lost_samples.saturating_sub(a.lost_samples),
        failed: b.failed_samples.saturating_sub(a.failed_samples),
        achieved_hz: b.achieved_hz,
    };
    let stop = StopToken::new();
    stop.stop();
    bridge
        .run(&stop)
        .map_err(|e| BenchError::new("stopping the built-in robot's bridge", e))?;
    Ok(run)
}

/// The built-in robot at the bridge's default rate, then at
/// [`BUILTIN_SHARE_OF_LIMIT`] of its buses' limit (rounded down to 0.1 Hz).
fn builtin_runs(spec: &Spec) -> Result<Vec<BuiltinRun>, BenchError> {
    let default = builtin_run(spec, BridgeConfig::default().rate_hz)?;
    let within = (default.limit_hz() * BUILTIN_SHARE_OF_LIMIT * 10.0).floor() / 10.0;
    let mut runs = vec![default];
    if within.is_finite() && within < runs[0].asked_hz {
        runs.push(builtin_run(spec, within)?);
    }
    Ok(runs)
}

/// Runs `spec` (see the [module docs](self)).
pub fn run(spec: Spec) -> Result<BridgeResult, BenchError> {
    if !BRIDGES.contains(&spec.bridges) {
        return Err(BenchError::msg(format!(
            "{} bridges: {}..={} accepted",
            spec.bridges,
            BRIDGES.start(),
            BRIDGES.end()
        )));
    }
    let builtin = builtin_runs(&spec)?;
    let rig = Rig::start(&spec)?;
    rig.ready()?;
    let capacity = rig
        .bridges
        .first()
        .map(|b| b.capacity().clone())
        .ok_or_else(|| BenchError::msg("no bridge"))?;
    thread::sleep(spec.warmup);
    let c0 = Cut::now(&rig.bridges);
    thread::sleep(spec.secs);
    let c1 = Cut::now(&rig.bridges);
    let (totals, settled) = rig.quiesce();
    let router = rig.router_ep.clone();
    let undecodable = Arc::clone(&rig.inbox);
    let received = rig.stop()?;
    Ok(BridgeResult {
        spec,
        router,
        capacity,
        builtin,
        wall: c1.at.duration_since(c0.at),
        bots: bots(&c0, &c1, &totals, &received),
        undecodable: undecodable.undecodable.load(Ordering::Relaxed),
        settled,
        process_cpu: c1.process.saturating_sub(c0.process),
        sims_cpu: cpu::tasks_cpu(&c0.tasks, &c1.tasks, is_sim),
        bridge_threads_cpu: cpu::tasks_cpu(&c0.tasks, &c1.tasks, is_bridge_thread),
        main_cpu: c1.main.saturating_sub(c0.main),
    })
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;

    #[test]
    fn the_robot_file_has_the_seven_joints() {
        let c = RobotConfig::from_toml_str(&robot_file()).unwrap();
        assert_eq!(c.joints.len(), usize::from(JOINTS));
        let (s, served, _gate) = station(0).unwrap();
        assert_eq!(s.robot().unwrap().joints.len(), usize::from(JOINTS));
        drop(s);
        let _ = served.stop();
    }

    #[test]
    fn loss_is_what_was_published_and_not_received() {
        let b = Bot {
            published_total: 100,
            received_total: 101,
            ..Bot::default()
        };
        assert_eq!((b.missing(), b.loss()), (0, 0.0));
        let b = Bot {
            published_total: 100,
            received_total: 97,
            ..Bot::default()
        };
        assert_eq!(b.missing(), 3);
        assert!((b.loss() - 0.03).abs() < 1e-12);
    }
}
