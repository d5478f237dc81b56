//! CPU time of the calling thread and of the whole process (`getrusage`).

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
