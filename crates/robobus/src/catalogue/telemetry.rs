//! The telemetry stream: a sampler that runs a reading request (`wck.sample`,
//! `wck.status`, `whj.sample` with or without `broadcast`, `whj.status`, or `robot.sample`:
//! a robot file's joints in joint units across its buses) on a [`Station`]
//! at a chosen rate and hands every sample to any number of subscribers.
//!
//! # One sampler per bus, shared: [`Station::telemetry`]
//!
//! Every reader of a bus (a studio page, the bridge, Python, the monitor, a recording)
//! asks the station, not a stream of its own:
//!
//! ```no_run
//! # use std::sync::Arc;
//! # use std::time::Duration;
//! # use robobus::catalogue::{Request, whj};
//! # fn demo(station: Arc<robobus::station::Station>) -> Result<(), robobus::ops::OpError> {
//! let request = Request::WhjSample(whj::Sample {
//!     bus: None,
//!     joints: "1-3".into(),
//!     broadcast: false,
//! });
//! let sub = station.telemetry(request, 100.0, 64)?; // rate_hz, queue capacity
//! while let Ok(d) = sub.recv_timeout(Duration::from_secs(1)) {
//!     // d.sample.report: joints 1..=3 only; d.lost: samples this subscriber lost
//!     // (its queue was full); d.sample.sampled_by: how the bus was read.
//! }
//! drop(sub); // the last subscription gone, the bus is no longer sampled
//! # Ok(()) }
//! ```
//!
//! The station keeps one sampling per bus and kind of reading: every `whj.sample`
//! subscription of a bus shares one, which reads the union of the joints its subscribers
//! asked for (`broadcast` if any of them asked for it) at the highest rate any of them
//! asked; so does every `wck.sample` of a wCK bus, and `robot.sample`. Any other reading
//! request (`wck.status`, `whj.status`, `whj.can-health`) is shared by the subscriptions
//! that ask for exactly the same request. Each [`Subscription`] gets its own devices' rows
//! only, at its own rate (the sampling's samples decimated: at most one per period of its
//! own rate, each the latest there was), in its own bounded queue with its own lost count
//! and sequence numbers (`seq` 0, 1, 2, ... of the samples it was given or lost). A second
//! subscriber costs the bus nothing; a subscriber that asks for more devices or a higher
//! rate changes the sampling from its next sample on; the last subscription dropped (or
//! [`Subscription::close`]d) stops the sampling. [`Station::telemetry_limited`] ends a
//! subscription after a count of samples; [`Subscriber::stats`] says what a subscriber
//! was given (samples, late ones, failed ones). A sample of WHJ joints says how the bus
//! was read ([`Sample::sampled_by`]: pipelined requests, the broadcast status, the cyclic
//! loop's feedback; see [`sample_whj`]).
//!
//! [`Telemetry`] is a sampler of its own, for a caller that wants one whatever else reads
//! the bus. The shared sampling lives in `shared.rs`.
//!
//! Each subscriber has its own bounded queue. A subscriber that does not keep up loses
//! its *oldest* samples, and the next [`Delivery`] says how many it lost; the sampler
//! never waits for a subscriber, so a slow one cannot slow the bus or the others. A
//! [`Sample`] carries its sequence number, when its read completed (wall clock and
//! [`Sample::age`]), how long the read took, whether it came later than its slot, and the
//! request's [`Report`]: a device that did not answer is a row with its failure (`kind`,
//! `error`), never an old value. A read that failed as a whole is a sample with `error`
//! and no report. The sampler stops when the [`Telemetry`] is stopped or dropped, or after
//! its `limit` of samples; subscribers then get what is queued, then the end.

use std::collections::{BTreeSet, VecDeque};
use std::sync::{Arc, Condvar, Mutex, MutexGuard, Weak};
use std::thread::JoinHandle;
use std::time::{Duration, Instant, SystemTime};

use serde::Serialize;

use super::{Report, Request, kind_name};
use crate::ops::{Control, OpError, StopToken};
use crate::station::Station;
use crate::station::sampler::{SampledBy, sample_whj};

mod shared;
pub use shared::Subscription;

/// Sampling rates a stream takes, Hz.
pub const RATE_HZ: std::ops::RangeInclusive<f64> = 0.1..=1000.0;

/// The largest queue a subscriber may ask for, samples.
pub const MAX_QUEUE: usize = 65_536;

/// One sample of the stream.
#[derive(Debug, Clone, Serialize)]
pub struct Sample {
    /// 0, 1, 2, ... in the order taken.
    pub seq: u64,
    /// When the read completed, ms since the Unix epoch.
    pub unix_ms: f64,
    /// How long the read took, ms.
    pub read_ms: f64,
    /// The read started more than one period after its slot (the bus or the host could not
    /// keep the rate): the stream's timing, not the values, is off.
    pub late: bool,
    /// The request's report: one row per device, failures included. In a `wck.sample`
    /// stream a servo's `speed_deg_s` is its position's change since its previous
    /// reading in this stream (`null` until it has two).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub report: Option<Report>,
    /// How the bus was read for it, where the request says (`whj.sample`: `pipelined`,
    /// `one-by-one`, `broadcast` or `cyclic`; `wck.sample`: `status-reads`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sampled_by: Option<SampledBy>,
    /// The kind of the failure, if the read failed as a whole (a frame that could not be
    /// sent, a link that went away): the [`ErrorKind`](crate::ErrorKind) name.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub failed: Option<String>,
    /// Why the read failed as a whole, if it did.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
    #[serde(skip)]
    at: Option<Instant>,
}

impl Sample {
    /// How long ago its read completed.
    pub fn age(&self) -> Duration {
        self.at.map_or(Duration::ZERO, |t| t.elapsed())
    }
}

/// A sample handed to a subscriber.
#[derive(Debug, Clone)]
pub struct Delivery {
    /// The sample (shared by every subscriber).
    pub sample: Arc<Sample>,
    /// Samples this subscriber lost (its queue was full) since its previous delivery.
    pub lost: u64,
}

/// Why [`Subscriber::recv_timeout`] returned no sample.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RecvError {
    /// Nothing arrived in time.
    Timeout,
    /// The stream has ended and everything queued was delivered.
    Ended,
}

#[derive(Debug)]
struct QueueState {
    buf: VecDeque<Arc<Sample>>,
    capacity: usize,
    lost_since: u64,
    lost_total: u64,
    /// What was pushed: samples (lost ones too), late ones, failed ones.
    given: StreamStats,
    ended: bool,
}

#[derive(Debug)]
struct Queue {
    state: Mutex<QueueState>,
    ready: Condvar,
}

impl Queue {
    fn new(capacity: usize) -> Self {
        Self {
            state: Mutex::new(QueueState {
                buf: VecDeque::with_capacity(capacity.min(1024)),
                capacity,
                lost_since: 0,
                lost_total: 0,
                given: StreamStats::default(),
                ended: false,
            }),
            ready: Condvar::new(),
        }
    }

    fn lock(&self) -> MutexGuard<'_, QueueState> {
        self.state
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    /// Queues `sample`, losing the oldest one when full.
    fn push(&self, sample: Arc<Sample>) {
        let mut s = self.lock();
        s.given.samples += 1;
        s.given.late += u64::from(sample.late);
        s.given.failed += u64::from(sample.error.is_some());
        if s.buf.len() >= s.capacity {
            s.buf.pop_front();
            s.lost_since += 1;
            s.lost_total += 1;
        }
        s.buf.push_back(sample);
        drop(s);
        self.ready.notify_one();
    }

    fn end(&self) {
        self.lock().ended = true;
        self.ready.notify_all();
    }
}

/// A subscriber's end of the stream (see the [module docs](self)).
#[derive(Debug)]
pub struct Subscriber {
    queue: Arc<Queue>,
}

impl Subscriber {
    /// The next sample, waiting at most `timeout`.
    pub fn recv_timeout(&self, timeout: Duration) -> Result<Delivery, RecvError> {
        let deadline = Instant::now() + timeout;
        let mut s = self.queue.lock();
        loop {
            if let Some(sample) = s.buf.pop_front() {
                let lost = std::mem::take(&mut s.lost_since);
                return Ok(Delivery { sample, lost });
            }
            if s.ended {
                return Err(RecvError::Ended);
            }
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return Err(RecvError::Timeout);
            }
            s = self
                .queue
                .ready
                .wait_timeout(s, left)
                .unwrap_or_else(std::sync::PoisonError::into_inner)
                .0;
        }
    }

    /// The next sample if one is queued.
    pub fn try_recv(&self) -> Result<Delivery, RecvError> {
        self.recv_timeout(Duration::ZERO)
    }

    /// Samples queued now (at most the queue's capacity).
    pub fn queued(&self) -> usize {
        self.queue.lock().buf.len()
    }

    /// Samples this subscriber lost so far.
    pub fn lost(&self) -> u64 {
        self.queue.lock().lost_total
    }

    /// What this subscriber was given so far: samples (those it lost too), of them late
    /// ones and reads that failed as a whole.
    pub fn stats(&self) -> StreamStats {
        self.queue.lock().given
    }
}

/// Every sample until the stream ends.
impl Iterator for Subscriber {
    type Item = Delivery;

    fn next(&mut self) -> Option<Delivery> {
        loop {
            match self.recv_timeout(Duration::from_secs(1)) {
                Ok(d) => return Some(d),
                Err(RecvError::Ended) => return None,
                Err(RecvError::Timeout) => {}
            }
        }
    }
}

#[derive(Debug, Default)]
struct Hub {
    subscribers: Mutex<(Vec<Weak<Queue>>, bool)>,
}

impl Hub {
    fn lock(&self) -> MutexGuard<'_, (Vec<Weak<Queue>>, bool)> {
        self.subscribers
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    fn publish(&self, sample: &Arc<Sample>) {
        let mut subs = self.lock();
        subs.0.retain(|w| w.strong_count() > 0);
        for q in subs.0.iter().filter_map(Weak::upgrade) {
            q.push(Arc::clone(sample));
        }
    }

    fn end(&self) {
        let mut subs = self.lock();
        subs.1 = true;
        for q in subs.0.iter().filter_map(Weak::upgrade) {
            q.lock().ended = true;
            q.ready.notify_all();
        }
    }
}

/// What a stream did, when it is stopped.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct StreamStats {
    /// Samples taken.
    pub samples: u64,
    /// Of them, late ones.
    pub late: u64,
    /// Of them, reads that failed as a whole.
    pub failed: u64,
}

/// A running telemetry stream (see the [module docs](self)).
#[derive(Debug)]
pub struct Telemetry {
    hub: Arc<Hub>,
    stop: StopToken,
    thread: Option<JoinHandle<StreamStats>>,
    request: Request,
    go: Mutex<Option<std::sync::mpsc::SyncSender<()>>>,
}

impl Telemetry {
    /// Starts sampling `request` on `station` at `rate_hz` ([`RATE_HZ`]), `limit` samples at
    /// most (`None`: until stopped). Only reading requests are streamed (`wck.sample`,
    /// `wck.status`, `whj.sample`, `whj.status`, `robot.sample`); anything else, a rate out of range or a
    /// request that does not validate is refused before the first read.
    pub fn start(
        station: &Arc<Station>,
        request: Request,
        rate_hz: f64,
        limit: Option<u64>,
    ) -> Result<Self, OpError> {
        let t = Self::paused(station, request, rate_hz, limit)?;
        t.resume();
        Ok(t)
    }

    /// [`Telemetry::start`] without taking a sample until [`Telemetry::resume`]: so
    /// subscribers made in between get every sample from the first.
    pub fn paused(
        station: &Arc<Station>,
        request: Request,
        rate_hz: f64,
        limit: Option<u64>,
    ) -> Result<Self, OpError> {
        let reading = check_stream(station, &request, rate_hz)?;
        let devices = devices_of(&request)?.unwrap_or_default();
        let hub = Arc::new(Hub::default());
        let stop = StopToken::new();
        let (go, gate) = std::sync::mpsc::sync_channel::<()>(1);
        let period = Duration::from_secs_f64(1.0 / rate_hz);
        let thread = {
            let (hub, stop, station) = (Arc::clone(&hub), stop.clone(), Arc::clone(station));
            let broadcast = matches!(&request, Request::WhjSample(r) if r.broadcast);
            std::thread::Builder::new()
                .name("robobus-telemetry".into())
                .spawn(move || {
                    // Until resumed (or the stream is dropped unresumed).
                    if gate.recv().is_err() {
                        hub.end();
                        return StreamStats::default();
                    }
                    let taking = Taking {
                        station: &station,
                        reading: &reading,
                        devices: &devices,
                        broadcast,
                    };
                    sample_loop(&hub, &stop, &taking, period, limit)
                })
                .map_err(|e| OpError::Device(format!("starting the telemetry thread: {e}")))?
        };
        Ok(Self {
            hub,
            stop,
            thread: Some(thread),
            request,
            go: Mutex::new(Some(go)),
        })
    }

    /// A new subscriber with room for `capacity` samples (1..=[`MAX_QUEUE`]); it gets
    /// every sample taken from now on.
    pub fn subscribe(&self, capacity: usize) -> Result<Subscriber, OpError> {
        check_capacity(capacity)?;
        let queue = Arc::new(Queue::new(capacity));
        let mut subs = self.hub.lock();
        queue.lock().ended = subs.1;
        subs.0.push(Arc::downgrade(&queue));
        Ok(Subscriber { queue })
    }

    /// Starts a [`Telemetry::paused`] stream (nothing if it runs already).
    pub fn resume(&self) {
        let go = self
            .go
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .take();
        if let Some(go) = go {
            let _ = go.send(());
        }
    }

    /// The request it samples.
    pub const fn request(&self) -> &Request {
        &self.request
    }

    /// Stops sampling (the read under way completes) and returns what the stream did.
    pub fn stop(mut self) -> StreamStats {
        self.finish()
    }

    /// Waits until the stream has taken its `limit` of samples (or was stopped); resumes
    /// a paused one first.
    pub fn join(mut self) -> StreamStats {
        self.resume();
        self.thread
            .take()
            .and_then(|t| t.join().ok())
            .unwrap_or_default()
    }

    fn finish(&mut self) -> StreamStats {
        self.stop.stop();
        // An unresumed stream ends without a sample.
        self.go
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .take();
        self.thread
            .take()
            .and_then(|t| t.join().ok())
            .unwrap_or_default()
    }
}

impl Drop for Telemetry {
    fn drop(&mut self) {
        self.finish();
    }
}

/// One read of a stream's devices, timed and checked, as a sample (its `seq` 0).
fn take_sample(
    taking: &Taking<'_>,
    stop: &StopToken,
    speeds: Option<&mut Speeds>,
    late: bool,
    stats: &mut StreamStats,
) -> Sample {
    let start = Instant::now();
    let (outcome, sampled_by) = taking.take(&mut Control::new(stop));
    let done = Instant::now();
    let unix_ms = SystemTime::now()
        .duration_since(SystemTime::UNIX_EPOCH)
        .map_or(0.0, |d| d.as_secs_f64() * 1e3);
    let (report, failed, error) = match outcome {
        Ok(mut r) => {
            if let Some(speeds) = speeds {
                speeds.fill(&mut r, done);
            }
            (Some(r), None, None)
        }
        Err(e) => {
            stats.failed += 1;
            (None, Some(kind_name(e.kind())), Some(e.to_string()))
        }
    };
    stats.samples += 1;
    stats.late += u64::from(late);
    Sample {
        seq: 0,
        unix_ms,
        read_ms: done.saturating_duration_since(start).as_secs_f64() * 1e3,
        late,
        report,
        sampled_by,
        failed,
        error,
        at: Some(done),
    }
}

fn sample_loop(
    hub: &Hub,
    stop: &StopToken,
    taking: &Taking<'_>,
    period: Duration,
    limit: Option<u64>,
) -> StreamStats {
    let mut stats = StreamStats::default();
    let mut speeds = matches!(taking.reading, Reading::Wck { .. }).then(Speeds::default);
    let mut slot = Instant::now();
    while !stop.is_stopped() && limit.is_none_or(|n| stats.samples < n) {
        let late = Instant::now().saturating_duration_since(slot) > period;
        let seq = stats.samples;
        let sample = take_sample(taking, stop, speeds.as_mut(), late, &mut stats);
        let sample = Arc::new(Sample { seq, ..sample });
        hub.publish(&sample);
        slot += period;
        if late {
            // Behind: start again from now rather than bursting to catch up.
            slot = Instant::now().max(slot);
        }
        if !stop.sleep_until(slot) {
            break;
        }
    }
    hub.end();
    stats
}

fn check_capacity(capacity: usize) -> Result<(), OpError> {
    if (1..=MAX_QUEUE).contains(&capacity) {
        Ok(())
    } else {
        Err(OpError::invalid(
            "capacity",
            capacity,
            format!("out of range (allowed: 1..={MAX_QUEUE} samples)"),
        ))
    }
}

/// Refuses what cannot be streamed (not a reading request, a rate out of range, a request
/// that does not validate, a bus the station does not have); what the stream reads.
fn check_stream(station: &Station, request: &Request, rate_hz: f64) -> Result<Reading, OpError> {
    if !matches!(
        request,
        Request::WckSample(_)
            | Request::WckStatus(_)
            | Request::WhjSample(_)
            | Request::WhjStatus(_)
            | Request::WhjCanHealth(_)
            | Request::RobotSample(_)
    ) {
        return Err(OpError::invalid(
            "request",
            request.op(),
            "a telemetry stream takes a reading request only (wck.sample, wck.status, \
             whj.sample, whj.status, whj.can-health, robot.sample)",
        ));
    }
    if !(rate_hz.is_finite() && RATE_HZ.contains(&rate_hz)) {
        return Err(OpError::invalid(
            "rate_hz",
            rate_hz,
            format!(
                "out of range (allowed: {}..={} Hz)",
                RATE_HZ.start(),
                RATE_HZ.end()
            ),
        ));
    }
    super::validate(request)?;
    // The bus it names must be there now, not at the first read.
    match request.family() {
        super::Family::Wck => {
            let port = station.wck(request.bus())?;
            if matches!(request, Request::WckSample(_)) {
                return Ok(Reading::Wck {
                    bus: port.name().to_owned(),
                });
            }
        }
        super::Family::Whj => {
            let port = station.whj(request.bus())?;
            if matches!(request, Request::WhjSample(_)) {
                return Ok(Reading::Whj {
                    bus: port.name().to_owned(),
                });
            }
        }
        // Not a reading request: refused above.
        super::Family::Host => {}
        super::Family::Robot => {
            if station.robot().is_none() {
                return Err(OpError::invalid(
                    "robot",
                    "(none)",
                    "the station has no robot file (open it with --robot FILE.toml)",
                ));
            }
        }
    }
    Ok(Reading::Whole(request.clone()))
}

/// The devices a `whj.sample` / `wck.sample` names (`None`: another request, read whole).
fn devices_of(request: &Request) -> Result<Option<BTreeSet<u64>>, OpError> {
    Ok(match request {
        Request::WhjSample(r) => Some(
            r.joints
                .parse_sorted::<robobus_whj::JointId>("joints")?
                .iter()
                .map(|j| u64::from(j.get()))
                .collect(),
        ),
        Request::WckSample(r) => Some(
            r.ids
                .parse::<robobus_wck::ServoId>("ids")?
                .iter()
                .map(|j| u64::from(j.get()))
                .collect(),
        ),
        _ => None,
    })
}

/// What a stream reads.
#[derive(Debug, Clone)]
enum Reading {
    /// `whj.sample` on this WHJ bus: the joints asked.
    Whj { bus: String },
    /// `wck.sample` on this wCK port: the servos asked.
    Wck { bus: String },
    /// Any other reading request, as it is.
    Whole(Request),
}

impl Reading {
    /// The key of its shared sampling in the station.
    fn key(&self) -> String {
        match self {
            Self::Whj { bus } => format!("whj.sample\u{0}{bus}"),
            Self::Wck { bus } => format!("wck.sample\u{0}{bus}"),
            Self::Whole(r) => format!("{r:?}"),
        }
    }
}

/// One read of a stream: what, of which devices, on which station.
struct Taking<'a> {
    station: &'a Station,
    reading: &'a Reading,
    devices: &'a BTreeSet<u64>,
    broadcast: bool,
}

impl Taking<'_> {
    fn take(&self, control: &mut Control<'_>) -> (Result<Report, OpError>, Option<SampledBy>) {
        match self.reading {
            Reading::Whj { bus } => {
                let ids: Vec<robobus_whj::JointId> = self
                    .devices
                    .iter()
                    .filter_map(|&d| u8::try_from(d).ok())
                    .filter_map(|d| robobus_whj::JointId::new(d).ok())
                    .collect();
                let port = match self.station.whj(Some(bus)) {
                    Ok(p) => p,
                    Err(e) => return (Err(e), None),
                };
                // Joints this bus has not connected yet are connected first (together; a
                // silent one shows in its rows), once per station.
                let _ = port.bus().joints(&port.untried(&ids));
                match sample_whj(port.bus(), &ids, self.broadcast) {
                    Ok((rows, by)) => (
                        Ok(
                            super::operation::Report::devices("whj.sample", port.name(), rows)
                                .erase(),
                        ),
                        Some(by),
                    ),
                    Err(e) => (Err(e), None),
                }
            }
            Reading::Wck { bus } => {
                let ids: Vec<String> = self.devices.iter().map(u64::to_string).collect();
                let request = Request::WckSample(super::wck::Sample {
                    bus: Some(bus.clone()),
                    ids: ids.join(",").as_str().into(),
                });
                (
                    super::run(self.station, &request, control),
                    Some(SampledBy::StatusReads),
                )
            }
            Reading::Whole(request) => (super::run(self.station, request, control), None),
        }
    }
}

/// Each servo's previous reading in a `wck.sample` stream, for its speed.
#[derive(Debug, Default)]
struct Speeds {
    last: std::collections::HashMap<u64, (Instant, f64)>,
}

impl Speeds {
    /// Fills each answered row's `speed_deg_s` from its previous reading.
    fn fill(&mut self, report: &mut Report, at: Instant) {
        for row in &mut report.results {
            let (Some(id), Some(deg)) = (row["id"].as_u64(), row["position_deg"].as_f64()) else {
                continue;
            };
            if let Some((t0, d0)) = self.last.insert(id, (at, deg)) {
                let dt = at.saturating_duration_since(t0).as_secs_f64();
                if dt > 0.0 && row["speed_deg_s"].is_null() {
                    row["speed_deg_s"] = serde_json::json!((deg - d0) / dt);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn report(rows: &serde_json::Value) -> Report {
        Report::with_rows(
            "wck.sample",
            "legs",
            rows.as_array().cloned().unwrap_or_default(),
        )
    }

    #[test]
    fn a_servos_speed_is_its_change_since_its_previous_reading() {
        let mut speeds = Speeds::default();
        let t0 = Instant::now();
        let mut first = report(&serde_json::json!([
            {"id": 1, "position_deg": 10.0, "speed_deg_s": null},
            {"id": 2, "kind": "no-device", "error": "silent"},
        ]));
        speeds.fill(&mut first, t0);
        assert!(first.results[0]["speed_deg_s"].is_null());
        // Half a second later servo 1 is 10 degrees on; servo 2 answers for the first time.
        let mut second = report(&serde_json::json!([
            {"id": 1, "position_deg": 20.0, "speed_deg_s": null},
            {"id": 2, "position_deg": 5.0, "speed_deg_s": null},
        ]));
        speeds.fill(&mut second, t0 + Duration::from_millis(500));
        assert_eq!(second.results[0]["speed_deg_s"].as_f64(), Some(20.0));
        assert!(second.results[1]["speed_deg_s"].is_null());
        // A silent reading keeps the last one it had: the next speed spans the gap.
        let mut third = report(&serde_json::json!([
            {"id": 1, "kind": "no-device", "error": "silent"},
            {"id": 2, "position_deg": 4.0, "speed_deg_s": null},
        ]));
        speeds.fill(&mut third, t0 + Duration::from_secs(1));
        assert_eq!(third.results[1]["speed_deg_s"].as_f64(), Some(-2.0));
        let mut fourth = report(&serde_json::json!([
            {"id": 1, "position_deg": 30.0, "speed_deg_s": null},
        ]));
        speeds.fill(&mut fourth, t0 + Duration::from_millis(1500));
        assert_eq!(fourth.results[0]["speed_deg_s"].as_f64(), Some(10.0));
    }
}
