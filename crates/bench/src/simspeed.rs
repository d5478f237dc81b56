//! How fast the simulators run on the virtual clock.

use std::time::{Duration, Instant};

use robobus_sim::wck::{Bus, BusConfig, Model, VirtualHost};
use robobus_wck::{Command, ServoId};
use robobus_whj::CanFrame;

use crate::whj::{ChainSpec, DEFAULT_DELAY};

/// Simulated time and the wall time it took.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SimSpeed {
    /// What ran.
    pub what: &'static str,
    /// Simulated time.
    pub simulated: Duration,
    /// Wall time.
    pub wall: Duration,
}

impl SimSpeed {
    /// Simulated seconds per wall-clock second.
    pub fn ratio(&self) -> f64 {
        self.simulated.as_secs_f64() / self.wall.as_secs_f64().max(1e-9)
    }
}

/// 31 wCK servos at 115200 bit/s with the manual's turnaround under continuous status
/// polling, for `simulated` seconds of virtual time.
pub fn wck(simulated: Duration) -> SimSpeed {
    let bus = Bus::with_servos(BusConfig::default(), Model::W1108, 0..31);
    let mut host = VirtualHost::new(bus);
    host.sleep(Duration::from_millis(70));
    let start = host.now();
    let end = start + simulated;
    let wall = Instant::now();
    let mut k = 0u8;
    while host.now() < end {
        let id = ServoId::new(k % 31).unwrap_or(ServoId::MAX);
        let _ = host.command(&Command::StatusRead { id });
        k = (k + 1) % 31;
    }
    SimSpeed {
        what: "wCK: 31 servos at 115200 bit/s, continuous status polling",
        simulated: host.now().saturating_sub(start),
        wall: wall.elapsed(),
    }
}

/// 7 WHJ joints, a position servo frame to each every millisecond (14 frames per cycle
/// on the 1 / 5 Mbit/s wire), for `simulated` seconds of virtual time.
pub fn whj(simulated: Duration) -> SimSpeed {
    let spec = ChainSpec {
        joints: 7,
        delay: DEFAULT_DELAY,
        fast_wire: false,
        wait: robobus_link::WaitMode::Sleep,
        collision_window: true,
    };
    let mut bus = spec.build();
    let ms = u64::try_from(simulated.as_millis()).unwrap_or(u64::MAX);
    let start = bus.now();
    let wall = Instant::now();
    for k in 0..ms {
        let now = bus.now();
        for id in 1..=7u16 {
            #[allow(clippy::cast_possible_truncation)] // a small sine in counts
            let counts = (1000.0 * ((k as f64) / 1000.0 + f64::from(id)).sin()) as i32;
            if let Some(f) = CanFrame::standard_id(0x200 + id)
                .ok()
                .and_then(|sid| CanFrame::new_fd(sid, &counts.to_le_bytes()).ok())
            {
                bus.submit(f, now);
            }
        }
        let _ = bus.run_until(now + Duration::from_millis(1));
    }
    SimSpeed {
        what: "WHJ: 7 joints, 1 kHz point-to-point position servo (14 frames per cycle)",
        simulated: bus.now().saturating_sub(start),
        wall: wall.elapsed(),
    }
}
