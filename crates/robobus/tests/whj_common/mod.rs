//! Shared by the `whj_*` integration tests: the WHJ simulator served on a thread over a
//! frame link (the same `serve` a real endpoint uses), and a client link to it.

#![allow(dead_code, unreachable_pub, clippy::unwrap_used, clippy::panic)]

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;

use robobus_link::{FrameLink, MemoryBus, MemoryBusEndpoint};
use robobus_sim::whj::{JointConfig, ServeStats, WhjBus, WhjModel};

/// A simulated WHJ bus served on its own thread.
pub struct Sim {
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<(WhjBus, ServeStats)>>,
}

impl Sim {
    /// Serve `bus` on `link` (wall clock) until stopped.
    pub fn serve<L: FrameLink + Send + 'static>(mut bus: WhjBus, mut link: L) -> Self {
        let stop = Arc::new(AtomicBool::new(false));
        let flag = Arc::clone(&stop);
        let thread = std::thread::spawn(move || {
            let stats = robobus_sim::whj::serve(&mut bus, &mut link, &flag).unwrap();
            (bus, stats)
        });
        Self {
            stop,
            thread: Some(thread),
        }
    }

    /// Stops serving ("unplugs" every joint) and returns the simulated bus.
    pub fn stop(mut self) -> (WhjBus, ServeStats) {
        self.halt().unwrap()
    }

    fn halt(&mut self) -> Option<(WhjBus, ServeStats)> {
        self.stop.store(true, Ordering::Relaxed);
        self.thread.take().map(|t| t.join().unwrap())
    }
}

impl Drop for Sim {
    fn drop(&mut self) {
        let _ = self.halt();
    }
}

/// An in-memory CAN FD bus with the simulator on one endpoint; returns the client's
/// endpoint.
pub fn memory(bus: WhjBus) -> (Sim, MemoryBusEndpoint) {
    let wire = MemoryBus::new();
    let sim = Sim::serve(bus, wire.endpoint());
    (sim, wire.endpoint())
}

/// `n` WHJ30 joints with IDs 1..=n (waiting for the IAP release, as shipped).
pub fn chain(n: u8) -> WhjBus {
    WhjBus::chain(1..=n, WhjModel::Whj30, 11)
}

/// Joints from configs.
pub fn configs(configs: Vec<JointConfig>) -> WhjBus {
    WhjBus::with_configs(configs, 11)
}
