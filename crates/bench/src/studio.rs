//! The web studio (`robobus-studio`) under load, in-process: the built-in simulated robot
//! on the wall clock (`Station::simulated_live`) served by `Studio::serve` on its own
//! thread, and WebSocket clients (`tungstenite`) on threads of this process, as a page
//! would talk to it.
//!
//! - **Telemetry fan-out**: N pages each subscribe to `whj.sample` of the 7 joints at
//!   [`ASKED_HZ`] with [`FPS`] frames a second, and read. Every stream subscribes to the
//!   station's one sampling of the bus (`Station::telemetry`), so N pages cost the bus one
//!   stream's frames; each page's samples say so (the same `seq` carries the same read
//!   instant on every page, [`FanOut::same_samples`]).
//! - **Jog latency**: one controlling page (take control, arm, heartbeat every 100 ms)
//!   jogs WHJ joint 1 at [`JOG_HZ`] between −1° and +1° (each jog one position servo
//!   frame), and times each jog message to its `jogged` reply on the page, and to the
//!   instant the simulated joint's position target changed (the simulator's own state,
//!   `LiveSimulator::snapshot`, polled in a tight loop by a thread of this process from
//!   the moment the jog is sent).
//!
//! The wire model ([`WireModel`]) gives what the bus itself could carry: the exact frames
//! of one sample and of one servo cycle, recorded on a second simulated chain, timed with
//! `robobus_whj::timing::frame_duration`.

use std::collections::HashMap;
use std::net::{SocketAddr, TcpStream};
use std::sync::mpsc;
use std::sync::{Arc, Barrier, Mutex, PoisonError};
use std::thread;
use std::time::{Duration, Instant, SystemTime};

use robobus::catalogue::{Request, whj as cat_whj};
use robobus::frontend::live::LiveSimulator;
use robobus::ops::{Control, StopToken};
use robobus::station::Station;
use robobus::whj::{JointBus, JointBusConfig};
use robobus_link::{FrameLink, FrameLinkError, IdFilter, MemoryBus, Received};
use robobus_sim::whj::{Served, WhjBus, WhjModel};
use robobus_studio::{Studio, StudioConfig};
use robobus_whj::CanFrame;
use robobus_whj::timing::{BitRates, frame_duration};
use serde_json::{Value, json};
use tungstenite::{Message, WebSocket};

use crate::stats::Summary;
use crate::{BenchError, cpu, whj};

/// Sampling rate each page asks for, Hz.
pub const ASKED_HZ: f64 = 500.0;
/// Frames a second each page asks for.
pub const FPS: f64 = 60.0;
/// Jogs a second.
pub const JOG_HZ: f64 = 20.0;
/// "The bus period" the latencies are compared with: the period of the 500 Hz telemetry
/// the pages ask for, 2 ms.
pub const BUS_PERIOD: Duration = Duration::from_millis(2);
/// The simulated robot's WHJ joints.
pub const JOINTS: u8 = 7;
/// How often the controlling page sends its heartbeat.
const HEARTBEAT: Duration = Duration::from_millis(100);
/// How long a message is awaited during setup.
const SETUP_TIMEOUT: Duration = Duration::from_secs(10);

/// What one `whj.sample` of 7 joints and one position servo cycle cost on the modelled
/// 1 / 5 Mbit/s wire, from the exact frames exchanged.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct WireModel {
    /// Request–reply transactions in one sample (a status query and a speed read per
    /// joint).
    pub transactions: usize,
    /// One sample's transactions back to back: Σ (request + processing delay + reply −
    /// the intermission the delay hides).
    pub sample: Duration,
    /// The link's own allowance in the client's duplicate check
    /// (`JointBus::duplicate_check`: 0 on the in-process memory bus, where only the
    /// arbitration loser's frame is waited for). A sample's requests are pipelined, so
    /// the holds overlap the other requests' frames and this model leaves them out.
    pub collision_window: Duration,
    /// One jog: one position servo frame and its feedback.
    pub jog: Duration,
    /// A 7-joint position servo cycle, one frame and its feedback per joint.
    pub servo_cycle: Duration,
}

impl WireModel {
    /// Samples a second the wire could carry (one stream alone on the bus).
    pub fn wire_hz(&self) -> f64 {
        1.0 / self.sample.as_secs_f64().max(1e-9)
    }
}

/// One page of a fan-out run.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Page {
    /// How long it read.
    pub wall: Duration,
    /// `telemetry` messages received.
    pub messages: u64,
    /// Σ `skipped` of them (taken by the server and never delivered, lost ones included).
    pub skipped: u64,
    /// Samples the server took for this stream per second (from the samples' `seq` and
    /// `unix_ms`).
    pub taken_hz: f64,
    /// Samples that came `late` (the sampler could not keep its slot), of those delivered.
    pub late: u64,
    /// Samples that failed (a read of the whole request), of those delivered.
    pub failed: u64,
    /// Age of each delivered sample at the page (now − `unix_ms`), µs.
    pub age_us: Vec<f64>,
    /// Each delivered sample's `seq` and read instant (`unix_ms`).
    pub samples: Vec<(u64, f64)>,
    /// CPU time of this page's thread while it read.
    pub cpu: Duration,
}

impl Page {
    /// Messages delivered a second.
    pub fn delivered_hz(&self) -> f64 {
        self.messages as f64 / self.wall.as_secs_f64().max(1e-9)
    }
}

/// One fan-out run: N pages streaming the same request.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct FanOut {
    /// Pages.
    pub subscribers: usize,
    /// The measured window (all pages reading).
    pub wall: Duration,
    /// Each page.
    pub pages: Vec<Page>,
    /// CPU time of the whole process over the window.
    pub process_cpu: Duration,
    /// Of it, the pages' threads (each measured by itself).
    pub clients_cpu: Duration,
    /// Of it, the thread that ran the benchmark (waiting).
    pub main_cpu: Duration,
    /// Of it, the simulators' serving threads (`sim-whj`, `robobus-sim-wck`, from
    /// `/proc/self/task`, 10 ms ticks).
    pub sims_cpu: Duration,
}

impl FanOut {
    /// The studio's own CPU: the process less the pages, the benchmark's thread and the
    /// simulators (its runtime thread, the stream forwarders, the samplers, the bus
    /// thread, the guard and the blocking pool).
    pub fn server_cpu(&self) -> Duration {
        self.process_cpu
            .saturating_sub(self.clients_cpu)
            .saturating_sub(self.main_cpu)
            .saturating_sub(self.sims_cpu)
    }

    /// Samples the server took a second for the stream of the page that had fewest.
    pub fn fewest_taken_hz(&self) -> f64 {
        let fewest = self
            .pages
            .iter()
            .map(|p| p.taken_hz)
            .fold(f64::INFINITY, f64::min);
        if fewest.is_finite() { fewest } else { 0.0 }
    }

    /// Of the samples a later page received with a `seq` the first page received too, how
    /// many carry the first page's read instant, and how many there were: equal when one
    /// sampling serves every page (a sampler per page would number its own samples).
    pub fn same_samples(&self) -> (usize, usize) {
        let Some((first, rest)) = self.pages.split_first() else {
            return (0, 0);
        };
        let at: HashMap<u64, f64> = first.samples.iter().copied().collect();
        let (mut same, mut common) = (0, 0);
        for (seq, t) in rest.iter().flat_map(|p| p.samples.iter()) {
            if let Some(t0) = at.get(seq) {
                common += 1;
                same += usize::from(t0.to_bits() == t.to_bits());
            }
        }
        (same, common)
    }

    /// Share of a core, `d` over the window.
    pub fn share(&self, d: Duration) -> f64 {
        d.as_secs_f64() / self.wall.as_secs_f64().max(1e-9)
    }

    /// Ages of every page's samples, µs.
    pub fn ages(&self) -> Summary {
        let all: Vec<f64> = self
            .pages
            .iter()
            .flat_map(|p| p.age_us.iter().copied())
            .collect();
        Summary::of_us(&all)
    }
}

/// The jog run.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Jog {
    /// How long it jogged.
    pub wall: Duration,
    /// Jogs sent.
    pub sent: u64,
    /// Jogs answered by an `error`.
    pub errors: u64,
    /// Jogs cut short by the jog step or a limit (`limited`).
    pub limited: u64,
    /// Jog message sent → its `jogged` reply read by the page, µs.
    pub reply_us: Vec<f64>,
    /// Jog message sent → the simulated joint's target changed to the position sent, µs.
    pub wire_us: Vec<f64>,
    /// For each of `wire_us`, how long before the poll that saw the change the previous
    /// poll (or the jog) was: the change happened in that interval, µs.
    pub poll_gap_us: Vec<f64>,
    /// Jogs neither answered nor refused.
    pub unanswered: u64,
    /// Answered jogs whose target change the poller did not see (the target did not
    /// change, or not within 50 ms).
    pub unmatched: u64,
    /// Heartbeats sent.
    pub heartbeats: u64,
}

/// Everything the studio case measured.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct StudioResult {
    /// The wire model.
    pub model: WireModel,
    /// Fan-out runs.
    pub fan_out: Vec<FanOut>,
    /// The jog run.
    pub jog: Jog,
}

// ---------------------------------------------------------------------------------------
// The wire model
// ---------------------------------------------------------------------------------------

type Log = Arc<Mutex<Vec<(bool, CanFrame)>>>;

/// A frame link that records every frame sent (`true`) and received (`false`).
struct Recorder<L> {
    inner: L,
    log: Log,
}

impl<L: FrameLink> FrameLink for Recorder<L> {
    fn send(&mut self, frame: &CanFrame) -> Result<(), FrameLinkError> {
        self.log
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .push((true, *frame));
        self.inner.send(frame)
    }

    fn recv(&mut self, deadline: Instant) -> Result<Received, FrameLinkError> {
        let r = self.inner.recv(deadline)?;
        self.log
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .push((false, r.frame));
        Ok(r)
    }

    fn set_filters(&mut self, filters: &[IdFilter]) -> Result<(), FrameLinkError> {
        self.inner.set_filters(filters)
    }

    robobus_link::forward_frame_link_clock!(inner);
}

/// The frames as request–reply transactions back to back, whatever order they went in (a
/// pipelined sample sends its requests together): (requests, replies, Σ request +
/// Σ (max(delay, intermission) + reply − intermission)).
fn transactions(frames: &[(bool, CanFrame)], rates: BitRates) -> (usize, usize, Duration) {
    let gap = whj::intermission(rates);
    let (mut n, mut replies) = (0, 0);
    let mut total = Duration::ZERO;
    for (sent, f) in frames {
        if *sent {
            n += 1;
            total += frame_duration(f, rates);
        } else {
            replies += 1;
            total += (whj::DEFAULT_DELAY.max(gap) + frame_duration(f, rates)).saturating_sub(gap);
        }
    }
    (n, replies, total)
}

/// Records one `whj.sample` of 7 joints and one 7-joint position servo cycle on a chain
/// built as the live station's is (WHJ30, 1 / 5 Mbit/s, 20 µs processing delay).
pub fn wire_model() -> Result<WireModel, BenchError> {
    let wire = MemoryBus::new();
    let served = Served::spawn(
        "bench-model-whj",
        WhjBus::chain(1..=JOINTS, WhjModel::Whj30, 11),
        wire.endpoint(),
    )
    .map_err(|e| BenchError::new("starting the model's simulator", e))?;
    let log: Log = Arc::default();
    let config = JointBusConfig::simulated();
    let bus = JointBus::open_with(
        Recorder {
            inner: wire.endpoint(),
            log: Arc::clone(&log),
        },
        config,
    )
    .map_err(|e| BenchError::new("JointBus", e))?;
    let collision_window = bus.duplicate_check().unwrap_or_default();
    let mut station = Station::new();
    let port = station.add_whj("sim-whj", bus);
    let request = Request::WhjSample(cat_whj::Sample {
        bus: None,
        joints: "1-7".into(),
        broadcast: false,
    });
    let rates = BitRates::WHJ;
    let take = || std::mem::take(&mut *log.lock().unwrap_or_else(PoisonError::into_inner));
    // The first sample connects (identities cached); the second is what a stream sends.
    for _ in 0..2 {
        take();
        robobus::catalogue::run(&station, &request, &mut Control::none())
            .map_err(|e| BenchError::new("whj.sample", e))?;
    }
    let (n, replies, sample) = transactions(&take(), rates);
    if n == 0 || replies != n {
        return Err(BenchError::msg(format!(
            "the model's sample sent {n} requests and had {replies} answered"
        )));
    }
    let joints = whj::prepare(port.bus(), JOINTS)?;
    take();
    for (id, p) in &joints {
        port.bus()
            .joint_unchecked(*id)
            .command_position(*p)
            .map_err(|e| BenchError::new("position servo frame", e))?;
    }
    let (_, _, servo_cycle) = transactions(&take(), rates);
    drop(station);
    let _ = served.stop();
    Ok(WireModel {
        transactions: n,
        sample,
        collision_window,
        jog: servo_cycle / u32::from(JOINTS),
        servo_cycle,
    })
}

// ---------------------------------------------------------------------------------------
// CPU time per thread
// ---------------------------------------------------------------------------------------

// ---------------------------------------------------------------------------------------
// A page
// ---------------------------------------------------------------------------------------

fn unix_ms() -> f64 {
    SystemTime::now()
        .duration_since(SystemTime::UNIX_EPOCH)
        .map_or(0.0, |d| d.as_secs_f64() * 1e3)
}

/// A page's WebSocket: blocking reads with a short timeout.
struct PageSocket {
    ws: WebSocket<TcpStream>,
}

impl PageSocket {
    fn connect(addr: SocketAddr, read_timeout: Duration) -> Result<Self, BenchError> {
        let stream = TcpStream::connect(addr)
            .map_err(|e| BenchError::new(format!("connecting {addr}"), e))?;
        // A browser's socket does not wait to coalesce small writes either.
        stream
            .set_nodelay(true)
            .map_err(|e| BenchError::new("TCP_NODELAY", e))?;
        let (ws, _) = tungstenite::client(format!("ws://{addr}/api/ws"), stream)
            .map_err(|e| BenchError::msg(format!("WebSocket handshake: {e}")))?;
        ws.get_ref()
            .set_read_timeout(Some(read_timeout))
            .map_err(|e| BenchError::new("read timeout", e))?;
        let mut s = Self { ws };
        s.expect(|v| v["type"] == "hello", SETUP_TIMEOUT, None)?;
        Ok(s)
    }

    fn send(&mut self, v: &Value) -> Result<(), BenchError> {
        self.ws
            .send(Message::text(v.to_string()))
            .map_err(|e| BenchError::new("WebSocket send", e))
    }

    /// The next message, `None` when none came within the read timeout.
    fn read(&mut self) -> Result<Option<Value>, BenchError> {
        match self.ws.read() {
            Ok(Message::Text(t)) => serde_json::from_str(t.as_str())
                .map(Some)
                .map_err(|e| BenchError::new("a message that is not JSON", e)),
            Ok(_) => Ok(None),
            Err(tungstenite::Error::Io(e))
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                ) =>
            {
                Ok(None)
            }
            Err(e) => Err(BenchError::new("WebSocket read", e)),
        }
    }

    /// Reads until a message passes `want`; an `error` message fails it. With `beat`,
    /// sends a heartbeat every [`HEARTBEAT`] while it waits.
    fn expect(
        &mut self,
        want: impl Fn(&Value) -> bool,
        timeout: Duration,
        mut beat: Option<&mut Instant>,
    ) -> Result<Value, BenchError> {
        let deadline = Instant::now() + timeout;
        while Instant::now() < deadline {
            if let Some(last) = beat.as_deref_mut()
                && last.elapsed() >= HEARTBEAT
            {
                self.send(&json!({"type": "heartbeat"}))?;
                *last = Instant::now();
            }
            if let Some(v) = self.read()? {
                if v["type"] == "error" {
                    return Err(BenchError::msg(format!("the studio answered {v}")));
                }
                if want(&v) {
                    return Ok(v);
                }
            }
        }
        Err(BenchError::msg("the studio did not answer in time"))
    }

    fn close(mut self) {
        let _ = self.ws.close(None);
        let _ = self.ws.flush();
    }
}

// ---------------------------------------------------------------------------------------
// The studio
// ---------------------------------------------------------------------------------------

/// A studio served on its own thread until dropped.
struct Running {
    addr: SocketAddr,
    sim: LiveSimulator,
    stop: StopToken,
    thread: Option<thread::JoinHandle<Result<(), robobus_studio::StudioError>>>,
}

impl Running {
    fn start() -> Result<Self, BenchError> {
        let (station, sim) = Station::simulated_live(None)
            .map_err(|e| BenchError::new("the simulated live station", e))?;
        let studio = Studio::bind(
            station,
            Some(sim.clone()),
            StudioConfig {
                listen: SocketAddr::from(([127, 0, 0, 1], 0)),
                token: None,
                read_only: false,
                guard: robobus::frontend::guard::GuardConfig::default(),
            },
        )
        .map_err(|e| BenchError::new("binding the studio", e))?;
        let addr = studio.addr();
        let stop = StopToken::new();
        let flag = stop.clone();
        let thread = thread::Builder::new()
            .name("bench-studio".into())
            .spawn(move || studio.serve(&flag))
            .map_err(|e| BenchError::new("starting the studio's thread", e))?;
        Ok(Self {
            addr,
            sim,
            stop,
            thread: Some(thread),
        })
    }

    fn stop(mut self) -> Result<(), BenchError> {
        self.halt()
    }

    fn halt(&mut self) -> Result<(), BenchError> {
        self.stop.stop();
        match self.thread.take().map(thread::JoinHandle::join) {
            Some(Ok(Err(e))) => Err(BenchError::new("serving the studio", e)),
            Some(Err(_)) => Err(BenchError::msg("the studio's thread panicked")),
            _ => Ok(()),
        }
    }
}

impl Drop for Running {
    fn drop(&mut self) {
        let _ = self.halt();
    }
}

/// Runs the whole case: the wire model, a fan-out run per entry of `subscribers`, and the
/// jog run, each for `secs`.
pub fn run(subscribers: &[usize], secs: Duration) -> Result<StudioResult, BenchError> {
    let model = wire_model()?;
    let studio = Running::start()?;
    let mut r = StudioResult {
        model,
        ..StudioResult::default()
    };
    for &n in subscribers {
        r.fan_out.push(fan_out(studio.addr, n, secs)?);
        // The closed pages' streams end on the studio's blocking pool.
        thread::sleep(Duration::from_millis(300));
    }
    r.jog = jog(&studio, secs)?;
    studio.stop()?;
    Ok(r)
}

/// Subscribes and waits for the first sample.
fn subscribe(addr: SocketAddr) -> Result<PageSocket, BenchError> {
    let mut s = PageSocket::connect(addr, Duration::from_millis(50))?;
    s.send(&json!({
        "type": "subscribe", "stream": "bench",
        "request": {"op": "whj.sample", "joints": format!("1-{JOINTS}")},
        "rate_hz": ASKED_HZ, "fps": FPS,
    }))?;
    s.expect(|v| v["type"] == "telemetry", SETUP_TIMEOUT, None)?;
    Ok(s)
}

/// Reads telemetry until `deadline`.
fn read_page(s: &mut PageSocket, deadline: Instant) -> Result<Page, BenchError> {
    let start = Instant::now();
    let mut p = Page::default();
    let mut first: Option<(u64, f64)> = None;
    let mut last: Option<(u64, f64)> = None;
    while Instant::now() < deadline {
        let Some(v) = s.read()? else { continue };
        if v["type"] != "telemetry" {
            continue;
        }
        let now = unix_ms();
        let sample = &v["sample"];
        p.messages += 1;
        p.skipped += v["skipped"].as_u64().unwrap_or(0);
        p.late += u64::from(sample["late"].as_bool().unwrap_or(false));
        p.failed += u64::from(!sample["failed"].is_null());
        if let (Some(seq), Some(at)) = (sample["seq"].as_u64(), sample["unix_ms"].as_f64()) {
            p.age_us.push((now - at) * 1e3);
            p.samples.push((seq, at));
            first.get_or_insert((seq, at));
            last = Some((seq, at));
        }
    }
    p.wall = start.elapsed();
    if let (Some((s0, t0)), Some((s1, t1))) = (first, last)
        && t1 > t0
    {
        p.taken_hz = (s1 - s0) as f64 / ((t1 - t0) / 1e3);
    }
    Ok(p)
}

/// `n` pages subscribed at once, reading for `secs`.
fn fan_out(addr: SocketAddr, n: usize, secs: Duration) -> Result<FanOut, BenchError> {
    let ready = Arc::new(Barrier::new(n + 1));
    let done = Arc::new(Barrier::new(n + 1));
    let release = Arc::new(Barrier::new(n + 1));
    let mut handles = Vec::new();
    for i in 0..n {
        let (ready, done, release) = (Arc::clone(&ready), Arc::clone(&done), Arc::clone(&release));
        let h = thread::Builder::new()
            .name(format!("bench-ws-{i}"))
            .spawn(move || {
                // Every page passes every barrier, whatever fails.
                let socket = subscribe(addr);
                ready.wait();
                let deadline = Instant::now() + secs;
                let cpu0 = cpu::thread();
                let page = socket.and_then(|mut s| {
                    let p = read_page(&mut s, deadline);
                    Ok((s, p?))
                });
                let cpu = cpu::thread().saturating_sub(cpu0);
                done.wait();
                release.wait();
                page.map(|(s, mut p)| {
                    s.close();
                    p.cpu = cpu;
                    p
                })
            })
            .map_err(|e| BenchError::new("starting a page's thread", e))?;
        handles.push(h);
    }
    ready.wait();
    let t0 = Instant::now();
    let (process0, main0, tasks0) = (cpu::process(), cpu::thread(), cpu::tasks());
    done.wait();
    let (process1, main1, tasks1) = (cpu::process(), cpu::thread(), cpu::tasks());
    let wall = t0.elapsed();
    release.wait();
    let mut pages = Vec::new();
    for h in handles {
        pages.push(
            h.join()
                .map_err(|_| BenchError::msg("a page's thread panicked"))??,
        );
    }
    Ok(FanOut {
        subscribers: n,
        wall,
        clients_cpu: pages.iter().map(|p| p.cpu).sum(),
        pages,
        process_cpu: process1.saturating_sub(process0),
        main_cpu: main1.saturating_sub(main0),
        sims_cpu: cpu::tasks_cpu(&tasks0, &tasks1, |n| {
            ["sim-whj", "robobus-sim-wck"].contains(&n)
        }),
    })
}

/// A change of the simulated joint's position target: (seen at, the previous poll ended
/// at, the new target).
type Change = (Instant, Instant, f64);

/// Polls the simulated joint 1's position target from each instant a jog is sent until it
/// changes (or 50 ms pass), in a tight loop.
fn poll_target(sim: &LiveSimulator, jogs: &mpsc::Receiver<()>, changes: &Mutex<Vec<Change>>) {
    let target = || {
        sim.snapshot()
            .whj
            .first()
            .map_or(f64::NAN, |j| j.target_position_deg)
    };
    let mut known = target();
    while jogs.recv().is_ok() {
        let mut prev = Instant::now();
        let until = prev + Duration::from_millis(50);
        while prev < until {
            let t = target();
            let at = Instant::now();
            if (t - known).abs() > 1e-9 {
                known = t;
                changes
                    .lock()
                    .unwrap_or_else(PoisonError::into_inner)
                    .push((at, prev, t));
                break;
            }
            prev = at;
            thread::yield_now();
        }
    }
}

/// Jogs sent: by ID, when it was sent, and when its `jogged` reply was read with the
/// position it sent.
type Jogs = HashMap<u64, (Instant, Option<(Instant, f64)>)>;

/// Takes control, arms, and puts joint 1 in position mode (disable, mode, enable); returns
/// when the last heartbeat was sent, and the control secret the studio gave this socket
/// (what every message that changes a device carries).
fn take_control(s: &mut PageSocket) -> Result<(Instant, Value), BenchError> {
    s.send(&json!({"type": "take-control"}))?;
    let control = s.expect(
        |v| v["type"] == "control" && v["controller"] == true,
        SETUP_TIMEOUT,
        None,
    )?["secret"]
        .clone();
    s.send(&json!({"type": "arm", "control": control}))?;
    s.expect(
        |v| v["type"] == "control" && v["armed"] == true,
        SETUP_TIMEOUT,
        None,
    )?;
    let mut beat = Instant::now();
    s.send(&json!({"type": "heartbeat"}))?;
    for (id, request) in [
        (1u64, json!({"op": "whj.disable", "joints": "1"})),
        (
            2,
            json!({"op": "whj.mode", "joints": "1", "mode": "position"}),
        ),
        (3, json!({"op": "whj.enable", "joints": "1"})),
    ] {
        s.send(&json!({"type": "run", "id": id, "request": request, "control": control}))?;
        s.expect(
            |v| v["type"] == "report" && v["id"] == id,
            SETUP_TIMEOUT,
            Some(&mut beat),
        )?;
    }
    Ok((beat, control))
}

/// Jogs joint 1 between −1° and +1° at [`JOG_HZ`] for `secs`, with a heartbeat every
/// [`HEARTBEAT`], then reads the last answers (at most a second more). `poll` is told of
/// each jog just before it is sent.
fn jog_loop(
    s: &mut PageSocket,
    (mut beat, control): (Instant, Value),
    poll: &mpsc::Sender<()>,
    secs: Duration,
    out: &mut Jog,
    jogs: &mut Jogs,
) -> Result<(), BenchError> {
    let period = Duration::from_secs_f64(1.0 / JOG_HZ);
    let start = Instant::now();
    let end = start + secs;
    let mut next = start;
    let mut id = 100u64;
    while Instant::now() < end + Duration::from_secs(1) {
        let now = Instant::now();
        if beat.elapsed() >= HEARTBEAT {
            s.send(&json!({"type": "heartbeat"}))?;
            beat = Instant::now();
            out.heartbeats += 1;
        }
        if now < end && now >= next {
            id += 1;
            let target = if id.is_multiple_of(2) { 1.0 } else { -1.0 };
            let _ = poll.send(());
            let at = Instant::now();
            s.send(&json!({
                "type": "jog", "id": id, "family": "whj", "device": 1, "target": target,
                "control": control,
            }))?;
            jogs.insert(id, (at, None));
            out.sent += 1;
            next += period;
        }
        if now >= end && jogs.values().all(|j| j.1.is_some()) {
            break;
        }
        let Some(v) = s.read()? else { continue };
        let at = Instant::now();
        let Some(jid) = v["id"].as_u64() else {
            continue;
        };
        match v["type"].as_str() {
            Some("jogged") => {
                if let Some(j) = jogs.get_mut(&jid) {
                    j.1 = Some((at, v["sent"].as_f64().unwrap_or(f64::NAN)));
                }
                out.limited += u64::from(v["limited"].as_bool().unwrap_or(false));
            }
            Some("error") if jogs.contains_key(&jid) => {
                jogs.remove(&jid);
                out.errors += 1;
            }
            _ => {}
        }
    }
    out.wall = start.elapsed().min(secs);
    Ok(())
}

/// Each answered jog's reply latency, and the instant its position reached the joint.
fn timings(jogs: Jogs, changes: &[Change], out: &mut Jog) {
    let mut sorted: Vec<_> = jogs.into_iter().collect();
    sorted.sort_by_key(|(id, _)| *id);
    for (_, (sent_at, answer)) in sorted {
        let Some((answered, position)) = answer else {
            out.unanswered += 1;
            continue;
        };
        out.reply_us
            .push(answered.duration_since(sent_at).as_secs_f64() * 1e6);
        let hit = changes
            .iter()
            .find(|(t, _, v)| *t >= sent_at && (v - position).abs() < 0.001);
        match hit {
            Some((t, prev, _)) => {
                out.wire_us
                    .push(t.duration_since(sent_at).as_secs_f64() * 1e6);
                out.poll_gap_us
                    .push(t.duration_since((*prev).max(sent_at)).as_secs_f64() * 1e6);
            }
            None => out.unmatched += 1,
        }
    }
}

/// The controlling page: takes control, arms, puts joint 1 in position mode, and jogs it
/// between −1° and +1° at [`JOG_HZ`] for `secs`.
fn jog(studio: &Running, secs: Duration) -> Result<Jog, BenchError> {
    let mut s = PageSocket::connect(studio.addr, Duration::from_millis(1))?;
    let taken = take_control(&mut s)?;
    let changes: Arc<Mutex<Vec<Change>>> = Arc::default();
    let (tx, rx) = mpsc::channel();
    let poller = {
        let sim = studio.sim.clone();
        let changes = Arc::clone(&changes);
        thread::Builder::new()
            .name("bench-sim-poll".into())
            .spawn(move || poll_target(&sim, &rx, &changes))
            .map_err(|e| BenchError::new("starting the poller", e))?
    };
    let mut out = Jog::default();
    let mut jogs = Jogs::new();
    let result = jog_loop(&mut s, taken, &tx, secs, &mut out, &mut jogs);
    drop(tx);
    let _ = poller.join();
    let _ = s.send(&json!({"type": "disarm"}));
    s.close();
    result?;
    let changes = changes
        .lock()
        .unwrap_or_else(PoisonError::into_inner)
        .clone();
    timings(jogs, &changes, &mut out);
    Ok(out)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;

    #[test]
    fn the_wire_model_counts_two_transactions_per_joint() {
        let m = wire_model().unwrap();
        assert_eq!(m.transactions, 2 * usize::from(JOINTS));
        // A status query and a speed read per joint, each about 0.1 ms at 1 / 5 Mbit/s.
        assert!((400.0..900.0).contains(&m.wire_hz()), "{m:?}");
        // The memory bus's allowance is 0: the window adds nothing on it.
        assert_eq!(m.collision_window, Duration::ZERO);
        assert!(m.jog > Duration::from_micros(50) && m.jog < Duration::from_micros(300));
        assert!(m.servo_cycle.abs_diff(m.jog * u32::from(JOINTS)) < Duration::from_nanos(7));
    }

    #[test]
    fn pages_of_one_sampling_share_their_samples_and_samplers_of_their_own_do_not() {
        let page = |samples: &[(u64, f64)]| Page {
            samples: samples.to_vec(),
            ..Page::default()
        };
        let of = |pages: Vec<Page>| FanOut {
            pages,
            ..FanOut::default()
        };
        // One sampling: a later page sees some of the first page's samples, each with the
        // same read instant, and others the first page skipped.
        let shared = of(vec![
            page(&[(10, 1.5), (18, 17.5), (26, 33.5)]),
            page(&[(11, 3.5), (18, 17.5), (26, 33.5)]),
        ]);
        assert_eq!(shared.same_samples(), (2, 2));
        // A sampler per page numbers its own samples: the same seq, another instant.
        let own = of(vec![
            page(&[(1, 1.5), (2, 3.5)]),
            page(&[(1, 1.7), (2, 3.1)]),
        ]);
        assert_eq!(own.same_samples(), (0, 2));
        assert_eq!(of(vec![page(&[(1, 1.5)])]).same_samples(), (0, 0));
    }
}
