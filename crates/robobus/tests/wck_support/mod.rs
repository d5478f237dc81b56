//! Helpers shared by the wCK client tests: the simulator in process behind a
//! [`SimLink`] on its virtual clock (the client takes every instant from the link, so
//! replies, timeouts and durations are exact and take no wall time), or served on a pty
//! as `robobus sim wck` serves it, with a client opening the pty like a real port.
#![allow(dead_code, unreachable_pub, clippy::unwrap_used)]

use core::time::Duration;

use robobus::wck::{WckBus, WckConfig};
#[cfg(unix)]
use robobus_link::PtyLink;
#[cfg(unix)]
use robobus_sim::wck::Endpoint;
use robobus_sim::wck::{Bus, BusConfig, Eeprom, Model, SimHandle, SimLink};
use robobus_wck::{BaudRate, ExtServoId, ServoId};

/// Past the 65 ms a module is deaf after power-up.
pub const AWAKE: Duration = Duration::from_millis(70);

/// The device name of the in-process simulator in errors.
pub const DEVICE: &str = "sim:wck";

/// The reply margin of the clients of the pty simulator. That simulator is a thread on
/// the wall clock, and a shared virtual machine stalls threads now and then: on the
/// development VM (CPU steal 10-60 %) a 1 ms sleep overshot by more than 50 ms about once
/// in 800 and by up to 172 ms (90 s of sampling). A reply that misses its deadline and
/// arrives later is taken for the next command's reply (wCK replies carry no ID), so
/// these clients wait long enough for such stalls; a real module answers within the
/// default 10 ms margin. The in-process [`SimLink`] needs none of this.
pub const PTY_MARGIN: Duration = Duration::from_millis(300);

/// A simulated bus in this process, and the client's link to it.
#[derive(Debug)]
pub struct Sim {
    /// The bus, from any thread.
    pub handle: SimHandle,
    /// The client's end (taken by [`Sim::bus`] or [`Sim::link`]).
    link: Option<SimLink>,
}

impl Sim {
    /// The client: a [`WckBus`] at 115200 bit/s with the default configuration, named
    /// [`DEVICE`].
    pub fn bus(&mut self) -> WckBus<SimLink> {
        WckBus::new(self.link(), BaudRate::B115200)
            .unwrap()
            .with_device_name(DEVICE)
    }

    /// The client's link itself.
    pub fn link(&mut self) -> SimLink {
        self.link.take().unwrap()
    }

    /// Runs `f` on the simulated bus.
    pub fn with_bus<R>(&self, f: impl FnOnce(&mut Bus) -> R) -> R {
        self.handle.with_bus(f)
    }

    /// Lets `d` of simulated time pass (at once: the clock is virtual).
    pub fn sleep(&self, d: Duration) {
        self.handle.sleep(d);
    }

    /// Simulated time now.
    pub fn now(&self) -> Duration {
        self.handle.now()
    }
}

/// Connects to `bus` in process on the virtual clock, with its modules awake.
pub fn serve(bus: Bus) -> Sim {
    let (link, handle) = SimLink::virtual_clock(bus);
    handle.sleep(AWAKE.saturating_sub(handle.now()));
    Sim {
        handle,
        link: Some(link),
    }
}

/// Like [`serve_at`] (the virtual clock runs long transaction loops as fast as the
/// processor allows).
pub fn serve_fast(ids: &[u8], baud: BaudRate) -> Sim {
    serve_at(ids, baud)
}

/// A simulated bus with one 1108 module per ID (factory defaults, shaft at 127).
pub fn serve_ids(ids: &[u8]) -> Sim {
    serve(bus_with_ids(ids, BaudRate::B115200))
}

/// Like [`serve_ids`], with the modules (and the simulated host) at `baud`.
pub fn serve_at(ids: &[u8], baud: BaudRate) -> Sim {
    serve(bus_with_ids(ids, baud))
}

/// A bus with modules given as (ID, baud rate, position 0..=254).
pub fn serve_modules(modules: &[(u8, BaudRate, u8)]) -> Sim {
    let mut bus = Bus::new(BusConfig::default());
    for &(id, baud, position) in modules {
        let eeprom = Eeprom {
            id: ExtServoId::new(id).unwrap(),
            baud,
            ..Eeprom::default()
        };
        bus.add(Model::W1108, eeprom, f64::from(position) * 269.0 / 255.0);
    }
    serve(bus)
}

fn bus_with_ids(ids: &[u8], baud: BaudRate) -> Bus {
    let config = BusConfig {
        host_baud: baud,
        ..BusConfig::default()
    };
    Bus::with_servos(config, Model::W1108, ids.iter().copied())
}

/// A simulated bus served on a pty by the simulator's endpoint thread, and the client
/// side of that pty (Unix: Windows has no ptys).
#[cfg(unix)]
#[derive(Debug)]
pub struct PtySim {
    /// The serving simulator.
    pub endpoint: Endpoint,
    /// The pty's slave side, what a client uses (taken by [`PtySim::bus`]).
    pub slave: Option<PtyLink>,
}

#[cfg(unix)]
impl PtySim {
    /// The client: a [`WckBus`] on the pty's slave side at 115200 with [`PTY_MARGIN`],
    /// named by its path.
    pub fn bus(&mut self) -> WckBus<PtyLink> {
        let link = self.slave.take().unwrap();
        WckBus::new(link, BaudRate::B115200)
            .unwrap()
            .with_config(pty_config())
            .with_device_name(self.endpoint.path().display().to_string())
    }

    /// Runs `f` on the simulated bus (in its serving thread).
    pub fn with_bus<R: Send + 'static>(&self, f: impl FnOnce(&mut Bus) -> R + Send + 'static) -> R {
        self.endpoint.with_bus(f).unwrap()
    }
}

/// The client configuration for the pty simulator: the defaults with [`PTY_MARGIN`] and
/// a drain after a failed attempt that outlasts most stalls.
pub fn pty_config() -> WckConfig {
    WckConfig {
        margin: PTY_MARGIN,
        settle: Duration::from_millis(40),
        ..WckConfig::default()
    }
}

/// Serves modules with `ids` (factory defaults) on a fresh pty and waits until they are
/// awake (in simulated time: the serving thread may start late on a busy machine).
#[cfg(unix)]
pub fn serve_pty(ids: &[u8]) -> PtySim {
    let (endpoint, slave) = robobus_sim::wck::spawn(bus_with_ids(ids, BaudRate::B115200)).unwrap();
    while endpoint.with_bus(|b| b.now()).unwrap() < AWAKE {
        std::thread::sleep(Duration::from_millis(5));
    }
    PtySim {
        endpoint,
        slave: Some(slave),
    }
}

/// A servo ID.
pub fn id(n: u8) -> ServoId {
    ServoId::new(n).unwrap()
}
