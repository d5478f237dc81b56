//! Shared by the `whj_*` integration tests: the WHJ simulator served on a thread over a
//! frame link (the same `serve` a real endpoint uses), and a client link to it.

#![allow(dead_code, unreachable_pub, clippy::unwrap_used, clippy::panic)]

use core::time::Duration;

use robobus::whj::JointBusConfig;
use robobus_link::{FrameLink, MemoryBusEndpoint};
use robobus_sim::whj::{
    JointConfig, ServeStats, Served, WhjBus, WhjModel, WhjSimHandle, WhjSimLink,
};

/// A simulated WHJ bus served on its own thread (the simulator crate's `Served`).
pub struct Sim(Served);

impl Sim {
    /// Serve `bus` on `link` (wall clock) until stopped.
    pub fn serve<L: FrameLink + Send + 'static>(bus: WhjBus, link: L) -> Self {
        Self(Served::spawn("sim-whj", bus, link).unwrap())
    }

    /// Stops serving ("unplugs" every joint) and returns the simulated bus.
    pub fn stop(self) -> (WhjBus, ServeStats) {
        self.0.stop().unwrap()
    }
}

/// An in-memory CAN FD bus with the simulator on one endpoint; returns the client's
/// endpoint.
pub fn memory(bus: WhjBus) -> (Sim, MemoryBusEndpoint) {
    let (served, wire) = robobus_sim::whj::spawn(bus).unwrap();
    (Sim(served), wire.endpoint())
}

/// `n` WHJ30 joints with IDs 1..=n (waiting for the IAP release, as shipped).
pub fn chain(n: u8) -> WhjBus {
    WhjBus::chain(1..=n, WhjModel::Whj30, 11)
}

/// Joints from configs.
pub fn configs(configs: Vec<JointConfig>) -> WhjBus {
    WhjBus::with_configs(configs, 11)
}

/// How long the test clients wait for a reply. The simulator answers from a thread on the
/// wall clock, and a shared virtual machine stalls threads now and then (on the
/// development VM a 1 ms sleep overshot by up to 172 ms, about once in 800 by more than
/// 50 ms); a real joint answers in about 0.2 ms, well within the default 20 ms.
pub const REPLY_TIMEOUT: Duration = Duration::from_millis(250);

/// The client configuration of the tests: [`JointBusConfig::simulated`]'s reply timeout,
/// with the default retries (the timeout tests count three attempts).
pub fn config() -> JointBusConfig {
    let config = JointBusConfig {
        retries: JointBusConfig::default().retries,
        ..JointBusConfig::simulated()
    };
    debug_assert_eq!(config.reply_timeout, REPLY_TIMEOUT);
    config
}

/// A client bus on `bus` on the simulator's virtual clock ([`WhjSimLink`]: no thread, no
/// wall clock; time moves only as the client waits), with a handle on the simulation.
pub fn virtual_bus(bus: WhjBus) -> (robobus::whj::JointBus, WhjSimHandle) {
    virtual_bus_with(bus, virtual_config())
}

/// [`virtual_bus`] with its own client configuration.
pub fn virtual_bus_with(
    bus: WhjBus,
    config: JointBusConfig,
) -> (robobus::whj::JointBus, WhjSimHandle) {
    let (link, handle) = WhjSimLink::new(bus);
    let bus = robobus::whj::JointBus::open_with(link, config).unwrap();
    (bus, handle)
}

/// The client configuration on the virtual clock: the library's defaults (20 ms reply
/// timeout, 2 retries), since nothing can stall a simulated reply there.
pub fn virtual_config() -> JointBusConfig {
    JointBusConfig::default()
}

/// The simulated bus as a frame link on the virtual clock, and a handle on it.
pub fn sim_link(bus: WhjBus) -> (WhjSimLink, WhjSimHandle) {
    WhjSimLink::new(bus)
}
