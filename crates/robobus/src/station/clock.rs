//! One clock over some of a station's buses, for an operation that paces a loop across
//! them (a teleoperation, a trajectory).
//!
//! On hardware every bus runs on the wall clock, and so does this. A simulator's bus runs
//! on a virtual clock that moves only when that bus is driven, each on its own; this clock
//! keeps them together as a robot does: its time is the furthest any of its buses has
//! gone since it was made, and every bus behind is brought up to it when it is read.
//! Instants of the buses and of this clock are apart by each bus's own origin
//! ([`BusClock::bus_now`] gives a bus's time on this clock's time line).

use std::time::{Duration, Instant};

use super::{WckPort, WhjPort};

/// A bus of a [`BusClock`].
#[derive(Debug, Clone)]
pub(crate) enum ClockBus {
    /// A wCK port.
    Wck(WckPort),
    /// A WHJ bus.
    Whj(WhjPort),
}

impl ClockBus {
    fn now(&self) -> Instant {
        match self {
            Self::Wck(p) => p.lock().now(),
            Self::Whj(p) => p.bus().now(),
        }
    }

    fn sleep_until(&self, t: Instant) {
        match self {
            Self::Wck(p) => p.lock().sleep_until(t),
            Self::Whj(p) => p.bus().sleep_until(t),
        }
    }

    fn virtual_time(&self) -> bool {
        match self {
            Self::Wck(p) => p.lock().link().virtual_time(),
            Self::Whj(p) => p.bus().virtual_time(),
        }
    }

    /// The bus's name.
    pub(crate) fn name(&self) -> &str {
        match self {
            Self::Wck(p) => p.name(),
            Self::Whj(p) => p.name(),
        }
    }
}

/// The clock of a set of buses (see the [module docs](self)).
#[derive(Debug)]
pub(crate) struct BusClock {
    /// Each bus and its clock's instant at this clock's origin.
    buses: Vec<(ClockBus, Instant)>,
    origin: Instant,
    wall: bool,
}

impl BusClock {
    /// The clock of `buses` (none: the wall clock), starting now.
    pub(crate) fn new(buses: Vec<ClockBus>) -> Self {
        // One bus on the wall clock (hardware, a live simulator) puts them all on it.
        let wall = buses.is_empty() || buses.iter().any(|b| !b.virtual_time());
        let origin = if wall {
            Instant::now()
        } else {
            buses.first().map_or_else(Instant::now, ClockBus::now)
        };
        let buses = buses
            .into_iter()
            .map(|b| {
                let o = b.now();
                (b, o)
            })
            .collect();
        Self {
            buses,
            origin,
            wall,
        }
    }

    /// The clock of `config`'s buses (each opened on the station under its name).
    pub(crate) fn of(
        station: &super::Station,
        config: &crate::robot::RobotConfig,
    ) -> Result<Self, crate::ops::OpError> {
        let buses = config
            .buses
            .iter()
            .map(|(n, b)| {
                Ok(if b.is_wck() {
                    ClockBus::Wck(station.wck(Some(n))?)
                } else {
                    ClockBus::Whj(station.whj(Some(n))?)
                })
            })
            .collect::<Result<Vec<_>, crate::ops::OpError>>()?;
        Ok(Self::new(buses))
    }

    /// The buses, in the order given.
    pub(crate) fn buses(&self) -> impl Iterator<Item = &ClockBus> {
        self.buses.iter().map(|(b, _)| b)
    }

    /// Now: on virtual clocks the furthest any bus has gone, every other brought up to it.
    pub(crate) fn now(&self) -> Instant {
        if self.wall {
            return Instant::now();
        }
        let elapsed = self.elapsed_of_buses();
        for (b, o) in &self.buses {
            b.sleep_until(*o + elapsed);
        }
        self.origin + elapsed
    }

    fn elapsed_of_buses(&self) -> Duration {
        self.buses
            .iter()
            .map(|(b, o)| b.now().saturating_duration_since(*o))
            .max()
            .unwrap_or_default()
    }

    /// Waits until `t` (this clock): the wall clock sleeps; every virtual bus runs to it.
    pub(crate) fn sleep_until(&self, t: Instant) {
        let since = t.saturating_duration_since(self.origin);
        if self.wall {
            std::thread::sleep(t.saturating_duration_since(Instant::now()));
            return;
        }
        for (b, o) in &self.buses {
            b.sleep_until(*o + since);
        }
    }

    /// Bus `index`'s time now, on this clock's time line (what it has reached by itself).
    pub(crate) fn bus_now(&self, index: usize) -> Option<Instant> {
        let (b, o) = self.buses.get(index)?;
        Some(self.origin + b.now().saturating_duration_since(*o))
    }
}
