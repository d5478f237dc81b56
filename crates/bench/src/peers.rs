//! The Python peers (`scripts/bench/*.py`): what a user would write instead of using
//! robobus. Each prints one JSON line with its counts and its own CPU time.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

use crate::BenchError;
use crate::wck::PollSpec;

/// What a peer reported.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PeerResult {
    /// Complete cycles.
    pub cycles: u64,
    /// Wall time of the measured cycles.
    pub elapsed: Duration,
    /// CPU time of the Python process over the measured cycles.
    pub cpu: Duration,
    /// Transactions without a (complete, correct) reply.
    pub errors: u64,
}

impl PeerResult {
    /// Cycles per second.
    pub fn rate_hz(&self) -> f64 {
        self.cycles as f64 / self.elapsed.as_secs_f64().max(1e-9)
    }

    /// CPU per cycle, µs.
    pub fn cpu_per_cycle_us(&self) -> f64 {
        self.cpu.as_secs_f64() * 1e6 / self.cycles.max(1) as f64
    }
}

/// Where the peer scripts live (`<workspace>/scripts/bench`).
pub fn script_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scripts/bench")
}

fn run(python: &Path, script: &str, args: &[String]) -> Result<PeerResult, BenchError> {
    let path = script_dir().join(script);
    let out = Command::new(python)
        .arg(&path)
        .args(args)
        .output()
        .map_err(|e| BenchError::new(format!("running {}", path.display()), e))?;
    let stdout = String::from_utf8_lossy(&out.stdout);
    if !out.status.success() {
        return Err(BenchError::msg(format!(
            "{script} failed ({}): {}{}",
            out.status,
            stdout,
            String::from_utf8_lossy(&out.stderr)
        )));
    }
    let line = stdout
        .lines()
        .rev()
        .find(|l| l.starts_with('{'))
        .ok_or_else(|| BenchError::msg(format!("{script} printed no result: {stdout}")))?;
    let v: serde_json::Value = serde_json::from_str(line)
        .map_err(|e| BenchError::new(format!("{script} result {line}"), e))?;
    let num = |k: &str| v.get(k).and_then(serde_json::Value::as_f64).unwrap_or(0.0);
    #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)] // counts
    Ok(PeerResult {
        cycles: num("cycles") as u64,
        elapsed: Duration::from_secs_f64(num("elapsed").max(0.0)),
        cpu: Duration::from_secs_f64(num("cpu").max(0.0)),
        errors: num("errors") as u64,
    })
}

/// pyserial polling `spec.servos` servos over the pty at `path` for `duration`.
pub fn wck_poll(
    python: &Path,
    path: &Path,
    spec: PollSpec,
    duration: Duration,
) -> Result<PeerResult, BenchError> {
    run(
        python,
        "wck_poll_peer.py",
        &[
            "--port".into(),
            path.display().to_string(),
            "--baud".into(),
            spec.baud.bits_per_second().to_string(),
            "--servos".into(),
            spec.servos.to_string(),
            "--seconds".into(),
            format!("{:.3}", duration.as_secs_f64()),
        ],
    )
}

/// python-can position servo cycle over `joints` joints (1..=joints) on the UDP multicast
/// bus (python-can's default group and port) for `duration`.
pub fn whj_servo(python: &Path, joints: u8, duration: Duration) -> Result<PeerResult, BenchError> {
    run(
        python,
        "whj_servo_peer.py",
        &[
            "--joints".into(),
            joints.to_string(),
            "--seconds".into(),
            format!("{:.3}", duration.as_secs_f64()),
        ],
    )
}
