//! wCK control loops against the simulator's pty endpoint on the wall clock: sequential
//! status polling and paced synchronized-move streaming, and the pyserial peer on the same
//! endpoint.

use std::path::PathBuf;
use std::time::{Duration, Instant};

use robobus::wck::{WckBus, WckConfig};
use robobus_link::{ByteLink, MemoryByteLink, WaitMode};
use robobus_sim::wck::{Bus, BusConfig, Endpoint, EndpointStats, Model, Timing};
use robobus_wck::timing;
use robobus_wck::{BaudRate, Command, Position, ServoId, TorqueLevel};

use crate::peers::{self, PeerResult};
use crate::{BenchError, cpu};

/// The simulator's pty endpoint with `servos` modules (IDs `0..servos`) and the client's
/// side of the pty.
pub struct Rig {
    /// The endpoint (one thread, wall clock).
    pub endpoint: Endpoint,
    /// The client side of the pty (or of the memory byte link), as a link.
    pub slave: Box<dyn ByteLink + Send>,
    /// The slave device path (what an outside program opens).
    pub path: PathBuf,
}

impl std::fmt::Debug for Rig {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Rig")
            .field("endpoint", &self.endpoint)
            .field("path", &self.path)
            .finish_non_exhaustive()
    }
}

impl Rig {
    /// Opens a pty and serves `servos` W1108 modules at `baud` with `timing` behind it (no
    /// turnaround spread between modules).
    /// In [`WaitMode::Spin`] the endpoint serves in its precise mode (it polls for
    /// requests and spins to each reply byte's release instant).
    #[cfg(unix)]
    pub fn open(
        servos: u8,
        baud: BaudRate,
        timing: Timing,
        wait: WaitMode,
    ) -> Result<Self, BenchError> {
        use robobus_link::{PtyOptions, PtyPair};
        use std::os::fd::AsFd as _;
        let bus = modules(servos, baud, timing);
        let pair = PtyPair::open(&PtyOptions {
            baud: baud.bits_per_second(),
            symlink: None,
        })
        .map_err(|e| BenchError::new("opening a pty", e))?;
        let termios = pair
            .master
            .as_fd()
            .try_clone_to_owned()
            .map_err(|e| BenchError::new("starting the wCK endpoint", e))?;
        let endpoint = Endpoint::spawn_waiting(
            bus,
            pair.master,
            Some(termios),
            pair.slave_path.clone(),
            wait,
        )
        .map_err(|e| BenchError::new("starting the wCK endpoint", e))?;
        Ok(Self {
            endpoint,
            slave: Box::new(pair.slave),
            path: pair.slave_path,
        })
    }

    /// Serves `servos` W1108 modules at `baud` with `timing` on a TCP port of 127.0.0.1
    /// (this system has no ptys), the client connected to it.
    #[cfg(not(unix))]
    pub fn open(
        servos: u8,
        baud: BaudRate,
        timing: Timing,
        wait: WaitMode,
    ) -> Result<Self, BenchError> {
        use robobus_link::{PortSpec, TcpByteLink};
        let any_port = std::net::SocketAddr::from((std::net::Ipv4Addr::LOCALHOST, 0));
        let endpoint = robobus_sim::wck::spawn_tcp(modules(servos, baud, timing), any_port, wait)
            .map_err(|e| BenchError::new("starting the wCK endpoint", e))?;
        let path = endpoint.path().to_path_buf();
        let spec: PortSpec = path
            .to_string_lossy()
            .parse()
            .map_err(|e| BenchError::new("naming the wCK endpoint", e))?;
        let PortSpec::Tcp { host, port } = spec else {
            return Err(BenchError::new(
                "naming the wCK endpoint",
                format!("{} is not a TCP address", path.display()),
            ));
        };
        let slave = TcpByteLink::connect(&host, port, Duration::from_secs(2))
            .map_err(|e| BenchError::new("connecting to the wCK endpoint", e))?;
        Ok(Self {
            endpoint,
            slave: Box::new(slave),
            path,
        })
    }

    /// The same modules served over TCP on a free port of 127.0.0.1 (what `robobus sim
    /// wck --listen` serves), the client connected with [`robobus_link::TcpByteLink`]
    /// through the port address it announces, as `--port socket://...` connects.
    pub fn open_tcp(
        servos: u8,
        baud: BaudRate,
        timing: Timing,
        wait: WaitMode,
    ) -> Result<Self, BenchError> {
        let any_port = std::net::SocketAddr::from((std::net::Ipv4Addr::LOCALHOST, 0));
        let endpoint = robobus_sim::wck::spawn_tcp(modules(servos, baud, timing), any_port, wait)
            .map_err(|e| BenchError::new("starting the wCK endpoint", e))?;
        let slave = endpoint
            .port()
            .open(baud.bits_per_second())
            .map_err(|e| BenchError::new("connecting to the wCK endpoint", e))?;
        Ok(Self {
            path: endpoint.path().to_path_buf(),
            endpoint,
            slave,
        })
    }

    /// The same modules served over an in-process memory byte link instead of a pty:
    /// no kernel between client and simulator (no path for an outside program).
    pub fn open_memory(
        servos: u8,
        baud: BaudRate,
        timing: Timing,
        wait: WaitMode,
    ) -> Result<Self, BenchError> {
        let (client, device) = MemoryByteLink::pair();
        let path = PathBuf::from("(memory)");
        let endpoint = Endpoint::spawn_waiting(
            modules(servos, baud, timing),
            device,
            None,
            path.clone(),
            wait,
        )
        .map_err(|e| BenchError::new("starting the wCK endpoint", e))?;
        Ok(Self {
            endpoint,
            slave: Box::new(client),
            path,
        })
    }
}

/// `servos` W1108 modules at `baud` with `timing` (no turnaround spread between them),
/// past their deaf time after power-up.
fn modules(servos: u8, baud: BaudRate, timing: Timing) -> Bus {
    let config = BusConfig {
        host_baud: baud,
        timing,
        max_skew: Duration::ZERO,
        ..BusConfig::default()
    };
    let mut bus = Bus::with_servos(config, Model::W1108, 0..servos);
    bus.advance(Duration::from_millis(70));
    bus
}

/// One polling configuration.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PollSpec {
    /// Servos polled per cycle (IDs `0..servos`).
    pub servos: u8,
    /// Line rate.
    pub baud: BaudRate,
    /// The manual's 1006.6 µs module turnaround (`true`) or none.
    pub manual_turnaround: bool,
    /// How the client waits for replies; in [`WaitMode::Spin`] the endpoint serves in its
    /// precise mode too.
    pub wait: WaitMode,
    /// Over an in-process memory byte link instead of the pty (takes the kernel's pty
    /// transfer out of the measurement).
    pub memory: bool,
    /// The client's default guard after each reply (`true`: [`WckConfig::guard`] left at
    /// `None`, one byte time plus the turnaround spread, [`robobus::wck::reply_guard`]),
    /// or none (`false`: `guard: Some(0)`, a reply credited as soon as it is read).
    pub guard: bool,
}

impl PollSpec {
    /// The modelled cycle: `servos × (60 / baud + turnaround)`, from
    /// `robobus_wck::timing`.
    pub fn modelled_cycle(&self) -> Duration {
        let cmd = status_read(0);
        let per = timing::command_wire_time(&cmd, self.baud)
            + if self.manual_turnaround {
                timing::turnaround(&cmd)
            } else {
                Duration::ZERO
            };
        per * u32::from(self.servos)
    }

    /// The client's settings: the simulated modules answer as soon as the command ends
    /// (zero turnaround) or after exactly the manual's turnaround; the guard after each
    /// reply is the client's default or off ([`PollSpec::guard`]). The simulated modules
    /// answer alone, so the guard never fires here: what it costs is its quiet time, one
    /// byte time plus the turnaround spread per transaction, which the wire model does not
    /// count.
    pub fn client_config(self) -> WckConfig {
        WckConfig {
            min_turnaround: (!self.manual_turnaround).then_some(Duration::ZERO),
            guard: if self.guard {
                None
            } else {
                Some(Duration::ZERO)
            },
            wait: self.wait,
            ..WckConfig::default()
        }
    }

    /// `8 servos, 921600 bit/s, zero turnaround, wait spin, pty, guard default`.
    pub fn label(&self) -> String {
        format!(
            "{} servos, {} bit/s, {} turnaround, wait {}, {}, guard {}",
            self.servos,
            self.baud.bits_per_second(),
            if self.manual_turnaround {
                "manual"
            } else {
                "zero"
            },
            self.wait,
            if self.memory { "memory link" } else { "pty" },
            if self.guard { "default" } else { "off" }
        )
    }

    fn timing(self) -> Timing {
        if self.manual_turnaround {
            Timing::MANUAL
        } else {
            Timing::ZERO
        }
    }
}

fn status_read(id: u8) -> Command {
    Command::StatusRead {
        id: ServoId::new(id).unwrap_or(ServoId::MAX),
    }
}

/// What a polling run measured.
#[derive(Debug, Clone)]
pub struct PollResult {
    /// The configuration.
    pub spec: PollSpec,
    /// Complete cycles (every servo polled once).
    pub cycles: u64,
    /// Status reads that failed (after the client's retries).
    pub errors: u64,
    /// Wall time of the measured cycles.
    pub elapsed: Duration,
    /// CPU time of the polling thread.
    pub cpu: Duration,
    /// Duration of each cycle, µs.
    pub cycle_us: Vec<f64>,
    /// The endpoint's own account (CPU, reply lateness).
    pub endpoint: EndpointStats,
    /// The pyserial peer on the same endpoint, if it ran.
    pub peer: Option<PeerResult>,
}

impl PollResult {
    /// Cycles per second.
    pub fn rate_hz(&self) -> f64 {
        self.cycles as f64 / self.elapsed.as_secs_f64().max(1e-9)
    }

    /// Modelled cycle time / measured mean cycle time.
    pub fn efficiency(&self) -> f64 {
        self.spec.modelled_cycle().as_secs_f64() * self.rate_hz()
    }

    /// Client CPU per cycle, µs.
    pub fn cpu_per_cycle_us(&self) -> f64 {
        self.cpu.as_secs_f64() * 1e6 / self.cycles.max(1) as f64
    }
}

/// Polls `spec.servos` servos one after the other with the client library's
/// `Servo::status` for `duration` (after one warm-up cycle); then, if `python` is given,
/// runs the pyserial peer for `duration` on the same endpoint.
pub fn poll(
    spec: PollSpec,
    duration: Duration,
    python: Option<&std::path::Path>,
) -> Result<PollResult, BenchError> {
    let rig = if spec.memory {
        Rig::open_memory(spec.servos, spec.baud, spec.timing(), spec.wait)?
    } else {
        Rig::open(spec.servos, spec.baud, spec.timing(), spec.wait)?
    };
    poll_on(rig, spec, duration, python)
}

/// [`poll`] with the simulator served over TCP on 127.0.0.1 ([`Rig::open_tcp`]) instead
/// of the pty (`spec.memory` is ignored; no pyserial peer).
pub fn poll_tcp(spec: PollSpec, duration: Duration) -> Result<PollResult, BenchError> {
    let rig = Rig::open_tcp(spec.servos, spec.baud, spec.timing(), spec.wait)?;
    poll_on(rig, spec, duration, None)
}

fn poll_on(
    rig: Rig,
    spec: PollSpec,
    duration: Duration,
    python: Option<&std::path::Path>,
) -> Result<PollResult, BenchError> {
    let mut bus = WckBus::new(rig.slave, spec.baud)
        .map_err(|e| BenchError::new("opening WckBus", e))?
        .with_config(spec.client_config());
    let ids: Vec<ServoId> = (0..spec.servos)
        .map(|i| ServoId::new(i).unwrap_or(ServoId::MAX))
        .collect();
    // Warm-up cycle (every servo must answer).
    for &id in &ids {
        bus.servo(id)
            .status()
            .map_err(|e| BenchError::new("warm-up status read", e))?;
    }
    let mut errors = 0u64;
    let mut cycles = 0u64;
    let mut cycle_us = Vec::with_capacity(1 << 16);
    let cpu0 = cpu::thread();
    crate::syscalls::mark("start");
    let t0 = Instant::now();
    while t0.elapsed() < duration {
        let c0 = Instant::now();
        for &id in &ids {
            if bus.servo(id).status().is_err() {
                errors += 1;
            }
        }
        cycle_us.push(c0.elapsed().as_secs_f64() * 1e6);
        cycles += 1;
    }
    crate::syscalls::mark("end");
    let elapsed = t0.elapsed();
    let cpu = cpu::thread().saturating_sub(cpu0);
    let peer = match python {
        Some(py) if !spec.memory => Some(peers::wck_poll(py, &rig.path, spec, duration)?),
        _ => None,
    };
    // The endpoint first: a memory link's endpoint would see its client gone.
    let endpoint = rig
        .endpoint
        .stop()
        .map_err(|e| BenchError::new("stopping the wCK endpoint", e))?;
    drop(bus);
    Ok(PollResult {
        spec,
        cycles,
        errors,
        elapsed,
        cpu,
        cycle_us,
        endpoint,
        peer,
    })
}

/// What a synchronized-move streaming run measured.
#[derive(Debug, Clone)]
pub struct StreamResult {
    /// Line rate.
    pub baud: BaudRate,
    /// Servos addressed by each packet.
    pub servos: u8,
    /// Packets sent.
    pub packets: u64,
    /// From the first packet written until the simulated wire finished the last one.
    pub elapsed: Duration,
    /// Modelled wire time of one packet, `(servos + 4) × 10 / baud`.
    pub packet_time: Duration,
    /// How late packets were written after their slot, µs.
    pub send_lateness_us: Vec<f64>,
    /// Packets a module rejected (should be 0).
    pub decode_errors: u64,
}

impl StreamResult {
    /// Packets per second.
    pub fn rate_hz(&self) -> f64 {
        self.packets as f64 / self.elapsed.as_secs_f64().max(1e-9)
    }

    /// Share of the time the wire carried packets: `packets × packet_time / elapsed`.
    pub fn efficiency(&self) -> f64 {
        self.packet_time.as_secs_f64() * self.rate_hz()
    }
}

/// Streams synchronized moves to 31 servos with `WckBus::sync_move`, paced at the
/// modelled wire rate (one packet every `(31 + 4) × 10 / baud`), for `duration`. The
/// moment the wire finished is taken from a final status read of servo 0, whose reply
/// comes after everything queued before it (minus its own modelled transaction time).
pub fn sync_stream(baud: BaudRate, duration: Duration) -> Result<StreamResult, BenchError> {
    const SERVOS: u8 = 31;
    let rig = Rig::open(SERVOS, baud, Timing::MANUAL, WaitMode::Sleep)?;
    // Paced at exactly the wire rate, any hold-up on the way (scheduling of this thread
    // or of the endpoint) leaves packets queued for good: the final status read may wait
    // behind them for a while.
    let mut bus = WckBus::new(rig.slave, baud)
        .map_err(|e| BenchError::new("opening WckBus", e))?
        .with_config(WckConfig {
            margin: Duration::from_secs(2),
            ..WckConfig::default()
        });
    let id0 = ServoId::new(0).unwrap_or(ServoId::MAX);
    bus.servo(id0)
        .status()
        .map_err(|e| BenchError::new("warm-up status read", e))?;
    let torque = TorqueLevel::new(0).map_err(|e| BenchError::new("torque", e))?;
    let a = [Position::new(120).map_err(|e| BenchError::new("position", e))?; SERVOS as usize];
    let b = [Position::new(134).map_err(|e| BenchError::new("position", e))?; SERVOS as usize];
    let packet_time = timing::sync_move_time(usize::from(SERVOS), baud);
    let mut lateness = Vec::new();
    let mut packets = 0u64;
    let t0 = Instant::now();
    let mut slot = t0;
    while slot.duration_since(t0) < duration {
        let now = Instant::now();
        if slot > now + Duration::from_micros(300) {
            std::thread::sleep(slot.saturating_duration_since(now + Duration::from_micros(200)));
        }
        while Instant::now() < slot {
            std::hint::spin_loop();
        }
        lateness.push(slot.elapsed().as_secs_f64() * 1e6);
        let pos = if packets.is_multiple_of(2) { &a } else { &b };
        bus.sync_move(torque, pos)
            .map_err(|e| BenchError::new("sync move", e))?;
        packets += 1;
        slot += packet_time;
    }
    let probe = status_read(0);
    if let Err(e) = bus.servo(id0).status() {
        let stats = rig.endpoint.with_bus(|b| (b.stats(), b.now()));
        return Err(BenchError::new(
            format!("final status read after {packets} packets (simulator: {stats:?})"),
            e,
        ));
    }
    let done = Instant::now()
        .checked_sub(timing::transaction_time(&probe, baud))
        .unwrap_or(t0);
    let decode_errors = rig
        .endpoint
        .with_bus(|b| b.stats().decode_errors)
        .unwrap_or(u64::MAX);
    drop(bus);
    drop(rig.endpoint);
    Ok(StreamResult {
        baud,
        servos: SERVOS,
        packets,
        elapsed: done.saturating_duration_since(t0),
        packet_time,
        send_lateness_us: lateness,
        decode_errors,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn hz(servos: u8, baud: BaudRate, manual_turnaround: bool) -> f64 {
        1.0 / PollSpec {
            servos,
            baud,
            manual_turnaround,
            wait: WaitMode::Sleep,
            memory: false,
            guard: true,
        }
        .modelled_cycle()
        .as_secs_f64()
    }

    /// The polling rates of the wire-time model (`robobus_wck::timing`): 31 servos at 21.1 / 30.1 Hz with the
    /// turnaround, 61.9 / 495.5 Hz on the wire alone.
    #[test]
    fn modelled_polling_rates_match_the_wire_timing_table() {
        let close = |a: f64, b: f64| (a - b).abs() < 0.05;
        assert!(close(hz(31, BaudRate::B115200, true), 21.1));
        assert!(close(hz(31, BaudRate::B921600, true), 30.1));
        assert!(close(hz(31, BaudRate::B115200, false), 61.9));
        assert!(close(hz(31, BaudRate::B921600, false), 495.5));
        // One transaction at 115200 with the turnaround: 1527.4 µs (655/s).
        assert!((1e6 / hz(1, BaudRate::B115200, true) - 1527.4).abs() < 0.1);
    }
}
