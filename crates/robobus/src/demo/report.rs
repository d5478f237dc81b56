//! What the demo reports: the document `robobus demo --json` prints, and the trace it
//! plots.

use std::time::Duration;

use serde::Serialize;

use super::{JOINTS, TRACED, WCK_PLOTTED, us};
use crate::whj::{CyclicStats, Percentiles};

/// What the demo did: the document `robobus demo --json` prints.
#[derive(Debug, Clone, Serialize)]
pub struct DemoReport {
    /// Wall time of the whole run, s.
    pub wall_s: f64,
    /// The wCK humanoid.
    pub wck: WckReport,
    /// The WHJ arm.
    pub whj: WhjReport,
    /// The plot file, when the front end wrote one (set by the caller).
    pub plot: Option<String>,
    /// What did not go as it should (a pose that did not settle, an error bit latched).
    pub errors: Vec<String>,
    /// Positions over time, for a plot (not serialized).
    #[serde(skip)]
    pub trace: Trace,
}

/// One keyframe's outcome.
#[derive(Debug, Clone, Serialize)]
pub struct PoseReport {
    /// The keyframe's name.
    pub name: &'static str,
    /// How long the pose was played (its transition and hold), ms, when every servo then
    /// stood within one step of it (`None`: one did not).
    pub settled_ms: Option<f64>,
    /// The largest distance from the target at the end, steps.
    pub worst_error_steps: u8,
}

/// What the wCK part did.
#[derive(Debug, Clone, Serialize)]
pub struct WckReport {
    /// Servos the scan found.
    pub servos_found: usize,
    /// Their IDs.
    pub ids: Vec<u8>,
    /// Bus rate, bit/s.
    pub baud: u32,
    /// Scan time, ms.
    pub scan_ms: f64,
    /// The keyframes.
    pub poses: Vec<PoseReport>,
    /// Status reads while the poses played (the play's watch reads and each pose's check).
    pub status_polls: u64,
    /// Transactions (attempts) of the client.
    pub transactions: u64,
    /// Retries.
    pub retries: u64,
    /// Timeouts.
    pub timeouts: u64,
    /// Implausible replies.
    pub bad_replies: u64,
    /// Bytes the host sent.
    pub bytes_out: u64,
    /// Bytes the servos sent.
    pub bytes_in: u64,
    /// Wire time of all bytes / run time.
    pub wire_utilisation: f64,
    /// Status polls of all servos per second the wire allows.
    pub status_poll_limit_hz: f64,
}

/// One joint's identity.
#[derive(Debug, Clone, Serialize)]
pub struct JointIdentity {
    /// Joint ID.
    pub id: u8,
    /// Model name.
    pub model: String,
    /// Firmware version.
    pub firmware: String,
}

/// One joint's tracking of the sine.
#[derive(Debug, Clone, Serialize)]
pub struct JointTracking {
    /// Joint ID.
    pub joint: u8,
    /// RMS of feedback − previous set-point, degrees.
    pub rms_deg: f64,
    /// Largest such error, degrees.
    pub max_deg: f64,
    /// Samples compared.
    pub samples: u64,
    /// Error bits read after the run.
    pub error: String,
    /// No error bit latched after the run.
    pub error_free: bool,
}

/// Latency percentiles, µs.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct LatencyUs {
    /// Number of samples.
    pub samples: usize,
    /// Median.
    pub p50: f64,
    /// 90th percentile.
    pub p90: f64,
    /// 99th percentile.
    pub p99: f64,
    /// Largest.
    pub max: f64,
}

impl From<&Percentiles> for LatencyUs {
    fn from(p: &Percentiles) -> Self {
        Self {
            samples: p.samples,
            p50: us(p.p50),
            p90: us(p.p90),
            p99: us(p.p99),
            max: us(p.max),
        }
    }
}

/// What the WHJ part did.
#[derive(Debug, Clone, Serialize)]
pub struct WhjReport {
    /// Joints connected.
    pub joints: usize,
    /// Their identities.
    pub identities: Vec<JointIdentity>,
    /// Sine run, s.
    pub seconds: f64,
    /// Loop rate, Hz.
    pub rate_hz: f64,
    /// Cycles run.
    pub cycles: u64,
    /// Cycles with every joint's feedback in time.
    pub complete: u64,
    /// Cycles that missed their deadline.
    pub deadline_misses: u64,
    /// Feedback frames that never came.
    pub missing_replies: u64,
    /// Feedback frames that came after their cycle.
    pub late_replies: u64,
    /// Cycles that started after the next one was due.
    pub overruns: u64,
    /// Frames the link refused.
    pub send_errors: u64,
    /// Command → feedback round trip.
    pub round_trip_us: LatencyUs,
    /// How late cycles started.
    pub start_lateness_us: LatencyUs,
    /// Each joint's tracking.
    pub tracking: Vec<JointTracking>,
    /// The worst joint's RMS tracking error, degrees.
    pub tracking_rms_deg: f64,
    /// The worst joint's largest tracking error, degrees.
    pub tracking_max_deg: f64,
    /// Wire time of one cycle's frames, µs.
    pub cycle_wire_us: f64,
    /// Cycle wire time / period.
    pub wire_utilisation: f64,
    /// Cycles per second the wire allows.
    pub wire_limit_hz: f64,
    /// Frames the simulator received.
    pub simulator_frames_in: u64,
    /// Frames the simulator sent.
    pub simulator_frames_out: u64,
    /// The loop's own statistics.
    #[serde(skip)]
    pub stats: CyclicStats,
    /// Wire time of one cycle.
    #[serde(skip)]
    pub cycle_wire: Duration,
}

/// Positions over time: (seconds of simulated time since the start, signal, degrees).
/// Signals are the plotted wCK servos (where the scan and each pose's check found them),
/// then the WHJ joints (every tenth cycle's feedback), then the targets of both in the
/// same order (every move the keyframes' play sent, the set-points the loop sent)
/// ([`Trace::names`]).
#[derive(Debug, Clone, Default)]
pub struct Trace(pub Vec<(f64, usize, f64)>);

impl Trace {
    pub(super) fn push(&mut self, t: f64, col: usize, v: f64) {
        self.0.push((t, col, v));
    }

    /// The signal names: `wck0_deg`, ..., `whj1_deg`, ..., then the targets:
    /// `wck0_target_deg`, ..., `whj1_target_deg`, ...
    pub fn names() -> Vec<String> {
        let mut names: Vec<String> = WCK_PLOTTED
            .iter()
            .map(|id| format!("wck{id}_deg"))
            .collect();
        names.extend((1..=JOINTS).map(|j| format!("whj{j}_deg")));
        let targets: Vec<String> = names
            .iter()
            .map(|n| n.replace("_deg", "_target_deg"))
            .collect();
        names.extend(targets);
        names
    }

    /// One row per distinct time: the time and one value per signal (`None`: not sampled).
    pub fn rows(&self) -> (Vec<f64>, Vec<Vec<Option<f64>>>) {
        let columns = 2 * TRACED;
        let mut time = Vec::new();
        let mut signals: Vec<Vec<Option<f64>>> = vec![Vec::new(); columns];
        for &(t, col, v) in &self.0 {
            if time.last() != Some(&t) {
                time.push(t);
                for s in &mut signals {
                    s.push(None);
                }
            }
            if let Some(cell) = signals.get_mut(col).and_then(|s| s.last_mut()) {
                *cell = Some(v);
            }
        }
        (time, signals)
    }
}
