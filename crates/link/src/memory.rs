//! In-memory links for deterministic tests: a byte pipe pair and a CAN FD bus.

use std::collections::VecDeque;
use std::sync::{Arc, Condvar, Mutex, MutexGuard, PoisonError};
use std::time::{Duration, Instant, SystemTime};

use robobus_whj::frame::CanFrame;

use crate::byte::{ByteLink, LinkError};
use crate::frame_link::{FrameLink, FrameLinkError, IdFilter, Received, passes};

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    // A panicking test thread must not wedge the other side: the data stays usable.
    m.lock().unwrap_or_else(PoisonError::into_inner)
}

/// Waits on `cv` until `deadline`; returns the guard and whether the deadline passed.
fn wait_until<'a, T>(
    cv: &Condvar,
    guard: MutexGuard<'a, T>,
    deadline: Instant,
) -> (MutexGuard<'a, T>, bool) {
    let now = Instant::now();
    if now >= deadline {
        return (guard, true);
    }
    let (g, _) = cv
        .wait_timeout(guard, deadline - now)
        .unwrap_or_else(PoisonError::into_inner);
    (g, Instant::now() >= deadline)
}

#[derive(Debug, Default)]
struct Pipe {
    bytes: VecDeque<u8>,
    writer_gone: bool,
}

#[derive(Debug, Default)]
struct PipeShared {
    pipe: Mutex<Pipe>,
    cv: Condvar,
}

/// One end of an in-memory byte pipe pair (see [`MemoryByteLink::pair`]).
///
/// Bytes written on one end are read on the other, instantly and in order. When an end is
/// dropped, the other end reads what is left and then gets [`LinkError::Closed`].
#[derive(Debug)]
pub struct MemoryByteLink {
    rx: Arc<PipeShared>,
    tx: Arc<PipeShared>,
    baud: u32,
}

impl MemoryByteLink {
    /// A connected pair of ends (both start at 115200 baud, which only gets recorded).
    pub fn pair() -> (Self, Self) {
        let a = Arc::new(PipeShared::default());
        let b = Arc::new(PipeShared::default());
        (
            Self {
                rx: Arc::clone(&a),
                tx: Arc::clone(&b),
                baud: 115_200,
            },
            Self {
                rx: b,
                tx: a,
                baud: 115_200,
            },
        )
    }

    /// Bytes waiting to be read on this end.
    pub fn pending(&self) -> usize {
        lock(&self.rx.pipe).bytes.len()
    }
}

impl Drop for MemoryByteLink {
    fn drop(&mut self) {
        lock(&self.tx.pipe).writer_gone = true;
        self.tx.cv.notify_all();
    }
}

impl ByteLink for MemoryByteLink {
    fn write_all(&mut self, bytes: &[u8]) -> Result<(), LinkError> {
        // The peer's read side is `tx`; a dropped peer no longer holds `tx` as its `rx`.
        if Arc::strong_count(&self.tx) < 2 {
            return Err(LinkError::Closed {
                context: "memory byte link: peer dropped".into(),
            });
        }
        lock(&self.tx.pipe).bytes.extend(bytes);
        self.tx.cv.notify_all();
        Ok(())
    }

    fn read_some(&mut self, buf: &mut [u8], deadline: Instant) -> Result<usize, LinkError> {
        if buf.is_empty() {
            return Ok(0);
        }
        let mut pipe = lock(&self.rx.pipe);
        loop {
            if !pipe.bytes.is_empty() {
                let n = buf.len().min(pipe.bytes.len());
                for (slot, b) in buf.iter_mut().zip(pipe.bytes.drain(..n)) {
                    *slot = b;
                }
                return Ok(n);
            }
            if pipe.writer_gone {
                return Err(LinkError::Closed {
                    context: "memory byte link: peer dropped".into(),
                });
            }
            let (g, expired) = wait_until(&self.rx.cv, pipe, deadline);
            pipe = g;
            if expired && pipe.bytes.is_empty() {
                return Err(LinkError::Timeout {
                    received: 0,
                    expected: buf.len(),
                });
            }
        }
    }

    fn discard_input(&mut self) -> Result<(), LinkError> {
        lock(&self.rx.pipe).bytes.clear();
        Ok(())
    }

    fn set_baud(&mut self, baud: u32) -> Result<(), LinkError> {
        if baud == 0 {
            return Err(LinkError::UnsupportedBaud {
                baud,
                context: "memory byte link".into(),
            });
        }
        self.baud = baud;
        Ok(())
    }

    fn baud(&self) -> Option<u32> {
        Some(self.baud)
    }
}

#[derive(Debug)]
struct Inbox {
    id: u64,
    frames: VecDeque<Received>,
    filters: Vec<IdFilter>,
    loopback: bool,
}

#[derive(Debug, Default)]
struct BusState {
    next_id: u64,
    inboxes: Vec<Inbox>,
}

#[derive(Debug, Default)]
struct BusShared {
    state: Mutex<BusState>,
    cv: Condvar,
}

/// An in-memory CAN FD bus: every frame sent by one endpoint reaches every other endpoint
/// (and the sender too if it asked for loopback), in send order, instantly.
///
/// ```
/// use std::time::{Duration, Instant};
/// use robobus_link::{FrameLink, MemoryBus};
/// use robobus_whj::CanFrame;
///
/// let bus = MemoryBus::new();
/// let (mut a, mut b) = (bus.endpoint(), bus.endpoint());
/// let frame = CanFrame::new_fd(CanFrame::standard_id(0x7)?, &[1, 2, 3, 4])?;
/// a.send(&frame)?;
/// let got = b.recv(Instant::now() + Duration::from_secs(1))?;
/// assert_eq!(got.frame, frame);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
#[derive(Debug, Clone, Default)]
pub struct MemoryBus {
    shared: Arc<BusShared>,
}

impl MemoryBus {
    /// A bus with no endpoints.
    pub fn new() -> Self {
        Self::default()
    }

    /// A new endpoint that does not receive its own frames.
    pub fn endpoint(&self) -> MemoryBusEndpoint {
        self.endpoint_with_loopback(false)
    }

    /// A new endpoint; with `loopback` it also receives the frames it sends.
    pub fn endpoint_with_loopback(&self, loopback: bool) -> MemoryBusEndpoint {
        let mut st = lock(&self.shared.state);
        let id = st.next_id;
        st.next_id += 1;
        st.inboxes.push(Inbox {
            id,
            frames: VecDeque::new(),
            filters: Vec::new(),
            loopback,
        });
        MemoryBusEndpoint {
            shared: Arc::clone(&self.shared),
            id,
        }
    }

    /// How many endpoints are attached.
    pub fn endpoint_count(&self) -> usize {
        lock(&self.shared.state).inboxes.len()
    }
}

/// One node on a [`MemoryBus`]. Dropping it detaches it from the bus.
#[derive(Debug)]
pub struct MemoryBusEndpoint {
    shared: Arc<BusShared>,
    id: u64,
}

impl MemoryBusEndpoint {
    /// Frames waiting to be received (after filtering).
    pub fn pending(&self) -> usize {
        let st = lock(&self.shared.state);
        st.inboxes
            .iter()
            .find(|i| i.id == self.id)
            .map_or(0, |i| i.frames.len())
    }
}

impl Drop for MemoryBusEndpoint {
    fn drop(&mut self) {
        lock(&self.shared.state).inboxes.retain(|i| i.id != self.id);
    }
}

impl FrameLink for MemoryBusEndpoint {
    fn send(&mut self, frame: &CanFrame) -> Result<(), FrameLinkError> {
        let timestamp = Some(SystemTime::now());
        let mut st = lock(&self.shared.state);
        for inbox in &mut st.inboxes {
            if (inbox.id != self.id || inbox.loopback) && passes(&inbox.filters, frame) {
                inbox.frames.push_back(Received {
                    frame: *frame,
                    timestamp,
                });
            }
        }
        drop(st);
        self.shared.cv.notify_all();
        Ok(())
    }

    fn recv(&mut self, deadline: Instant) -> Result<Received, FrameLinkError> {
        let mut st = lock(&self.shared.state);
        loop {
            let inbox = st
                .inboxes
                .iter_mut()
                .find(|i| i.id == self.id)
                .ok_or_else(|| FrameLinkError::Closed {
                    context: "memory bus endpoint detached".into(),
                })?;
            if let Some(r) = inbox.frames.pop_front() {
                return Ok(r);
            }
            let (g, expired) = wait_until(&self.shared.cv, st, deadline);
            st = g;
            if expired {
                let inbox = st.inboxes.iter_mut().find(|i| i.id == self.id);
                return inbox
                    .and_then(|i| i.frames.pop_front())
                    .ok_or(FrameLinkError::Timeout);
            }
        }
    }

    /// Zero: a frame is in every other endpoint's queue, behind the ones sent before it,
    /// the instant it is sent.
    fn reply_allowance(&self) -> Duration {
        Duration::ZERO
    }

    fn set_filters(&mut self, filters: &[IdFilter]) -> Result<(), FrameLinkError> {
        let mut st = lock(&self.shared.state);
        if let Some(inbox) = st.inboxes.iter_mut().find(|i| i.id == self.id) {
            inbox.filters = filters.to_vec();
            // Frames already queued are filtered too, as a kernel socket filter would not
            // have let them in.
            let f = inbox.filters.clone();
            inbox.frames.retain(|r| passes(&f, &r.frame));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use std::time::Duration;

    use super::*;

    fn fd(id: u16, data: &[u8]) -> CanFrame {
        CanFrame::new_fd(CanFrame::standard_id(id).unwrap(), data).unwrap()
    }

    #[test]
    fn byte_pair_moves_bytes_both_ways_and_reports_close() {
        let (mut a, mut b) = MemoryByteLink::pair();
        a.write_all(&[1, 2, 3]).unwrap();
        b.write_all(&[9]).unwrap();
        let mut buf = [0; 3];
        b.read_exact(&mut buf, Instant::now() + Duration::from_secs(1))
            .unwrap();
        assert_eq!(buf, [1, 2, 3]);
        let mut one = [0; 1];
        a.read_exact(&mut one, Instant::now()).unwrap();
        assert_eq!(one, [9]);
        a.write_all(&[4, 5]).unwrap();
        let err = b
            .read_exact(&mut buf, Instant::now() + Duration::from_millis(20))
            .unwrap_err();
        assert!(
            matches!(
                err,
                LinkError::Timeout {
                    received: 2,
                    expected: 3
                }
            ),
            "{err:?}"
        );
        assert_eq!(&buf[..2], &[4, 5]);
        a.write_all(&[6]).unwrap();
        b.discard_input().unwrap();
        assert_eq!(b.pending(), 0);
        drop(a);
        assert!(matches!(
            b.read_some(&mut buf, Instant::now()),
            Err(LinkError::Closed { .. })
        ));
        assert!(matches!(b.write_all(&[1]), Err(LinkError::Closed { .. })));
    }

    #[test]
    fn bus_delivers_to_every_other_endpoint_with_filters_and_loopback() {
        let bus = MemoryBus::new();
        let mut a = bus.endpoint();
        let mut b = bus.endpoint();
        let mut c = bus.endpoint_with_loopback(true);
        c.set_filters(&[IdFilter::standard(0x10)]).unwrap();
        a.send(&fd(0x10, &[1])).unwrap();
        a.send(&fd(0x11, &[2])).unwrap();
        c.send(&fd(0x10, &[3])).unwrap();
        let soon = Instant::now() + Duration::from_millis(50);
        assert_eq!(b.recv(soon).unwrap().frame, fd(0x10, &[1]));
        assert_eq!(b.recv(soon).unwrap().frame, fd(0x11, &[2]));
        assert_eq!(b.recv(soon).unwrap().frame, fd(0x10, &[3]));
        assert_eq!(c.recv(soon).unwrap().frame, fd(0x10, &[1]));
        assert_eq!(c.recv(soon).unwrap().frame, fd(0x10, &[3]));
        assert!(c.recv(soon).unwrap_err().is_timeout());
        assert_eq!(a.recv(soon).unwrap().frame, fd(0x10, &[3]));
        assert!(a.recv(Instant::now()).unwrap_err().is_timeout());
        assert_eq!(bus.endpoint_count(), 3);
        drop(c);
        assert_eq!(bus.endpoint_count(), 2);
    }

    #[test]
    fn bus_recv_wakes_when_a_frame_arrives_from_another_thread() {
        let bus = MemoryBus::new();
        let mut a = bus.endpoint();
        let mut b = bus.endpoint();
        let t = std::thread::spawn(move || {
            std::thread::sleep(Duration::from_millis(20));
            a.send(&fd(0x1, &[7; 64])).unwrap();
        });
        let got = b.recv(Instant::now() + Duration::from_secs(5)).unwrap();
        assert_eq!(got.frame.data(), &[7; 64]);
        t.join().unwrap();
    }
}
