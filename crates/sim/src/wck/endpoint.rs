//! The wCK bus behind a pseudo-terminal (Unix) or a TCP listener (every OS), on the wall
//! clock.
//!
//! One thread owns the [`Bus`] and the pty master (or the [`TcpServer`]). It reads what a
//! client writes to the slave side (or the socket), stamps each chunk with its arrival
//! time and puts it on the simulated wire at the client's baud rate (on a pty, read from
//! its termios, which the kernel shares between master and slave, so a client's
//! `tcsetattr` is seen here and a mismatch garbles the bytes as on a real bus; over TCP
//! there is no line rate to set, and the wire runs at the bus's host rate, the
//! simulator's `--baud`). It writes each reply byte to the master the moment its stop
//! bit would leave the wire, sleeping in `ppoll` with a 1 µs timer slack until then.
//! Input is taken from the pty no faster than the wire carries it (a few milliseconds
//! ahead at most), so a client that floods the port blocks in its write, as on a real
//! port, and a command after the flood is answered within a bounded time. While the
//! client's bytes are on the simulated wire the model runs ahead through them (nothing the
//! client writes meanwhile can come earlier on the wire), so the thread wakes for a
//! command and for each reply byte, not for every byte a module receives.
//! Other threads reach the bus through [`Endpoint::with_bus`] (a small command queue),
//! so the test API (push, hold, set the A/D input, power-cycle) works while it serves.
//!
//! Over TCP ([`spawn_tcp`]) the timing model is the same; the listener serves one client
//! at a time and the next once it leaves, as a port closed and opened again (see
//! [`TcpServer`]); reply bytes due while no client is connected are dropped.

use core::time::Duration;
#[cfg(unix)]
use std::os::fd::AsFd;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::thread::JoinHandle;
use std::time::Instant;

#[cfg(unix)]
use robobus_link::pty::termios_speed;
use robobus_link::{ByteLink, LinkError, PortSpec, TcpServer, WaitMode, wait};
#[cfg(unix)]
use robobus_link::{PtyLink, PtyOptions, PtyPair};

use super::bus::Bus;
use crate::lateness::{Lateness, LatenessSummary};

/// How long the serving thread sleeps at most when nothing is due (it then checks for
/// stop requests, queued commands and the client's baud rate).
const IDLE: Duration = Duration::from_millis(10);

/// Input backpressure: the client's bytes are taken from the pty only while the simulated
/// wire has less than this much of them still to carry. A real port accepts bytes only at
/// the wire rate, so a flood fills the kernel's buffer and blocks the writer instead of
/// queueing minutes of traffic in the simulator (which would leave it deaf to a command
/// sent after the flood for as long).
const INPUT_AHEAD: Duration = Duration::from_millis(5);

/// What the serving thread did, returned by [`Endpoint::stop`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct EndpointStats {
    /// How long it served.
    pub wall: Duration,
    /// CPU time the serving thread used (user + system).
    pub cpu: Duration,
    /// Bytes read from the client.
    pub bytes_in: u64,
    /// Bytes written to the client.
    pub bytes_out: u64,
    /// Latest a reply byte was written after its release instant.
    pub late_max: Duration,
    /// Sum of the lateness of every written byte (divide by `bytes_out` for the mean).
    pub late_total: Duration,
    /// Times the serving thread woke up (client input, a reply byte due, a queued
    /// command, or the idle tick); in [`WaitMode::Spin`], loop passes.
    pub wakeups: u64,
    /// How late the reply bytes were written after their release instants (p50, p99).
    pub lateness: LatenessSummary,
    /// How the serving thread waited.
    pub wait: WaitMode,
}

/// Why serving stopped with an error.
#[derive(Debug, thiserror::Error)]
pub enum EndpointError {
    /// The pty failed.
    #[error("wCK endpoint: {0}")]
    Link(#[from] LinkError),
    /// The serving thread panicked (a bug).
    #[error("wCK endpoint: the serving thread panicked")]
    Panicked,
}

type Job = Box<dyn FnOnce(&mut Bus) + Send>;

/// A descriptor of the pty whose termios holds the client's baud rate (see
/// [`Endpoint::spawn_link`]).
#[cfg(unix)]
pub type TermiosFd = std::os::fd::OwnedFd;

/// Without ptys there is no termios to follow: no value of this type exists.
#[cfg(not(unix))]
#[derive(Debug)]
pub enum TermiosFd {}

/// A simulated bus served on a pty by a background thread. Dropping it stops the thread.
#[derive(Debug)]
pub struct Endpoint {
    stop: Arc<AtomicBool>,
    jobs: mpsc::Sender<Job>,
    thread: Option<JoinHandle<Result<EndpointStats, EndpointError>>>,
    path: PathBuf,
    port: PortSpec,
}

impl Endpoint {
    /// Serves `bus` on the master side of a pty (from `robobus_link::PtyPair`); `path` is
    /// what clients open (the slave device or its symlink), kept for [`Endpoint::path`].
    /// Simulation time continues from the bus's current time.
    #[cfg(unix)]
    pub fn spawn(bus: Bus, master: PtyLink, path: PathBuf) -> std::io::Result<Self> {
        let termios = master.as_fd().try_clone_to_owned()?;
        Self::spawn_link(bus, master, Some(termios), path)
    }

    /// Serves `bus` on any byte link, for example a pty master wrapped in
    /// `robobus_link::FaultyByteLink` (noise, dropped bytes). `termios` is a descriptor of
    /// the pty (a duplicate of the master) whose baud rate the client sets; `None` keeps
    /// the bus's host rate.
    pub fn spawn_link<L: ByteLink + Send + 'static>(
        bus: Bus,
        link: L,
        termios: Option<TermiosFd>,
        path: PathBuf,
    ) -> std::io::Result<Self> {
        Self::spawn_waiting(bus, link, termios, path, WaitMode::Sleep)
    }

    /// [`Endpoint::spawn_link`], waiting in `wait`: [`WaitMode::Spin`] is the precise
    /// mode, for benchmarks that measure a client against a device that keeps its timing.
    /// The serving thread then polls the pty for requests instead of sleeping, and spins to
    /// each reply byte's release instant instead of waking up for it: one core stays busy
    /// while it serves.
    pub fn spawn_waiting<L: ByteLink + Send + 'static>(
        bus: Bus,
        link: L,
        termios: Option<TermiosFd>,
        path: PathBuf,
        wait: WaitMode,
    ) -> std::io::Result<Self> {
        Self::spawn_at(bus, link, termios, PortSpec::Device(path), wait)
    }

    /// Serves `bus` on a [`TcpServer`] (one client at a time; the wire runs at the bus's
    /// host rate). [`Endpoint::path`] and [`Endpoint::port`] are then its
    /// `socket://HOST:PORT` address.
    pub fn spawn_tcp(bus: Bus, server: TcpServer, wait: WaitMode) -> std::io::Result<Self> {
        let port = server.port_spec();
        Self::spawn_at(bus, server, None, port, wait)
    }

    /// Serves `bus` on any byte link that clients reach at `port`: a pty master (with the
    /// `termios` descriptor whose baud rate the client sets), or a [`TcpServer`] wrapped in
    /// a fault injector or a capture (`termios` `None`: the bus's host rate applies).
    pub fn spawn_at<L: ByteLink + Send + 'static>(
        bus: Bus,
        link: L,
        termios: Option<TermiosFd>,
        port: PortSpec,
        wait: WaitMode,
    ) -> std::io::Result<Self> {
        let path = match &port {
            PortSpec::Device(path) => path.clone(),
            other => PathBuf::from(other.to_string()),
        };
        let stop = Arc::new(AtomicBool::new(false));
        let (jobs, rx) = mpsc::channel::<Job>();
        let flag = Arc::clone(&stop);
        let thread = std::thread::Builder::new()
            .name("robobus-sim-wck".into())
            .spawn(move || serve(bus, link, termios.as_ref(), &flag, &rx, wait))?;
        Ok(Self {
            stop,
            jobs,
            thread: Some(thread),
            path,
            port,
        })
    }

    /// The path clients open: the pty's slave device (or its symlink), or over TCP the
    /// `socket://HOST:PORT` address as text (which `WckBus::open` takes as it is).
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// What clients name to reach it (`--port`): the pty's path, or `socket://HOST:PORT`.
    pub const fn port(&self) -> &PortSpec {
        &self.port
    }

    /// Whether the serving thread is still running.
    pub fn is_running(&self) -> bool {
        self.thread.as_ref().is_some_and(|t| !t.is_finished())
    }

    /// Runs `f` on the bus in the serving thread (after bringing the bus to the current
    /// time; while a client's command is still on the simulated wire the bus may already
    /// stand at a later instant of it, see the module notes) and returns its result, or
    /// `None` if the thread has stopped.
    pub fn with_bus<R: Send + 'static>(
        &self,
        f: impl FnOnce(&mut Bus) -> R + Send + 'static,
    ) -> Option<R> {
        let (tx, rx) = mpsc::sync_channel(1);
        let job: Job = Box::new(move |bus| {
            let _ = tx.send(f(bus));
        });
        self.jobs.send(job).ok()?;
        rx.recv().ok()
    }

    /// Stops serving and returns what the thread did. The pty (and its symlink) is closed.
    pub fn stop(mut self) -> Result<EndpointStats, EndpointError> {
        self.stop_thread()
    }

    fn stop_thread(&mut self) -> Result<EndpointStats, EndpointError> {
        self.stop.store(true, Ordering::Relaxed);
        match self.thread.take() {
            Some(t) => t.join().map_err(|_| EndpointError::Panicked)?,
            None => Ok(EndpointStats::default()),
        }
    }
}

impl Drop for Endpoint {
    fn drop(&mut self) {
        let _ = self.stop_thread();
    }
}

/// Serves `bus` behind a new pty (default options: no symlink) on a thread of its own:
/// the shortest way to a simulated wCK bus in a test or an example. Returns the endpoint
/// (its [`Endpoint::path`] is the slave device) and the pty's slave side, the client's
/// link (`WckBus::new(link, baud)`). Simulation time continues from the bus's current
/// time: the modules are deaf for the first 65 ms after power-up.
///
/// Errors: the pty cannot be opened or the thread cannot be started.
#[cfg(unix)]
pub fn spawn(bus: Bus) -> Result<(Endpoint, PtyLink), LinkError> {
    spawn_waiting(bus, WaitMode::Sleep)
}

/// [`spawn`], the serving thread waiting in `wait` (see [`Endpoint::spawn_waiting`]).
///
/// Errors: the pty cannot be opened or the thread cannot be started.
#[cfg(unix)]
pub fn spawn_waiting(bus: Bus, wait: WaitMode) -> Result<(Endpoint, PtyLink), LinkError> {
    let pair = PtyPair::open(&PtyOptions::default())?;
    let termios = pair
        .master
        .as_fd()
        .try_clone_to_owned()
        .map_err(|e| LinkError::io("starting the wCK endpoint", e))?;
    let endpoint = Endpoint::spawn_waiting(bus, pair.master, Some(termios), pair.slave_path, wait)
        .map_err(|e| LinkError::io("starting the wCK endpoint", e))?;
    Ok((endpoint, pair.slave))
}

/// Serves `bus` over TCP on `addr` (`127.0.0.1:0` picks a free port; the endpoint's
/// [`Endpoint::port`] names it), the serving thread waiting in `wait`: the simulator for
/// systems without ptys, and for clients that speak pyserial's `socket://`. The wire runs
/// at the bus's host rate ([`Bus::set_host_bps`]).
///
/// Errors: the address cannot be listened on or the thread cannot be started.
pub fn spawn_tcp(
    bus: Bus,
    addr: std::net::SocketAddr,
    wait: WaitMode,
) -> Result<Endpoint, LinkError> {
    let server = TcpServer::bind(addr, bus.host_bps())?;
    Endpoint::spawn_tcp(bus, server, wait)
        .map_err(|e| LinkError::io("starting the wCK endpoint", e))
}

/// CPU time of the calling thread.
#[cfg(target_os = "linux")]
fn thread_cpu() -> Duration {
    use nix::sys::resource::{UsageWho, getrusage};
    getrusage(UsageWho::RUSAGE_THREAD).map_or(Duration::ZERO, |u| {
        let tv = |t: nix::sys::time::TimeVal| {
            let secs = u64::try_from(t.tv_sec()).unwrap_or(0);
            let micros = u64::try_from(t.tv_usec()).unwrap_or(0);
            Duration::from_secs(secs) + Duration::from_micros(micros)
        };
        tv(u.user_time()) + tv(u.system_time())
    })
}

/// CPU time of the calling thread (not measured on this system).
#[cfg(not(target_os = "linux"))]
const fn thread_cpu() -> Duration {
    Duration::ZERO
}

/// A little past the instant there is room again, so one wake-up finds it.
const BYTE_SLACK: Duration = Duration::from_micros(100);

/// How many 8N1 bytes (10 bits each) the wire carries in `d` at `bps`.
fn bytes_in(d: Duration, bps: u32) -> usize {
    let bits = d.as_nanos() * u128::from(bps) / 1_000_000_000;
    usize::try_from(bits / 10).unwrap_or(usize::MAX)
}

#[cfg(unix)]
fn follow_client_baud(bus: &mut Bus, termios: Option<&TermiosFd>) {
    if let Some(fd) = termios
        && let Ok(Some(bps)) = termios_speed(fd)
    {
        bus.set_host_bps(bps);
    }
}

#[cfg(not(unix))]
const fn follow_client_baud(_bus: &mut Bus, _termios: Option<&TermiosFd>) {}

/// Runs the model ahead of the present, through the events before `wire_free` (the end
/// of the client's bytes already on the simulated wire), until a reply byte is on its way
/// to the client: one wake-up for that byte instead of one per byte a module receives.
/// The client cannot change that stretch: bytes it writes meanwhile go on the wire after
/// `wire_free` anyway. Reply bytes are still written no earlier than their instant.
fn run_ahead(bus: &mut Bus, wire_free: Duration) {
    while bus.peek_received().is_none() {
        match bus.next_event() {
            Some(t) if t <= wire_free => bus.advance(t.max(bus.now() + Duration::from_nanos(100))),
            _ => break,
        }
    }
}

fn serve<L: ByteLink>(
    mut bus: Bus,
    mut master: L,
    termios: Option<&TermiosFd>,
    stop: &AtomicBool,
    jobs: &mpsc::Receiver<Job>,
    wait: WaitMode,
) -> Result<EndpointStats, EndpointError> {
    // Wake-ups as close to the requested instant as the kernel allows.
    #[cfg(target_os = "linux")]
    let _ = nix::sys::prctl::set_timerslack(1);
    let cpu0 = thread_cpu();
    let t0 = Instant::now();
    let offset = bus.now();
    let sim_now = || offset + t0.elapsed();
    let mut stats = EndpointStats {
        wait,
        ..EndpointStats::default()
    };
    let mut lateness = Lateness::new();
    let mut buf = [0u8; 512];
    let mut out: Vec<u8> = Vec::with_capacity(64);
    let mut next_baud_check = Duration::ZERO;
    let mut wire_free = Duration::ZERO;
    while !stop.load(Ordering::Relaxed) {
        stats.wakeups += 1;
        let now = sim_now();
        while let Ok(job) = jobs.try_recv() {
            bus.advance(now);
            job(&mut bus);
        }
        if now >= next_baud_check {
            follow_client_baud(&mut bus, termios);
            next_baud_check = now + IDLE;
        }
        bus.advance(now);
        out.clear();
        while let Some((due, byte)) = bus.peek_received().filter(|&(due, _)| due <= now) {
            bus.pop_received();
            let late = now.saturating_sub(due);
            stats.late_max = stats.late_max.max(late);
            stats.late_total += late;
            lateness.record(late);
            out.push(byte);
        }
        if !out.is_empty() {
            master.write_all(&out)?;
            stats.bytes_out += out.len() as u64;
        }
        run_ahead(&mut bus, wire_free);
        let due = bus.peek_received().map(|(due, _)| due);
        let next = match (due, bus.next_event()) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        };
        let wake = next.map_or(now + IDLE, |t| t.min(now + IDLE));
        // Wire time still ahead for the bytes already taken: read again only once it is
        // below INPUT_AHEAD, and only as many bytes as fit in the rest of that window.
        let ahead = wire_free.saturating_sub(now);
        if ahead >= INPUT_AHEAD {
            let until = wake.min(wire_free.saturating_sub(INPUT_AHEAD) + BYTE_SLACK);
            let until = t0 + until.saturating_sub(offset);
            if wait.spins() {
                while Instant::now() < until {
                    core::hint::spin_loop();
                }
            } else {
                std::thread::sleep(until.saturating_duration_since(Instant::now()));
            }
            continue;
        }
        let room = bytes_in(INPUT_AHEAD.saturating_sub(ahead), bus.host_bps()).clamp(1, buf.len());
        let deadline = t0 + wake.saturating_sub(offset);
        // A request may come at any time: in the precise mode the pty is polled from now
        // on, and the wait for the next release ends on time.
        let input = buf.get_mut(..room).unwrap_or_default();
        match wait::read_some(&mut master, input, deadline, Instant::now(), wait) {
            Ok(n) => {
                let at = sim_now();
                bus.advance(at);
                follow_client_baud(&mut bus, termios);
                wire_free = bus.host_send(at, buf.get(..n).unwrap_or_default());
                stats.bytes_in += n as u64;
            }
            Err(LinkError::Timeout { .. }) => {}
            Err(e) => return Err(e.into()),
        }
    }
    stats.wall = t0.elapsed();
    stats.lateness = lateness.summary();
    stats.cpu = thread_cpu().saturating_sub(cpu0);
    Ok(stats)
}
