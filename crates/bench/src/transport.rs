//! The transports' own round trip, with nothing simulated: a byte through the pty, or over
//! TCP on 127.0.0.1, and straight back (wCK), a frame through the in-process memory bus
//! and straight back (WHJ), both sides spinning. What a request/reply loop over that transport loses per
//! transaction at the least, whatever the client and the simulator do.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use robobus_link::{ByteLink, FrameLink, MemoryBus, TcpServer, WaitMode, wait};
#[cfg(unix)]
use robobus_link::{PtyOptions, PtyPair};
use robobus_whj::CanFrame;

use crate::BenchError;
use crate::stats::Summary;

/// `n` one-byte round trips through a pty: not on this system (it has no ptys).
#[cfg(not(unix))]
pub fn pty_echo(_n: usize) -> Result<Summary, BenchError> {
    Err(BenchError::new(
        "opening a pty",
        "this system has no pseudo-terminals (the benchmarks measure on Linux)",
    ))
}

/// `n` one-byte round trips through a pty: the client writes to the slave, an echo
/// thread spinning on the master writes the byte back, the client spins until it is in.
#[cfg(unix)]
pub fn pty_echo(n: usize) -> Result<Summary, BenchError> {
    let PtyPair {
        master, mut slave, ..
    } = PtyPair::open(&PtyOptions::default()).map_err(|e| BenchError::new("opening a pty", e))?;
    byte_echo(&mut slave, master, n, "pty echo")
}

/// `n` one-byte round trips over TCP on 127.0.0.1: the client ([`TcpByteLink`](robobus_link::TcpByteLink), as
/// `--port socket://...` opens it) writes a byte, an echo thread spinning on the
/// simulator's side ([`TcpServer`]) writes it back, the client spins until it is in.
pub fn tcp_echo(n: usize) -> Result<Summary, BenchError> {
    let any_port = std::net::SocketAddr::from((std::net::Ipv4Addr::LOCALHOST, 0));
    let server = TcpServer::bind(any_port, 115_200).map_err(|e| BenchError::new("listening", e))?;
    let mut client = server
        .port_spec()
        .open(115_200)
        .map_err(|e| BenchError::new("connecting", e))?;
    byte_echo(&mut *client, server, n, "TCP echo")
}

/// `n` one-byte round trips from `near` to `far` and back: an echo thread spinning on `far`
/// writes every byte back, `near` spins until it is in (a failure is `what`'s).
fn byte_echo<N, F>(near: &mut N, mut far: F, n: usize, what: &str) -> Result<Summary, BenchError>
where
    N: ByteLink + ?Sized,
    F: ByteLink + Send + 'static,
{
    let stop = Arc::new(AtomicBool::new(false));
    let flag = Arc::clone(&stop);
    let echo = std::thread::spawn(move || {
        let mut b = [0u8; 16];
        while !flag.load(Ordering::Relaxed) {
            let now = Instant::now();
            let deadline = now + Duration::from_millis(10);
            if let Ok(k) = wait::read_some(&mut far, &mut b, deadline, now, WaitMode::SPIN)
                && far.write_all(b.get(..k).unwrap_or_default()).is_err()
            {
                return;
            }
        }
    });
    let mut rtt = Vec::with_capacity(n);
    let mut b = [0u8; 1];
    let mut result = Ok(());
    for i in 0..n {
        let t0 = Instant::now();
        #[allow(clippy::cast_possible_truncation)] // any byte will do
        let byte = [i as u8];
        if let Err(e) = near.write_all(&byte).and_then(|()| {
            wait::read_some(
                near,
                &mut b,
                t0 + Duration::from_secs(1),
                t0,
                WaitMode::SPIN,
            )
        }) {
            result = Err(BenchError::new(what, e));
            break;
        }
        rtt.push(t0.elapsed());
    }
    stop.store(true, Ordering::Relaxed);
    let _ = echo.join();
    result.map(|()| Summary::of(&rtt))
}

/// `n` frame round trips through the in-process memory bus: one endpoint sends, an echo
/// thread spinning on another sends the frame back, the first spins until it is in.
pub fn memory_echo(n: usize) -> Result<Summary, BenchError> {
    let wire = MemoryBus::new();
    let mut host = wire.endpoint();
    let mut far = wire.endpoint();
    let stop = Arc::new(AtomicBool::new(false));
    let flag = Arc::clone(&stop);
    let echo = std::thread::spawn(move || {
        while !flag.load(Ordering::Relaxed) {
            let now = Instant::now();
            if let Ok(rx) = wait::recv(
                &mut far,
                now + Duration::from_millis(10),
                now,
                WaitMode::SPIN,
            ) {
                let back = CanFrame::standard_id(0x501)
                    .and_then(|id| CanFrame::new_fd(id, rx.frame.data()));
                if let Ok(f) = back
                    && far.send(&f).is_err()
                {
                    return;
                }
            }
        }
    });
    let frame = CanFrame::standard_id(0x201)
        .and_then(|id| CanFrame::new_fd(id, &[0, 0, 0, 0]))
        .map_err(|e| BenchError::msg(format!("test frame: {e:?}")))?;
    let mut rtt = Vec::with_capacity(n);
    let mut result = Ok(());
    for _ in 0..n {
        let t0 = Instant::now();
        if let Err(e) = host
            .send(&frame)
            .and_then(|()| wait::recv(&mut host, t0 + Duration::from_secs(1), t0, WaitMode::SPIN))
        {
            result = Err(BenchError::new("memory bus echo", e));
            break;
        }
        rtt.push(t0.elapsed());
    }
    stop.store(true, Ordering::Relaxed);
    let _ = echo.join();
    result.map(|()| Summary::of(&rtt))
}
