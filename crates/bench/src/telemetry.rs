//! The telemetry stream against the wire: `whj.sample` of the live simulated arm's 7
//! joints (1 / 5 Mbit/s wire, wall clock) through the station's one shared sampling of the
//! bus ([`Station::telemetry`]), with one subscriber and with eight (seven reading, one
//! never reading). The samples a second are compared with what the wire allows for one
//! sample (the exact frames of a sample, back to back: [`studio::wire_model`]), or with
//! the rate asked where that is lower. The bus must keep its rate however many
//! subscribers there are, the readers must lose nothing, and the idle subscriber's queue
//! must stay at its capacity (memory bounded) while it is told how many samples it lost.

use std::sync::OnceLock;
use std::thread;
use std::time::{Duration, Instant};

use robobus::catalogue::telemetry::{StreamStats, Subscription};
use robobus::catalogue::{Request, whj};
use robobus::station::Station;

use crate::{BenchError, studio};

/// Queue of every subscriber, samples.
pub const QUEUE: usize = 64;

/// One run of the stream.
#[derive(Debug, Clone, PartialEq)]
pub struct FanOut {
    /// Requested rate, Hz.
    pub rate_hz: f64,
    /// Subscribers, the idle one included.
    pub subscribers: usize,
    /// How long it ran.
    pub wall: Duration,
    /// Samples taken (by the one sampling of the bus).
    pub samples: u64,
    /// Of them, late (read started more than a period after its slot).
    pub late: u64,
    /// Samples the reading subscribers lost, all together.
    pub lost_by_readers: u64,
    /// Samples a reading subscriber received, the fewest of any.
    pub min_received: u64,
    /// The idle subscriber's queue at the end (at most [`QUEUE`]).
    pub idle_queued: usize,
    /// Samples the idle subscriber lost.
    pub idle_lost: u64,
    /// Samples a second the wire allows for one sample of the 7 joints.
    pub wire_hz: f64,
    /// How the samples were taken (`pipelined`, ...: the last sample's `sampled_by`).
    pub sampled_by: String,
}

impl FanOut {
    /// Samples per second.
    pub fn rate(&self) -> f64 {
        #[allow(clippy::cast_precision_loss)] // counts far below 2^52
        let n = self.samples as f64;
        n / self.wall.as_secs_f64().max(1e-9)
    }

    /// What the stream could reach: the rate asked, or the wire's if lower.
    pub fn reachable_hz(&self) -> f64 {
        self.rate_hz.min(self.wire_hz)
    }

    /// [`FanOut::rate`] over [`FanOut::reachable_hz`].
    pub fn of_reachable(&self) -> f64 {
        self.rate() / self.reachable_hz().max(1e-9)
    }
}

/// The wire's samples a second for one `whj.sample` of 7 joints, measured once.
fn wire_hz() -> Result<f64, BenchError> {
    static WIRE: OnceLock<f64> = OnceLock::new();
    if let Some(hz) = WIRE.get() {
        return Ok(*hz);
    }
    let hz = studio::wire_model()?.wire_hz();
    Ok(*WIRE.get_or_init(|| hz))
}

/// What one reader did.
struct Read {
    got: u64,
    lost: u64,
    stats: Option<StreamStats>,
    sampled_by: Option<String>,
}

/// Reads `sub` until `until`, then leaves.
fn read(mut sub: Subscription, until: Instant) -> Read {
    let mut got = 0u64;
    let mut sampled_by = None;
    while Instant::now() < until {
        if let Ok(d) = sub.recv_timeout(Duration::from_millis(50)) {
            got += 1;
            sampled_by = d.sample.sampled_by.map(|b| b.name().to_owned());
        }
    }
    let lost = sub.lost();
    let stats = sub.close();
    Read {
        got,
        lost,
        stats,
        sampled_by,
    }
}

/// Streams `whj.sample` of the live simulated arm's 7 joints at `rate_hz` for `secs` to
/// `subscribers` subscribers of the bus's one sampling: with more than one, one of them
/// never reads.
pub fn fan_out(rate_hz: f64, subscribers: usize, secs: Duration) -> Result<FanOut, BenchError> {
    let wire_hz = wire_hz()?;
    let (station, live) = Station::simulated_live(None)
        .map_err(|e| BenchError::msg(format!("simulated station: {e}")))?;
    let station = std::sync::Arc::new(station);
    let request = Request::WhjSample(whj::Sample {
        bus: Some("sim-whj".into()),
        joints: "1-7".into(),
        broadcast: false,
    });
    // The first sample connects the joints (identities, limits): not part of the run.
    robobus::catalogue::run(&station, &request, &mut robobus::ops::Control::none())
        .map_err(|e| BenchError::msg(format!("whj.sample: {e}")))?;
    let readers = subscribers
        .saturating_sub(usize::from(subscribers > 1))
        .max(1);
    let start = Instant::now();
    let until = start + secs;
    let mut handles = Vec::new();
    for _ in 0..readers {
        let sub = station
            .telemetry(request.clone(), rate_hz, QUEUE)
            .map_err(|e| BenchError::msg(format!("subscribe: {e}")))?;
        handles.push(thread::spawn(move || read(sub, until)));
    }
    let mut idle = if subscribers > 1 {
        Some(
            station
                .telemetry(request, rate_hz, QUEUE)
                .map_err(|e| BenchError::msg(format!("subscribe: {e}")))?,
        )
    } else {
        None
    };
    let mut reads = Vec::new();
    for h in handles {
        reads.push(
            h.join()
                .map_err(|_| BenchError::msg("a subscriber thread panicked"))?,
        );
    }
    let idle_queued = idle.as_ref().map_or(0, |s| s.queued());
    let idle_lost = idle.as_ref().map_or(0, |s| s.lost());
    let idle_stats = idle.as_mut().and_then(Subscription::close);
    let wall = start.elapsed();
    drop(idle);
    drop(live);
    let stats = reads
        .iter()
        .find_map(|r| r.stats)
        .or(idle_stats)
        .ok_or_else(|| BenchError::msg("no subscription ended the sampling"))?;
    Ok(FanOut {
        rate_hz,
        subscribers,
        wall,
        samples: stats.samples,
        late: stats.late,
        lost_by_readers: reads.iter().map(|r| r.lost).sum(),
        min_received: reads.iter().map(|r| r.got).min().unwrap_or(0),
        idle_queued,
        idle_lost,
        wire_hz,
        sampled_by: reads
            .iter()
            .find_map(|r| r.sampled_by.clone())
            .unwrap_or_else(|| "-".into()),
    })
}
