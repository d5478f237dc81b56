//! WHJ joints through an slcan CAN FD adapter: the client's register read and cyclic loop
//! over `SlcanLink` on a pty, against the emulated adapter (`robobus sim whj --bus
//! slcan:PATH`'s driver, on a thread) with simulated joints behind it.
//!
//! The modelled time of each exchange is what the same exchange takes on the simulator's
//! virtual clock (`AdapterSimLink`): the CAN wire, the joints' processing delay, and the
//! adapter's serial time (10 µs a character each way, an slcan FD frame of n bytes being
//! 2n + 6 characters). The measured time is the wall clock's over the pty. The ratio
//! modelled / measured is the client's efficiency through the adapter: 100 % is an
//! adapter and host that add nothing to the model.

use std::time::Duration;

use robobus::whj::{CyclicConfig, CyclicStats, JointBus, JointBusConfig};
use robobus_link::{SlcanConfig, SlcanLink};
use robobus_sim::whj::adapter::{AdapterSimLink, SlcanAdapter};
use robobus_sim::whj::{WhjBus, WhjModel, WhjSimLink};
use robobus_whj::units::Position;
use robobus_whj::{JointId, WorkMode};

use crate::BenchError;
use crate::stats::Summary;

/// One run's results.
#[derive(Debug, Clone, Copy)]
pub struct SlcanResult {
    /// Joints behind the adapter (all in the cyclic loop).
    pub joints: u8,
    /// A register read's modelled round trip.
    pub read_modelled: Duration,
    /// Measured register reads, µs.
    pub read_measured: Summary,
    /// The cyclic loop's period.
    pub period: Duration,
    /// A cycle's modelled round trip (commands out, every feedback back).
    pub cycle_modelled: Duration,
    /// Measured cycle round trips, µs.
    pub cycle_measured: Summary,
    /// Cycles run, complete, and missed on the wall clock.
    pub cycles: (u64, u64, u64),
}

impl SlcanResult {
    /// Modelled / measured median of a register read.
    pub fn read_ratio(&self) -> f64 {
        ratio(self.read_modelled, self.read_measured.p50)
    }

    /// Modelled / measured median of a cycle's round trip.
    pub fn cycle_ratio(&self) -> f64 {
        ratio(self.cycle_modelled, self.cycle_measured.p50)
    }

    /// The report's lines.
    pub fn lines(&self) -> String {
        format!(
            "slcan register read: modelled {:.1} µs, measured p50 {:.1} µs p99 {:.1} µs: {:.1} %\n\
             slcan cyclic loop, {} joints at {} µs: modelled cycle {:.1} µs, measured p50 \
             {:.1} µs p99 {:.1} µs: {:.1} %; cycles {} complete {} missed {}",
            us(self.read_modelled),
            self.read_measured.p50,
            self.read_measured.p99,
            self.read_ratio() * 100.0,
            self.joints,
            self.period.as_micros(),
            us(self.cycle_modelled),
            self.cycle_measured.p50,
            self.cycle_measured.p99,
            self.cycle_ratio() * 100.0,
            self.cycles.0,
            self.cycles.1,
            self.cycles.2,
        )
    }
}

fn us(d: Duration) -> f64 {
    d.as_secs_f64() * 1e6
}

fn ratio(modelled: Duration, measured_us: f64) -> f64 {
    if measured_us > 0.0 {
        us(modelled) / measured_us
    } else {
        0.0
    }
}

fn err(what: &str) -> impl FnOnce(String) -> BenchError + '_ {
    move |e| BenchError::new(what.to_owned(), e)
}

fn chain(joints: u8) -> WhjBus {
    WhjBus::chain(1..=joints, WhjModel::Whj30, 5)
}

fn jid(i: u8) -> JointId {
    JointId::new(i).unwrap_or(JointId::MIN)
}

/// Joints ready for the cyclic loop: position mode, enabled.
fn ready(bus: &JointBus, joints: u8) -> Result<(), BenchError> {
    for i in 1..=joints {
        let j = bus
            .joint(jid(i))
            .map_err(|e| err("connecting a joint")(e.to_string()))?;
        j.set_mode(WorkMode::Position)
            .and_then(|()| j.enable())
            .map_err(|e| err("enabling a joint")(e.to_string()))?;
    }
    Ok(())
}

/// `reads` register reads (the work mode, register 0x30) of joint 1: each one's time on
/// the bus's clock.
fn reads(bus: &JointBus, reads: usize) -> Result<Vec<Duration>, BenchError> {
    let j = bus
        .joint(jid(1))
        .map_err(|e| err("connecting joint 1")(e.to_string()))?;
    let mut out = Vec::with_capacity(reads);
    for _ in 0..reads {
        let t = bus.now();
        j.mode()
            .map_err(|e| err("reading a register")(e.to_string()))?;
        out.push(bus.now() - t);
    }
    Ok(out)
}

/// The cyclic loop for `secs`: its statistics.
fn cyclic(
    bus: &JointBus,
    joints: u8,
    period: Duration,
    secs: Duration,
) -> Result<CyclicStats, BenchError> {
    let ids: Vec<JointId> = (1..=joints).map(jid).collect();
    let cyc = bus
        .cyclic(CyclicConfig::position(ids, period))
        .map_err(|e| err("starting the cyclic loop")(e.to_string()))?;
    let targets = vec![Position::from_degrees(1.0).unwrap_or_default(); usize::from(joints)];
    cyc.set_positions(&targets)
        .map_err(|e| err("setting targets")(e.to_string()))?;
    bus.sleep_until(bus.now() + secs);
    Ok(cyc.stop())
}

fn summary(d: &[Duration]) -> Summary {
    let v: Vec<f64> = d.iter().map(|d| us(*d)).collect();
    Summary::of_us(&v)
}

/// Runs the case: `n_reads` register reads and `secs` of the cyclic loop over `joints`
/// joints at `period`, first on the virtual clock (the model), then on a pty.
///
/// # Errors
/// A pty, the adapter or a joint that fails.
pub fn run(
    joints: u8,
    n_reads: usize,
    period: Duration,
    secs: Duration,
) -> Result<SlcanResult, BenchError> {
    // The model: the same client on the virtual clock.
    let (sim, _handle) = WhjSimLink::new(chain(joints));
    let port = AdapterSimLink::new(Box::new(SlcanAdapter::default()), sim);
    let link = SlcanLink::open(port, "sim", &SlcanConfig::default())
        .map_err(|e| err("opening the virtual adapter")(e.to_string()))?;
    let bus = JointBus::open_with(link, JointBusConfig::default())
        .map_err(|e| err("opening the virtual bus")(e.to_string()))?;
    ready(&bus, joints)?;
    let modelled_reads = reads(&bus, 5)?;
    let read_modelled = modelled_reads.iter().copied().min().unwrap_or_default();
    let stats = cyclic(&bus, joints, period, Duration::from_millis(200))?;
    let cycle_modelled = stats.round_trip.p50;
    drop(bus);

    let (r, stats) = measure(joints, n_reads, period, secs)?;
    Ok(SlcanResult {
        joints,
        read_modelled,
        read_measured: summary(&r),
        period,
        cycle_modelled,
        cycle_measured: Summary {
            n: stats.round_trip.samples,
            p50: us(stats.round_trip.p50),
            p99: us(stats.round_trip.p99),
            max: us(stats.round_trip.max),
            ..Summary::of_us(&[us(stats.round_trip.p50)])
        },
        cycles: (stats.cycles, stats.complete, stats.deadline_misses),
    })
}

/// The measurement: the emulated adapter's driver on a thread, the client on its pty;
/// the register reads' and the cyclic loop's times.
#[cfg(unix)]
fn measure(
    joints: u8,
    n_reads: usize,
    period: Duration,
    secs: Duration,
) -> Result<(Vec<Duration>, CyclicStats), BenchError> {
    use robobus_link::{PtyOptions, PtyPair, SerialLink};
    use robobus_sim::whj::adapter;
    use std::sync::Arc;
    use std::sync::atomic::{AtomicBool, Ordering};
    let PtyPair {
        master,
        slave,
        slave_path,
    } = PtyPair::open(&PtyOptions::default()).map_err(|e| err("opening a pty")(e.to_string()))?;
    drop(slave);
    let stop = Arc::new(AtomicBool::new(false));
    let flag = Arc::clone(&stop);
    let joints_bus = chain(joints);
    let server = std::thread::Builder::new()
        .name("slcan-adapter".into())
        .spawn(move || {
            let (mut sim, handle) = WhjSimLink::new(joints_bus);
            let mut master = master;
            let mut model = SlcanAdapter::default();
            adapter::run(
                &mut model,
                &mut master,
                &mut sim,
                &handle,
                &flag,
                || {},
                |_| {},
            )
        })
        .map_err(|e| err("starting the adapter")(e.to_string()))?;
    let measured = (|| {
        let serial = SerialLink::open(&slave_path, 115_200)
            .map_err(|e| err("opening the pty")(e.to_string()))?;
        let link = SlcanLink::open(
            serial,
            &slave_path.display().to_string(),
            &SlcanConfig::default(),
        )
        .map_err(|e| err("opening the adapter")(e.to_string()))?;
        let bus = JointBus::open_with(link, JointBusConfig::simulated())
            .map_err(|e| err("opening the bus")(e.to_string()))?;
        ready(&bus, joints)?;
        let r = reads(&bus, n_reads)?;
        let stats = cyclic(&bus, joints, period, secs)?;
        Ok::<_, BenchError>((r, stats))
    })();
    stop.store(true, Ordering::Relaxed);
    let _ = server.join();
    measured
}

/// The measurement needs a pty: not on this system (the benchmarks measure on Linux).
#[cfg(not(unix))]
fn measure(
    _joints: u8,
    _n_reads: usize,
    _period: Duration,
    _secs: Duration,
) -> Result<(Vec<Duration>, CyclicStats), BenchError> {
    Err(err("opening a pty")(
        "this system has no pseudo-terminals (the benchmarks measure on Linux)".into(),
    ))
}
