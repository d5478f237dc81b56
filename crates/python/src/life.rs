//! What a station is alive for: its process and whether it is closed, shared by the
//! station and everything made from it (telemetry streams, cyclic loops, handles), with
//! what runs on it (streams, loops, requests under way) so that closing it stops them all
//! first.
//!
//! - Every call checks [`Life::check`] first: on a closed station it raises naming the
//!   call, in a forked child (the pid is not the one the station was opened in) it raises
//!   at once, saying to open a new station in the child: the serial ports, sockets, locks
//!   and threads of the station belong to the parent (its threads do not exist in the
//!   child, so waiting on one would hang).
//! - [`Life::close`] marks the station closed and stops what runs on it: each stream
//!   (its thread joined, so it lets go of the station), each loop (its thread joined, so it
//!   lets go of the bus), each request under way (through its stop token: it brings its
//!   devices to its safe state). A stream, loop or request started after that is refused.
//! - In a forked child nothing of the parent's is stopped, closed or joined, not even on
//!   drop: the objects are leaked there ([`Life::forked`]).

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard, RwLock, Weak};

use pyo3::prelude::*;
use robobus::ErrorKind;
use robobus::ops::StopToken;
use robobus::station::cyclic::CyclicLoop;

use crate::raise;

/// A running stream's cell, as the station's registry sees it.
pub(crate) type StreamCell = Mutex<Option<crate::telemetry::Stream>>;
/// A running loop's cell.
pub(crate) type LoopCell = RwLock<CyclicLoop>;

/// Whether this process was forked from another since the module was loaded (set in the
/// child by [`after_fork_in_child`]; a fork's fork inherits it).
static FORKED: AtomicBool = AtomicBool::new(false);

/// Python's fork hook in the child (`os.register_at_fork(after_in_child=...)`, registered
/// when the module is loaded): it runs after every fork Python makes or is told of
/// (`os.fork`, `multiprocessing`'s fork and forkserver children, a C extension that calls
/// `PyOS_AfterFork_Child`). From then on [`Life::forked`] compares process ids; before it,
/// every call is spared that system call.
#[pyfunction]
#[pyo3(name = "_after_fork_in_child")]
pub(crate) fn after_fork_in_child() {
    FORKED.store(true, Ordering::Relaxed);
}

/// Whether this process is a fork of process `pid` (see [`after_fork_in_child`]).
pub(crate) fn forked_from(pid: u32) -> bool {
    FORKED.load(Ordering::Relaxed) && pid != std::process::id()
}

/// Registers [`after_fork_in_child`] with Python's fork hooks.
pub(crate) fn watch_forks(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let hook = wrap_pyfunction!(after_fork_in_child, m)?;
    let kwargs = pyo3::types::PyDict::new(m.py());
    kwargs.set_item("after_in_child", hook)?;
    m.py()
        .import("os")?
        .getattr("register_at_fork")?
        .call((), Some(&kwargs))?;
    Ok(())
}

#[derive(Debug, Default)]
struct State {
    closed: bool,
    next_run: u64,
    /// Requests under way: an id and the stop token of each.
    runs: Vec<(u64, StopToken)>,
    streams: Vec<Weak<StreamCell>>,
    loops: Vec<Weak<LoopCell>>,
}

/// See the [module docs](self).
#[derive(Debug)]
pub(crate) struct Life {
    pid: u32,
    /// `state.closed`, read without the lock: a forked child may have inherited the lock
    /// held by one of the parent's threads.
    closed: AtomicBool,
    state: Mutex<State>,
    /// Read-only, arming and the write rate: the library's one admission, for the
    /// station and everything made from it.
    pub(crate) admission: robobus::frontend::Admission,
}

/// A request under way, registered until it is dropped.
pub(crate) struct Running<'a> {
    life: &'a Life,
    id: u64,
}

impl Drop for Running<'_> {
    fn drop(&mut self) {
        self.life.lock().runs.retain(|(id, _)| *id != self.id);
    }
}

impl Life {
    /// A station opened now, in this process: armed unless `read_only` (a script is its
    /// own operator; it disarms with `Station.disarm()`).
    pub(crate) fn new(read_only: bool) -> Arc<Self> {
        let admission = robobus::frontend::Admission::new(
            robobus::frontend::FrontEnd {
                name: "this station".into(),
                read_only_how: "opened with read_only=True".into(),
                arm_how: "station.arm()".into(),
            },
            read_only,
        );
        if !read_only {
            let _ = admission.arm();
        }
        Arc::new(Self {
            pid: std::process::id(),
            closed: AtomicBool::new(false),
            state: Mutex::new(State::default()),
            admission,
        })
    }

    fn lock(&self) -> MutexGuard<'_, State> {
        self.state
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    /// Whether this process is a fork of the one the station was opened in. The process
    /// id is asked (a system call) only once a fork was seen ([`after_fork_in_child`]).
    pub(crate) fn forked(&self) -> bool {
        forked_from(self.pid)
    }

    /// Whether the station was closed.
    pub(crate) fn closed(&self) -> bool {
        self.closed.load(Ordering::SeqCst)
    }

    /// The refusal of `call` in a forked child, if this is one.
    pub(crate) fn fork_error(&self, py: Python<'_>, call: &str, what: &str) -> Option<PyErr> {
        self.forked()
            .then(|| forked_error(py, call, what, self.pid))
    }

    /// `Ok` when `call` may go on: the station is open and this is its process.
    pub(crate) fn check(&self, py: Python<'_>, call: &str) -> PyResult<()> {
        if let Some(e) = self.fork_error(py, call, "station") {
            return Err(e);
        }
        if self.closed() {
            return Err(closed_error(py, call));
        }
        Ok(())
    }

    /// Registers a request under way with its stop token (stopped by `close`); refused on
    /// a closed station.
    pub(crate) fn running(
        &self,
        py: Python<'_>,
        call: impl FnOnce() -> String,
        stop: &StopToken,
    ) -> PyResult<Running<'_>> {
        let mut s = self.lock();
        if s.closed {
            drop(s);
            return Err(closed_error(py, &call()));
        }
        s.next_run += 1;
        let id = s.next_run;
        s.runs.push((id, stop.clone()));
        Ok(Running { life: self, id })
    }

    /// Registers a stream; on a closed station it is stopped and `call` refused.
    pub(crate) fn adopt_stream(
        &self,
        py: Python<'_>,
        call: &str,
        stream: &Arc<StreamCell>,
    ) -> PyResult<()> {
        let mut s = self.lock();
        if s.closed {
            drop(s);
            let t = take(stream);
            py.detach(|| drop(t));
            return Err(closed_error(py, call));
        }
        s.streams.retain(|w| w.strong_count() > 0);
        s.streams.push(Arc::downgrade(stream));
        Ok(())
    }

    /// Registers a loop; on a closed station it is stopped and `call` refused.
    pub(crate) fn adopt_loop(
        &self,
        py: Python<'_>,
        call: &str,
        cyclic: &Arc<LoopCell>,
    ) -> PyResult<()> {
        let mut s = self.lock();
        if s.closed {
            drop(s);
            py.detach(|| stop_loop(cyclic));
            return Err(closed_error(py, call));
        }
        s.loops.retain(|w| w.strong_count() > 0);
        s.loops.push(Arc::downgrade(cyclic));
        Ok(())
    }

    /// Marks the station closed and stops everything running on it (see the [module
    /// docs](self)); whether it was open. Call it without the GIL: it joins threads.
    pub(crate) fn close(&self) -> bool {
        let (runs, streams, loops) = {
            let mut s = self.lock();
            if s.closed {
                return false;
            }
            s.closed = true;
            self.closed.store(true, Ordering::SeqCst);
            (
                std::mem::take(&mut s.runs),
                std::mem::take(&mut s.streams),
                std::mem::take(&mut s.loops),
            )
        };
        for (_, stop) in &runs {
            stop.stop();
        }
        for cell in streams.iter().filter_map(Weak::upgrade) {
            drop(take(&cell));
        }
        for cell in loops.iter().filter_map(Weak::upgrade) {
            stop_loop(&cell);
        }
        true
    }
}

fn take(cell: &StreamCell) -> Option<crate::telemetry::Stream> {
    cell.lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
        .take()
}

fn stop_loop(cell: &LoopCell) {
    cell.write()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
        .stop();
}

/// The refusal of `call` on a closed station.
pub(crate) fn closed_error(py: Python<'_>, call: &str) -> PyErr {
    raise(
        py,
        ErrorKind::BadInput,
        &format!("{call}: the station is closed; open a new one; nothing was sent"),
        None,
    )
}

/// The refusal of `call` on a `what` opened in process `pid`, in a fork of it.
pub(crate) fn forked_error(py: Python<'_>, call: &str, what: &str, pid: u32) -> PyErr {
    raise(
        py,
        ErrorKind::Refused,
        &format!(
            "{call}: this {what} was opened in process {pid} and this is process {}, a fork \
             of it: its ports, threads and locks belong to that process; open a new {what} \
             in this one (with multiprocessing, in the child's target); nothing was sent",
            std::process::id()
        ),
        None,
    )
}
