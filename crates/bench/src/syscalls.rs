//! System calls per transaction, counted with `strace -ff -ttt` on a one-case runner of
//! this program: every thread's calls between two markers that the measured loop leaves
//! in the trace ([`mark`]), divided by the transactions the loop made.
//!
//! Under `strace` every call is slow, so the loop runs slower than it does untraced;
//! the counts per transaction are what it does, the rates are not. A spinning wait polls
//! as often as it can, so its count says how long it spun, not what it needs: only the
//! sleep mode is counted. The Python peers are counted the same way (their scripts leave
//! the same markers), against a simulator this process serves untraced.

use std::collections::BTreeMap;
use std::path::Path;
use std::process::{Command, Stdio};

use robobus_link::WaitMode;
use robobus_sim::wck::Timing;
use robobus_wck::BaudRate;

use crate::BenchError;

/// Leaves a marker in a trace: a `stat` of a path that does not exist, which `strace`
/// shows with its name (costs one failed system call).
pub fn mark(name: &str) {
    let _ = std::fs::metadata(format!("/robobus-bench-mark-{name}"));
}

/// Calls by name, and their sum.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Counts {
    /// Every call.
    pub total: u64,
    /// Per call name.
    pub by_name: BTreeMap<String, u64>,
}

impl Counts {
    fn add(&mut self, name: &str) {
        self.total += 1;
        *self.by_name.entry(name.to_owned()).or_default() += 1;
    }

    /// `name: n.n` for the calls that make up at least 0.05 per transaction, most first.
    pub fn per(&self, transactions: u64) -> String {
        let t = transactions.max(1) as f64;
        let mut v: Vec<_> = self
            .by_name
            .iter()
            .map(|(k, n)| (k.as_str(), *n as f64 / t))
            .filter(|(_, x)| *x >= 0.05)
            .collect();
        v.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(b.0)));
        v.iter()
            .map(|(k, x)| format!("{k} {x:.1}"))
            .collect::<Vec<_>>()
            .join(", ")
    }
}

/// One traced case.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct SyscallCase {
    /// What ran.
    pub what: String,
    /// Transactions between the markers.
    pub transactions: u64,
    /// The calling thread (the one that ran the loop).
    pub caller: Counts,
    /// Every other thread of the traced process (a simulator thread, a bus thread).
    pub others: Counts,
}

/// Whether `strace` can be run.
pub fn strace_available() -> bool {
    Command::new("strace")
        .arg("-V")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success())
}

/// Runs `exe args` under `strace -ff -ttt` and counts each thread's calls between the
/// markers; `transactions` reads the number of transactions from the runner's output.
///
/// Errors: `strace` or the runner fails, or the markers are missing.
pub fn count(
    what: &str,
    exe: &Path,
    args: &[&str],
    transactions: impl Fn(&str) -> Option<u64>,
) -> Result<SyscallCase, BenchError> {
    let dir = std::env::temp_dir().join(format!("robobus-strace-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).map_err(|e| BenchError::new("trace directory", e))?;
    let result = count_in(what, exe, args, &dir, transactions);
    let _ = std::fs::remove_dir_all(&dir);
    result
}

fn count_in(
    what: &str,
    exe: &Path,
    args: &[&str],
    dir: &Path,
    transactions: impl Fn(&str) -> Option<u64>,
) -> Result<SyscallCase, BenchError> {
    let out = Command::new("strace")
        .args(["-ff", "-ttt", "-o"])
        .arg(dir.join("t"))
        .arg(exe)
        .args(args)
        .stdin(Stdio::null())
        .output()
        .map_err(|e| BenchError::new("running strace", e))?;
    let stdout = String::from_utf8_lossy(&out.stdout);
    if !out.status.success() {
        return Err(BenchError::msg(format!(
            "strace {what}: {} {}",
            out.status,
            String::from_utf8_lossy(&out.stderr).trim()
        )));
    }
    let n = transactions(&stdout)
        .ok_or_else(|| BenchError::msg(format!("{what}: no transaction count in {stdout:?}")))?;
    let mut traces = Vec::new();
    for entry in std::fs::read_dir(dir).map_err(|e| BenchError::new("reading traces", e))? {
        let path = entry
            .map_err(|e| BenchError::new("reading traces", e))?
            .path();
        let text =
            std::fs::read_to_string(&path).map_err(|e| BenchError::new("reading a trace", e))?;
        traces.push(text);
    }
    let window = traces
        .iter()
        .find_map(|t| window_of(t))
        .ok_or_else(|| BenchError::msg(format!("{what}: the markers are not in the trace")))?;
    let mut case = SyscallCase {
        what: what.to_owned(),
        transactions: n,
        ..SyscallCase::default()
    };
    for t in &traces {
        let counts = if window_of(t).is_some() {
            &mut case.caller
        } else {
            &mut case.others
        };
        for (at, name) in calls(t) {
            if at > window.0 && at < window.1 {
                counts.add(name);
            }
        }
    }
    Ok(case)
}

/// Each call of a trace: its time and name (`1733390000.123456 write(4, ...) = 4`).
fn calls(trace: &str) -> impl Iterator<Item = (f64, &str)> {
    trace.lines().filter_map(|l| {
        let (at, rest) = l.split_once(' ')?;
        let at: f64 = at.parse().ok()?;
        let name = rest.split('(').next()?;
        let plain = !name.is_empty()
            && name
                .chars()
                .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_');
        plain.then_some((at, name))
    })
}

/// The times of the start and end markers, if this trace has them.
fn window_of(trace: &str) -> Option<(f64, f64)> {
    let at = |mark: &str| {
        trace
            .lines()
            .find(|l| l.contains(mark))
            .and_then(|l| l.split_once(' '))
            .and_then(|(t, _)| t.parse::<f64>().ok())
    };
    Some((
        at("/robobus-bench-mark-start")?,
        at("/robobus-bench-mark-end")?,
    ))
}

/// The number before the word `cycles` in a runner's output, times `per_cycle`.
pub fn cycles_times(stdout: &str, per_cycle: u64) -> Option<u64> {
    let words: Vec<&str> = stdout.split_whitespace().collect();
    words
        .windows(2)
        .find(|w| {
            w.get(1)
                .is_some_and(|x| x.trim_end_matches(',') == "cycles")
        })
        .and_then(|w| w.first()?.parse::<u64>().ok())
        .map(|c| c * per_cycle)
}

/// The counted cases: wCK polling of one servo at 115200 and 921600 bit/s on the pty, and
/// (with `udp`, inside a network namespace with a multicast route) the WHJ servo cycle of
/// one joint over python-can's UDP bus against a simulator process. All in the sleep mode.
pub fn measure(exe: &Path, udp: bool, python: Option<&Path>) -> (Vec<SyscallCase>, Vec<String>) {
    let mut cases = Vec::new();
    let mut notes = Vec::new();
    for baud in [BaudRate::B115200, BaudRate::B921600] {
        let bps = baud.bits_per_second().to_string();
        let what = format!("wCK status read, 1 servo, {bps} bit/s, pty: ours");
        let args = [
            "poll-wck", "--servos", "1", "--baud", &bps, "--secs", "1", "--wait", "sleep",
        ];
        match count(&what, exe, &args, |o| cycles_times(o, 1)) {
            Ok(c) => cases.push(c),
            Err(e) => notes.push(format!("FAILED {what}: {e}")),
        }
        let Some(py) = python else { continue };
        // The peer against an endpoint of this (untraced) process.
        let what = format!("wCK status read, 1 servo, {bps} bit/s, pty: pyserial");
        let counted =
            crate::wck::Rig::open(1, baud, Timing::ZERO, WaitMode::Sleep).and_then(|rig| {
                let script = crate::peers::script_dir().join("wck_poll_peer.py");
                let path = rig.path.display().to_string();
                let script = script.display().to_string();
                let args = [
                    script.as_str(),
                    "--port",
                    &path,
                    "--baud",
                    &bps,
                    "--servos",
                    "1",
                    "--seconds",
                    "1",
                ];
                count(&what, py, &args, json_cycles)
            });
        match counted {
            Ok(c) => cases.push(c),
            Err(e) => notes.push(format!("FAILED {what}: {e}")),
        }
    }
    if udp {
        let what = "WHJ position servo frame, 1 joint, UDP multicast: ours";
        let spec = crate::whj::ChainSpec {
            joints: 1,
            delay: std::time::Duration::ZERO,
            fast_wire: false,
            wait: robobus_link::WaitMode::Sleep,
            collision_window: true,
        };
        let args = [
            "servo-whj",
            "--external-sim",
            "--joints",
            "1",
            "--delay-us",
            "0",
            "--secs",
            "1",
        ];
        let counted = crate::whj::ChildSim::start(exe, spec).and_then(|sim| {
            let mut c = vec![count(what, exe, &args, |o| cycles_times(o, 1))];
            if let Some(py) = python {
                let script = crate::peers::script_dir().join("whj_servo_peer.py");
                let script = script.display().to_string();
                let args = [script.as_str(), "--joints", "1", "--seconds", "1"];
                let what = "WHJ position servo frame, 1 joint, UDP multicast: python-can";
                c.push(count(what, py, &args, json_cycles));
            }
            sim.stop()?;
            Ok(c)
        });
        match counted {
            Ok(c) => {
                for one in c {
                    match one {
                        Ok(c) => cases.push(c),
                        Err(e) => notes.push(format!("FAILED {e}")),
                    }
                }
            }
            Err(e) => notes.push(format!("FAILED {what}: {e}")),
        }
    } else {
        notes.push("WHJ system calls not counted (no network namespace for UDP)".into());
    }
    (cases, notes)
}

/// The `cycles` of a Python peer's JSON line.
pub fn json_cycles(stdout: &str) -> Option<u64> {
    let line = stdout.lines().rev().find(|l| l.starts_with('{'))?;
    let v: serde_json::Value = serde_json::from_str(line).ok()?;
    v.get("cycles")?.as_u64()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn calls_between_the_markers_are_counted_per_thread() {
        let caller = "1.0 execve(\"x\") = 0\n\
                      2.0 newfstatat(AT_FDCWD, \"/robobus-bench-mark-start\", 0x1, 0) = -1 ENOENT\n\
                      2.1 write(4, \"\\377\", 4) = 4\n\
                      2.2 ppoll([{fd=4}], 1, NULL, NULL, 8) = 1\n\
                      2.3 read(4, \"\\0\", 16) = 1\n\
                      3.0 newfstatat(AT_FDCWD, \"/robobus-bench-mark-end\", 0x1, 0) = -1 ENOENT\n\
                      3.1 write(1, \"done\", 4) = 4\n\
                      3.2 +++ exited with 0 +++\n";
        let other = "1.5 read(5, \"\", 1) = 0\n2.5 write(5, \"\\0\", 1) = 1\n4.0 exit(0) = ?\n";
        let w = window_of(caller).unwrap();
        assert_eq!(w, (2.0, 3.0));
        assert!(window_of(other).is_none());
        let names: Vec<_> = calls(caller)
            .filter(|(t, _)| *t > w.0 && *t < w.1)
            .collect();
        assert_eq!(names, [(2.1, "write"), (2.2, "ppoll"), (2.3, "read")]);
        let inside: Vec<_> = calls(other).filter(|(t, _)| *t > w.0 && *t < w.1).collect();
        assert_eq!(inside, [(2.5, "write")]);
        assert_eq!(
            cycles_times("1 servo(s) at 115200: 1091 cycles, 0 errors", 2),
            Some(2182)
        );
        let mut c = Counts::default();
        for n in ["write", "read", "read", "ppoll", "ppoll", "ppoll"] {
            c.add(n);
        }
        assert_eq!(c.per(2), "ppoll 1.5, read 1.0, write 0.5");
        assert_eq!(
            json_cycles("warming up\n{\"cycles\": 812, \"elapsed\": 1.0}\n"),
            Some(812)
        );
    }
}
