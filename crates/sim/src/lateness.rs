//! How late a simulator on the wall clock released what it sent: each reply byte or
//! frame against the instant the model says it leaves the wire. A benchmark that measures
//! a client against a simulator shows these figures beside its own, so that a result
//! spoiled by a late simulator is visible as such.

use core::time::Duration;

/// Resolution of the record: one bucket per microsecond.
const BUCKET: Duration = Duration::from_micros(1);

/// Buckets kept: lateness up to 20 ms is recorded to the microsecond, beyond that only
/// counted (and the largest kept).
const BUCKETS: usize = 20_000;

/// A bounded record of release lateness (fixed memory: one counter per microsecond up to
/// 20 ms).
#[derive(Debug, Clone)]
pub struct Lateness {
    counts: Vec<u32>,
    beyond: u64,
    total: u64,
    max: Duration,
}

impl Default for Lateness {
    fn default() -> Self {
        Self::new()
    }
}

impl Lateness {
    /// An empty record.
    pub fn new() -> Self {
        Self {
            counts: vec![0; BUCKETS],
            beyond: 0,
            total: 0,
            max: Duration::ZERO,
        }
    }

    /// One release, `late` after its modelled instant.
    pub fn record(&mut self, late: Duration) {
        self.total += 1;
        self.max = self.max.max(late);
        let i = usize::try_from(late.as_nanos() / BUCKET.as_nanos()).unwrap_or(usize::MAX);
        match self.counts.get_mut(i) {
            Some(c) => *c = c.saturating_add(1),
            None => self.beyond += 1,
        }
    }

    /// The lateness that a share `q` (0..=1) of the releases did not exceed, to the
    /// microsecond (rounded up); `None` with no release, or beyond the recorded range.
    pub fn quantile(&self, q: f64) -> Option<Duration> {
        if self.total == 0 {
            return None;
        }
        #[allow(
            clippy::cast_possible_truncation,
            clippy::cast_sign_loss,
            clippy::cast_precision_loss
        )]
        let rank = ((q.clamp(0.0, 1.0) * self.total as f64).ceil() as u64).max(1);
        let mut seen = 0u64;
        for (i, c) in self.counts.iter().enumerate() {
            seen += u64::from(*c);
            if seen >= rank {
                let i = u32::try_from(i + 1).unwrap_or(u32::MAX);
                return Some((BUCKET * i).min(self.max));
            }
        }
        None
    }

    /// The summary: count, p50, p99, max.
    pub fn summary(&self) -> LatenessSummary {
        LatenessSummary {
            releases: self.total,
            p50: self.quantile(0.5),
            p99: self.quantile(0.99),
            max: self.max,
        }
    }
}

/// Release lateness in brief (see [`Lateness`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct LatenessSummary {
    /// Releases recorded (reply bytes or frames).
    pub releases: u64,
    /// Median lateness (`None` with no release, or above 20 ms).
    pub p50: Option<Duration>,
    /// 99th percentile.
    pub p99: Option<Duration>,
    /// Largest.
    pub max: Duration,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantiles_are_read_to_the_microsecond_and_bounded_by_the_largest() {
        let us = Duration::from_micros;
        let mut l = Lateness::new();
        assert_eq!(l.summary(), LatenessSummary::default());
        for i in 0..100u64 {
            l.record(Duration::from_nanos(i * 1000 + 300));
        }
        let s = l.summary();
        assert_eq!(
            (s.releases, s.p50, s.p99),
            (100, Some(us(50)), Some(us(99)))
        );
        assert_eq!(s.max, Duration::from_nanos(99_300));
        // One very late release: counted, the median unchanged, the p100 unknown.
        l.record(Duration::from_millis(30));
        assert_eq!(l.summary().max, Duration::from_millis(30));
        assert_eq!(l.quantile(0.5), Some(us(51)));
        assert_eq!(l.quantile(1.0), None);
    }
}
