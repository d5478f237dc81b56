//! The telemetry stream's fan-out: one sampler, many subscribers, one of them never
//! reading. The bus must keep its rate however many subscribers there are, the readers
//! must lose nothing, and the idle subscriber's queue must stay at its capacity (memory
//! bounded) while it is told how many samples it lost.

use std::sync::Arc;
use std::thread;
use std::time::{Duration, Instant};

use robobus::catalogue::{Request, Telemetry, whj};
use robobus::station::Station;

use crate::BenchError;

/// Queue of every subscriber, samples.
pub const QUEUE: usize = 64;

/// One run of the stream.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FanOut {
    /// Requested rate, Hz.
    pub rate_hz: f64,
    /// Subscribers, the idle one included.
    pub subscribers: usize,
    /// How long it ran.
    pub wall: Duration,
    /// Samples taken.
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
}

impl FanOut {
    /// Samples per second.
    pub fn rate(&self) -> f64 {
        #[allow(clippy::cast_precision_loss)] // counts far below 2^52
        let n = self.samples as f64;
        n / self.wall.as_secs_f64().max(1e-9)
    }
}

/// Streams `whj.sample` of the built-in simulated robot's 7 joints at `rate_hz` for
/// `secs` to `subscribers` subscribers: with more than one, one of them never reads.
pub fn fan_out(rate_hz: f64, subscribers: usize, secs: Duration) -> Result<FanOut, BenchError> {
    let station = Arc::new(
        Station::simulated().map_err(|e| BenchError::msg(format!("simulated station: {e}")))?,
    );
    let request = Request::WhjSample(whj::Sample {
        bus: Some("sim-whj".into()),
        joints: "1-7".into(),
        broadcast: false,
    });
    let t = Telemetry::paused(&station, request, rate_hz, None)
        .map_err(|e| BenchError::msg(format!("telemetry: {e}")))?;
    let readers = subscribers
        .saturating_sub(usize::from(subscribers > 1))
        .max(1);
    let mut handles = Vec::new();
    for _ in 0..readers {
        let sub = t
            .subscribe(QUEUE)
            .map_err(|e| BenchError::msg(format!("subscribe: {e}")))?;
        handles.push(thread::spawn(move || {
            let mut got = 0u64;
            while let Ok(_delivery) = sub.recv_timeout(Duration::from_secs(5)) {
                got += 1;
            }
            (got, sub.lost())
        }));
    }
    let idle = if subscribers > 1 {
        Some(
            t.subscribe(QUEUE)
                .map_err(|e| BenchError::msg(format!("subscribe: {e}")))?,
        )
    } else {
        None
    };
    let start = Instant::now();
    t.resume();
    thread::sleep(secs);
    let stats = t.stop();
    let wall = start.elapsed();
    let mut lost_by_readers = 0;
    let mut min_received = u64::MAX;
    for h in handles {
        let (got, lost) = h
            .join()
            .map_err(|_| BenchError::msg("a subscriber thread panicked"))?;
        lost_by_readers += lost;
        min_received = min_received.min(got);
    }
    Ok(FanOut {
        rate_hz,
        subscribers,
        wall,
        samples: stats.samples,
        late: stats.late,
        lost_by_readers,
        min_received,
        idle_queued: idle
            .as_ref()
            .map_or(0, robobus::catalogue::Subscriber::queued),
        idle_lost: idle
            .as_ref()
            .map_or(0, robobus::catalogue::Subscriber::lost),
    })
}
