//! CPU time of the calling thread and of the whole process (`getrusage`), and of each
//! thread by name (`/proc/self/task`).

use std::collections::HashMap;
use std::time::Duration;

#[cfg(target_os = "linux")]
fn usage(who: nix::sys::resource::UsageWho) -> Duration {
    nix::sys::resource::getrusage(who).map_or(Duration::ZERO, |u| {
        let tv = |t: nix::sys::time::TimeVal| {
            let secs = u64::try_from(t.tv_sec()).unwrap_or(0);
            let micros = u64::try_from(t.tv_usec()).unwrap_or(0);
            Duration::from_secs(secs) + Duration::from_micros(micros)
        };
        tv(u.user_time()) + tv(u.system_time())
    })
}

/// CPU time (user + system) the calling thread has used.
pub fn thread() -> Duration {
    #[cfg(target_os = "linux")]
    {
        usage(nix::sys::resource::UsageWho::RUSAGE_THREAD)
    }
    #[cfg(not(target_os = "linux"))]
    {
        Duration::ZERO
    }
}

/// CPU time (user + system) of every thread of this process.
pub fn process() -> Duration {
    #[cfg(target_os = "linux")]
    {
        usage(nix::sys::resource::UsageWho::RUSAGE_SELF)
    }
    #[cfg(not(target_os = "linux"))]
    {
        Duration::ZERO
    }
}

/// Clock ticks a second of `/proc` times (`USER_HZ`, 100 on Linux).
const TICKS_PER_SEC: u64 = 100;

/// The threads of this process at one instant: (name, CPU time), by thread ID.
#[derive(Debug, Clone, Default)]
pub struct Tasks(HashMap<u64, (String, Duration)>);

impl Tasks {
    /// Whether the thread `tid` was there.
    #[must_use]
    pub fn contains(&self, tid: u64) -> bool {
        self.0.contains_key(&tid)
    }
}

/// Each thread of this process, from `/proc/self/task/*/stat` (10 ms ticks); empty where
/// there is no `/proc`.
pub fn tasks() -> Tasks {
    let mut out = HashMap::new();
    let Ok(dir) = std::fs::read_dir("/proc/self/task") else {
        return Tasks(out);
    };
    for e in dir.flatten() {
        let Some(tid) = e.file_name().to_str().and_then(|s| s.parse::<u64>().ok()) else {
            continue;
        };
        let Ok(stat) = std::fs::read_to_string(e.path().join("stat")) else {
            continue;
        };
        // "TID (COMM) STATE ... UTIME(14) STIME(15) ..."; COMM may hold spaces.
        let (Some(open), Some(close)) = (stat.find('('), stat.rfind(')')) else {
            continue;
        };
        let name = stat.get(open + 1..close).unwrap_or_default().to_owned();
        let rest: Vec<&str> = stat
            .get(close + 1..)
            .unwrap_or_default()
            .split_whitespace()
            .collect();
        let field = |i: usize| rest.get(i).and_then(|v| v.parse::<u64>().ok()).unwrap_or(0);
        let ticks = field(11) + field(12);
        out.insert(
            tid,
            (name, Duration::from_millis(ticks * 1000 / TICKS_PER_SEC)),
        );
    }
    Tasks(out)
}

/// CPU time the threads whose name `pick` accepts used between two [`tasks`] snapshots.
pub fn tasks_cpu(before: &Tasks, after: &Tasks, pick: impl Fn(&str) -> bool) -> Duration {
    after
        .0
        .iter()
        .filter(|(_, (n, _))| pick(n))
        .map(|(tid, (_, t))| t.saturating_sub(before.0.get(tid).map_or(Duration::ZERO, |b| b.1)))
        .sum()
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn this_thread_is_among_the_tasks() {
        let me: u64 = std::fs::read_link("/proc/thread-self")
            .unwrap()
            .file_name()
            .and_then(|n| n.to_str())
            .unwrap()
            .parse()
            .unwrap();
        let all = tasks();
        assert!(all.contains(me), "{me} not in {all:?}");
    }
}
