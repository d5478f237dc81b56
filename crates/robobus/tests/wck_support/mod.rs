//! Helpers shared by the wCK client tests: the simulator served on a pty, as
//! `robobus sim wck` serves it, and a client opening the pty by path like a real port.
#![allow(dead_code, unreachable_pub, clippy::unwrap_used)]

use core::time::Duration;

use robobus::wck::WckBus;
use robobus_link::{PtyLink, PtyOptions, PtyPair};
use robobus_sim::wck::{Bus, BusConfig, Eeprom, Endpoint, Model};
use robobus_wck::{BaudRate, ExtServoId, ServoId};

/// Past the 65 ms a module is deaf after power-up.
pub const AWAKE: Duration = Duration::from_millis(70);

/// A simulated bus served on a pty, and the client side of that pty.
#[derive(Debug)]
pub struct Sim {
    /// The serving simulator.
    pub endpoint: Endpoint,
    /// The pty's slave side, what a client uses (taken by [`Sim::bus`]).
    pub slave: Option<PtyLink>,
}

impl Sim {
    /// The client: a [`WckBus`] on the pty's slave side at 115200, named by its path.
    ///
    /// `WckBus::open` (a `SerialLink` on the path) is the real-port path; it is not used
    /// here because the simulator's endpoint cannot yet read the termios2 (BOTHER) speed
    /// that the `serialport` crate sets (see `wck_open_by_path`).
    pub fn bus(&mut self) -> WckBus<PtyLink> {
        let link = self.slave.take().unwrap();
        WckBus::new(link, BaudRate::B115200)
            .unwrap()
            .with_device_name(self.endpoint.path().display().to_string())
    }

    /// Runs `f` on the simulated bus (in its serving thread).
    pub fn with_bus<R: Send + 'static>(&self, f: impl FnOnce(&mut Bus) -> R + Send + 'static) -> R {
        self.endpoint.with_bus(f).unwrap()
    }
}

/// Serves `bus` on a fresh pty and waits until its modules are awake.
pub fn serve(bus: Bus) -> Sim {
    let pair = PtyPair::open(&PtyOptions::default()).unwrap();
    let path = pair.slave_path.clone();
    let endpoint = Endpoint::spawn(bus, pair.master, path).unwrap();
    std::thread::sleep(AWAKE);
    Sim {
        endpoint,
        slave: Some(pair.slave),
    }
}

/// A simulated bus with one 1108 module per ID (factory defaults, shaft at 127).
pub fn serve_ids(ids: &[u8]) -> Sim {
    serve(Bus::with_servos(
        BusConfig::default(),
        Model::W1108,
        ids.iter().copied(),
    ))
}

/// Like [`serve_ids`], with the modules (and the simulated host) at `baud`.
pub fn serve_at(ids: &[u8], baud: BaudRate) -> Sim {
    let config = BusConfig {
        host_baud: baud,
        ..BusConfig::default()
    };
    serve(Bus::with_servos(config, Model::W1108, ids.iter().copied()))
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

/// A servo ID.
pub fn id(n: u8) -> ServoId {
    ServoId::new(n).unwrap()
}
