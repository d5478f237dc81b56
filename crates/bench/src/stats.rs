//! Latency summaries (nearest-rank percentiles).

use std::time::Duration;

/// Percentiles of a set of latency samples, in microseconds.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Summary {
    /// Number of samples.
    pub n: usize,
    /// Arithmetic mean.
    pub mean: f64,
    /// Smallest.
    pub min: f64,
    /// Median.
    pub p50: f64,
    /// 99th percentile.
    pub p99: f64,
    /// 99.9th percentile.
    pub p999: f64,
    /// Largest.
    pub max: f64,
}

/// Nearest-rank percentile `q` (0..=1) of sorted `s`; 0 for no samples.
pub fn percentile(sorted: &[f64], q: f64) -> f64 {
    if sorted.is_empty() {
        return 0.0;
    }
    #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)] // 1..=len
    let rank = ((q * sorted.len() as f64).ceil() as usize).clamp(1, sorted.len());
    sorted.get(rank - 1).copied().unwrap_or(0.0)
}

impl Summary {
    /// Summary of samples given in microseconds.
    pub fn of_us(samples: &[f64]) -> Self {
        let mut s: Vec<f64> = samples.iter().copied().filter(|x| x.is_finite()).collect();
        s.sort_by(f64::total_cmp);
        if s.is_empty() {
            return Self::default();
        }
        Self {
            n: s.len(),
            mean: s.iter().sum::<f64>() / s.len() as f64,
            min: s.first().copied().unwrap_or(0.0),
            p50: percentile(&s, 0.5),
            p99: percentile(&s, 0.99),
            p999: percentile(&s, 0.999),
            max: s.last().copied().unwrap_or(0.0),
        }
    }

    /// Summary of durations.
    pub fn of(samples: &[Duration]) -> Self {
        let us: Vec<f64> = samples.iter().map(|d| d.as_secs_f64() * 1e6).collect();
        Self::of_us(&us)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nearest_rank_percentiles() {
        let v: Vec<f64> = (1..=1000).map(f64::from).collect();
        let s = Summary::of_us(&v);
        assert_eq!(s.n, 1000);
        assert!((s.p50 - 500.0).abs() < 1e-9);
        assert!((s.p99 - 990.0).abs() < 1e-9);
        assert!((s.p999 - 999.0).abs() < 1e-9);
        assert!((s.max - 1000.0).abs() < 1e-9);
        assert!((s.mean - 500.5).abs() < 1e-9);
        assert_eq!(Summary::of_us(&[]).n, 0);
    }
}
