//! The native part of the `robobus` Python package: the library's
//! [`Station`](robobus::station::Station), the catalogue's dispatcher and its telemetry stream, with requests and reports as Python dicts in the
//! catalogue's JSON form. The Python side (`python/robobus`) adds the methods generated
//! from the request schema, the exception classes and the type stubs.
//!
//! - Every call that waits on a device releases the GIL, and runs on the calling thread
//!   (no hand-off to another thread).
//! - On the main thread a request's stop token polls Python's signals
//!   ([`StopToken::with_poll`]): whenever the operation checks its token (between steps, and
//!   every 5 ms while it waits), at most once per `SIGNAL_SLICE` (10 ms), the GIL is taken back for
//!   `check_signals`. Ctrl-C so stops the request (the operation brings its devices to their
//!   safe state) and raises `KeyboardInterrupt` once it has; a short request never polls.
//!   An operation sees the signal at its next check (a long move's planning looks every
//!   4096 frames), and a CPU-bound Python thread can delay a poll by up to the
//!   interpreter's switch interval (5 ms) while it holds the GIL. Handle calls do not poll:
//!   each is a few transactions, bounded by the devices' reply timeouts.
//!   Python's own SIGINT handler stays in place; no handler is installed here.
//! - Requests come in as dicts written natively as JSON text (bounded: at most
//!   [`MAX_REQUEST_BYTES`](robobus::frontend::parse::MAX_REQUEST_BYTES) and `MAX_DEPTH` (32)
//!   levels), or as JSON text, parsed once by the library's parser; reports and the handles' results
//!   are Python objects built here (`pyser`: what `json.loads` of the report's JSON text
//!   would give, without the text).
//! - Errors are raised as `robobus.errors` classes chosen by the error kind, with the
//!   library's message.
//! - The library's log events go to Python's `logging` (pyo3-log).
//! - A station and everything made from it share its `Life` (`life.rs`): closing (or dropping)
//!   it stops its streams, loops and requests under way before its devices go to their
//!   safe state and its ports are released; every later call raises naming the call, and a
//!   forked child is refused at once.

// OpError carries the client errors by value, as the library returns them.
#![allow(clippy::result_large_err)]

use std::sync::{Arc, Mutex, OnceLock};
use std::thread::ThreadId;
use std::time::{Duration, Instant};

use pyo3::prelude::*;
use pyo3::types::PyString;
use robobus::ErrorKind;
use robobus::catalogue::{self, Request};
use robobus::frontend::Wording;
use robobus::ops::{Control, OpError, StopToken};
use robobus::station::StationConfig;

mod handles;
mod life;
mod pyser;
mod telemetry;

use life::{Life, LoopCell, closed_error};

/// How often a wait (or a request's stop token) on the main thread looks at Python's
/// signals.
const SIGNAL_SLICE: Duration = Duration::from_millis(10);

/// How deep a request's dicts and lists may nest.
const MAX_DEPTH: usize = 32;

/// The thread that imported the module: the one Python delivers signals to.
static MAIN: OnceLock<ThreadId> = OnceLock::new();

fn on_main_thread() -> bool {
    MAIN.get() == Some(&std::thread::current().id())
}

/// The `robobus.errors` class of `kind`, raised with `message` (and, when a report failed,
/// the report under `.report`).
fn raise(py: Python<'_>, kind: ErrorKind, message: &str, report: Option<Py<PyAny>>) -> PyErr {
    let class = match kind {
        ErrorKind::BadInput => "BadInputError",
        ErrorKind::Refused => "RefusedError",
        ErrorKind::NoDevice => "NoDeviceError",
        ErrorKind::Device => "DeviceError",
        ErrorKind::Link => "LinkError",
        ErrorKind::Interrupted => "StoppedError",
        ErrorKind::NotAvailable => "NotAvailableError",
        _ => "RobobusError",
    };
    let made = py
        .import("robobus.errors")
        .and_then(|m| m.getattr(class))
        .and_then(|c| c.call1((message, kind.name(), report)));
    match made {
        Ok(e) => PyErr::from_value(e),
        Err(e) => e,
    }
}

/// A library error as its class, in Python's wording (a refused argument is named
/// `ids=`, not the command line's `<IDS>`).
fn op_error(py: Python<'_>, e: &OpError) -> PyErr {
    raise(py, e.kind(), &Wording::Python.message(e), None)
}

/// A report (or any serialisable value) as Python objects, built directly (`pyser`): what
/// `json.loads` of its JSON text would give, in its field order.
fn to_py(py: Python<'_>, value: &impl serde::Serialize) -> PyResult<Py<PyAny>> {
    pyser::to_py(py, value).map(Bound::unbind)
}

/// A request from a dict (written as JSON text) or from its JSON text: the library's one
/// parser, its wording.
fn request(py: Python<'_>, value: &Bound<'_, PyAny>) -> PyResult<Request> {
    let parse =
        |text: &str| robobus::frontend::parse::request_text(text).map_err(|e| op_error(py, &e));
    if let Ok(text) = value.cast::<PyString>() {
        return parse(text.to_str()?);
    }
    let mut text = String::with_capacity(128);
    pyser::json_text(py, value, 0, &mut text)?;
    if text.len() > robobus::frontend::parse::MAX_REQUEST_BYTES {
        return Err(too_long(py));
    }
    parse(&text)
}

fn too_long(py: Python<'_>) -> PyErr {
    raise(
        py,
        ErrorKind::BadInput,
        &format!(
            "request: over {} bytes as JSON (the largest request taken); nothing was sent",
            robobus::frontend::parse::MAX_REQUEST_BYTES
        ),
        None,
    )
}

/// How long `close` waits for a call on another thread to let go of the station once it
/// was stopped (it brings its devices to its safe state first).
const CLOSE_WAIT: Duration = Duration::from_secs(10);

/// A stop token for a request run on this thread: on the main thread it also polls
/// Python's signals (at most once per [`SIGNAL_SLICE`], and only when the operation checks
/// its token), keeping the signal's exception in `raised`.
fn signal_token(stop: &StopToken, raised: &Arc<Mutex<Option<PyErr>>>) -> StopToken {
    if !on_main_thread() {
        // Python delivers signals to the main thread only.
        return stop.clone();
    }
    let thread = std::thread::current().id();
    let last = Mutex::new(Instant::now());
    let raised = Arc::clone(raised);
    stop.clone().with_poll(move || {
        if std::thread::current().id() != thread {
            return false;
        }
        {
            let mut last = last
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner);
            if last.elapsed() < SIGNAL_SLICE {
                return false;
            }
            *last = Instant::now();
        }
        Python::attach(|py| match py.check_signals() {
            Ok(()) => false,
            Err(e) => {
                *raised
                    .lock()
                    .unwrap_or_else(std::sync::PoisonError::into_inner) = Some(e);
                true
            }
        })
    })
}

/// The station: the buses a Python session holds (see the module docs of
/// `robobus.Station`).
#[pyclass(module = "robobus._robobus", name = "NativeStation", frozen)]
#[derive(Debug)]
struct NativeStation {
    station: Mutex<Option<Arc<robobus::station::Station>>>,
    /// Its process, whether it is closed, and what runs on it.
    life: Arc<Life>,
    /// The clock its devices run on: `"wall"`, or `"virtual"` (the built-in simulated
    /// robot's, which moves only as the buses are driven).
    clock: &'static str,
}

impl NativeStation {
    /// The station for `call`: refused when it is closed or this is a forked child.
    fn get(&self, py: Python<'_>, call: &str) -> PyResult<Arc<robobus::station::Station>> {
        self.life.check(py, call)?;
        self.station
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .clone()
            .ok_or_else(|| closed_error(py, call))
    }

    fn wrap(station: robobus::station::Station, read_only: bool, clock: &'static str) -> Self {
        Self {
            station: Mutex::new(Some(Arc::new(station))),
            life: Life::new(read_only),
            clock,
        }
    }

    /// Closes it: whatever runs on it stopped (streams, loops, requests on other threads),
    /// then `end` applied to the station once nothing else holds it (its ports released
    /// with it). The failures, one message per device; nothing the second time.
    fn release(
        &self,
        py: Python<'_>,
        call: &str,
        end: impl FnOnce(robobus::station::Station) -> Vec<String> + Send,
    ) -> PyResult<Vec<String>> {
        if let Some(e) = self.life.fork_error(py, call, "station") {
            return Err(e);
        }
        let taken = self
            .station
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .take();
        Ok(py.detach(|| {
            self.life.close();
            let Some(mut station) = taken else {
                return Vec::new();
            };
            let deadline = std::time::Instant::now() + CLOSE_WAIT;
            loop {
                match Arc::try_unwrap(station) {
                    Ok(s) => return end(s),
                    Err(shared) if std::time::Instant::now() >= deadline => {
                        // The last holder closes it when it lets go (the station's drop).
                        drop(shared);
                        return vec![format!(
                            "a call on another thread still holds the station after {} s; \
                             its devices go to their safe state when that call ends",
                            CLOSE_WAIT.as_secs()
                        )];
                    }
                    Err(shared) => {
                        station = shared;
                        std::thread::sleep(Duration::from_millis(1));
                    }
                }
            }
        }))
    }
}

impl Drop for NativeStation {
    /// Dropping the station closes it as `close` does; in a forked child it leaves the
    /// parent's devices, ports and threads alone.
    fn drop(&mut self) {
        let taken = self
            .station
            .get_mut()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .take();
        if self.life.forked() {
            std::mem::forget(taken);
            return;
        }
        let life = &self.life;
        without_gil(|| {
            life.close();
            drop(taken);
        });
    }
}

/// Runs `f` with the GIL released if this thread holds it: a drop that joins a thread
/// (whose log events need the GIL) or sends to devices.
fn without_gil(f: impl FnOnce() + Send) {
    let mut f = Some(f);
    let _ = Python::try_attach(|py| {
        py.detach(|| {
            if let Some(f) = f.take() {
                f();
            }
        });
    });
    // Python is shutting down: here, as it is.
    if let Some(f) = f.take() {
        f();
    }
}

#[pymethods]
#[allow(clippy::needless_pass_by_value, clippy::unused_self)] // pyo3 signatures
impl NativeStation {
    /// The built-in simulated robot, in-process: on the wall clock (`"wall"`: its
    /// simulators move in real time, as the studio's and the bridge's), or on the
    /// simulators' virtual clock (`"virtual"`: time moves only as the buses are driven,
    /// every run the same).
    #[staticmethod]
    #[pyo3(signature = (read_only = false, clock = "wall"))]
    fn simulated(py: Python<'_>, read_only: bool, clock: &str) -> PyResult<Self> {
        let (s, clock) = match clock {
            "wall" => (
                py.detach(|| robobus::station::Station::simulated_live(None).map(|(s, _)| s)),
                "wall",
            ),
            "virtual" => (py.detach(robobus::station::Station::simulated), "virtual"),
            other => {
                return Err(raise(
                    py,
                    ErrorKind::BadInput,
                    &format!(
                        "clock={other:?}: not a clock (allowed: \"wall\", \"virtual\"); \
                         nothing was opened"
                    ),
                    None,
                ));
            }
        };
        let s = s.map_err(|e| op_error(py, &e))?;
        Ok(Self::wrap(s, read_only, clock))
    }

    /// The clock the station's devices run on: `"wall"` (hardware, the simulated robot
    /// by default) or `"virtual"`.
    #[getter]
    fn clock(&self) -> &'static str {
        self.clock
    }

    /// Opens wCK ports, WHJ buses and a robot file from the CLI's address strings.
    #[staticmethod]
    #[pyo3(signature = (wck_ports, whj_buses, robot, wck_baud, reply_margin_ms, wait = "sleep", read_only = false))]
    #[allow(clippy::too_many_arguments)]
    fn open(
        py: Python<'_>,
        wck_ports: Vec<String>,
        whj_buses: Vec<String>,
        robot: Option<std::path::PathBuf>,
        wck_baud: u32,
        reply_margin_ms: Option<f64>,
        wait: &str,
        read_only: bool,
    ) -> PyResult<Self> {
        let wait: robobus::WaitMode = wait.parse().map_err(|e: robobus::WaitModeError| {
            raise(py, ErrorKind::BadInput, &format!("wait: {e}"), None)
        })?;
        let baud = robobus_wck::BaudRate::from_bits_per_second(wck_baud).map_err(|e| {
            raise(
                py,
                ErrorKind::BadInput,
                &format!("wck_baud {wck_baud}: {e}"),
                None,
            )
        })?;
        let margin = match reply_margin_ms {
            None => None,
            Some(ms) if ms.is_finite() && (0.0..=10_000.0).contains(&ms) => {
                Some(Duration::from_secs_f64(ms / 1000.0))
            }
            Some(ms) => {
                return Err(raise(
                    py,
                    ErrorKind::BadInput,
                    &format!("reply_margin_ms {ms}: out of range (allowed: 0..=10000)"),
                    None,
                ));
            }
        };
        let config = StationConfig {
            wck_ports,
            wck_baud: Some(baud),
            whj_buses,
            robot,
            wck_reply_margin: margin,
            wait,
            ..StationConfig::default()
        };
        let s = py
            .detach(|| robobus::station::Station::open(&config))
            .map_err(|e| op_error(py, &e))?;
        Ok(Self::wrap(s, read_only, "wall"))
    }

    /// Arms: motion requests, moves of handles and cyclic loops run (a station opened
    /// without `read_only` starts armed).
    fn arm(&self, py: Python<'_>) -> PyResult<()> {
        self.life.check(py, "Station.arm")?;
        self.life
            .admission
            .arm()
            .map_err(|r| op_error(py, &r.error))
    }

    /// Disarms: motion is refused until `arm`.
    fn disarm(&self, py: Python<'_>) -> PyResult<()> {
        self.life.check(py, "Station.disarm")?;
        self.life.admission.disarm();
        Ok(())
    }

    /// Whether motion is armed.
    #[getter]
    fn armed(&self) -> bool {
        self.life.admission.armed()
    }

    /// Whether it was opened read-only.
    #[getter]
    fn read_only(&self) -> bool {
        self.life.admission.read_only()
    }

    /// Runs one request (a dict in the catalogue's JSON form) and returns its report.
    fn run(&self, py: Python<'_>, request_obj: &Bound<'_, PyAny>) -> PyResult<Py<PyAny>> {
        let req = request(py, request_obj)?;
        // The call's name, for its errors only.
        let call = || format!("Station.run({})", req.op());
        if self.life.forked() || self.life.closed() {
            self.life.check(py, &call())?;
        }
        // Admitted (read-only, arming, the write rate) as every front end admits it, which
        // checks it first as `robobus run` does (bad input said as such before anything
        // is opened or sent). A read-only station refuses a change before that check: it
        // is checked here first, so that bad input is still said as such there.
        if self.life.admission.read_only() && req.effect() != catalogue::Effect::Read {
            catalogue::validate(&req).map_err(|e| op_error(py, &e))?;
        }
        let req = self
            .life
            .admission
            .admit(robobus::frontend::Arming::Local, req)
            .map_err(|r| op_error(py, &r.error))?
            .into_request();
        let call = || format!("Station.run({})", req.op());
        // Open and in this process, checked above; a `close` since is seen here or by
        // `running`.
        let station = self
            .station
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .clone()
            .ok_or_else(|| closed_error(py, &call()))?;
        let stop = StopToken::new();
        // Stopped by a `close` on another thread.
        let running = self.life.running(py, call, &stop)?;
        let raised = Arc::new(Mutex::new(None));
        let token = signal_token(&stop, &raised);
        let outcome = py.detach(move || {
            let r = catalogue::run(&station, &req, &mut Control::new(&token));
            // Let go of the station before the caller hears of the report, so that a
            // `close()` right after it finds the station unshared and closes it.
            drop(station);
            r
        });
        drop(running);
        if let Some(e) = raised
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .take()
        {
            return Err(e);
        }
        let report = outcome.map_err(|e| op_error(py, &e))?;
        to_py(py, &report)
    }

    /// Benchmark: `request` run `n` times by the library alone (parsed, checked and
    /// admitted once, each run in Rust with the GIL released, as `run` runs it); the
    /// seconds each took on average. What `run` adds over it is the bindings' cost.
    #[pyo3(name = "_bench_run")]
    fn bench_run(&self, py: Python<'_>, request_obj: &Bound<'_, PyAny>, n: u32) -> PyResult<f64> {
        let n = bench_count(py, n)?;
        let req = request(py, request_obj)?;
        let call = format!("Station._bench_run({})", req.op());
        catalogue::validate(&req).map_err(|e| op_error(py, &e))?;
        let req = self
            .life
            .admission
            .admit(robobus::frontend::Arming::Local, req)
            .map_err(|r| op_error(py, &r.error))?
            .into_request();
        let station = self.get(py, &call)?;
        let stop = StopToken::new();
        let _running = self.life.running(py, || call.clone(), &stop)?;
        py.detach(move || {
            let start = Instant::now();
            for _ in 0..n {
                catalogue::run(&station, &req, &mut Control::new(&stop))?;
            }
            Ok(start.elapsed().as_secs_f64() / f64::from(n))
        })
        .map_err(|e: robobus::ops::OpError| op_error(py, &e))
    }

    /// Checks a request as `run` will (its arguments against the protocol's ranges and
    /// the host bounds), without a station; nothing is opened or sent.
    #[staticmethod]
    fn validate(py: Python<'_>, request_obj: &Bound<'_, PyAny>) -> PyResult<()> {
        let req = request(py, request_obj)?;
        catalogue::validate(&req).map_err(|e| op_error(py, &e))
    }

    /// The plan of a request: what it would send (nothing is opened).
    #[staticmethod]
    fn plan(py: Python<'_>, request_obj: &Bound<'_, PyAny>) -> PyResult<Py<PyAny>> {
        let req = request(py, request_obj)?;
        let view = robobus::frontend::PlanView::of(&req).map_err(|e| op_error(py, &e))?;
        to_py(py, &view)
    }

    /// The names of the wCK ports and the WHJ buses.
    fn names(&self, py: Python<'_>) -> PyResult<(Vec<String>, Vec<String>)> {
        Ok(self.get(py, "Station.buses")?.names())
    }

    /// Whether the station has a robot file (for `robot.sample`).
    fn has_robot(&self, py: Python<'_>) -> PyResult<bool> {
        Ok(self.get(py, "Station.has_robot")?.robot().is_some())
    }

    /// Closes the station: its telemetry streams and cyclic loops stopped, a request under
    /// way on another thread stopped, then every device to its safe state (the wCK
    /// bus-wide break, every connected WHJ joint disabled) and the ports released. The
    /// failures, one message per device. Closing twice does nothing the second time.
    fn close(&self, py: Python<'_>) -> PyResult<Vec<String>> {
        self.release(py, "Station.close", robobus::station::Station::close)
    }

    /// Closes the station leaving every device as the last request left it (its streams
    /// and loops are stopped all the same).
    fn leave(&self, py: Python<'_>) -> PyResult<()> {
        self.release(py, "Station.leave", |s| {
            s.leave();
            Vec::new()
        })
        .map(drop)
    }

    /// Whether `close` (or `leave`) was called.
    #[getter]
    fn closed(&self) -> bool {
        self.life.closed()
    }

    /// Starts a checked cyclic loop of `mode` targets (`position` deg, `speed` RPM,
    /// `current` mA) for `joints` on the WHJ bus `bus` at `rate_hz`.
    #[pyo3(signature = (joints, mode, rate_hz, bus))]
    fn cyclic(
        &self,
        py: Python<'_>,
        joints: Vec<u8>,
        mode: &str,
        rate_hz: f64,
        bus: Option<String>,
    ) -> PyResult<NativeCyclic> {
        let call = "Station.cyclic";
        let servo = handles::servo_loop(py, mode)?;
        self.life.check(py, call)?;
        self.life
            .admission
            .check_motion(robobus::frontend::Arming::Local, call)
            .map_err(|r| op_error(py, &r.error))?;
        let station = self.get(py, call)?;
        let l = py
            .detach(move || {
                robobus::station::cyclic::CyclicLoop::start(
                    &station,
                    bus.as_deref(),
                    &joints,
                    servo,
                    rate_hz,
                )
            })
            .map_err(|e| op_error(py, &e))?;
        let inner = Arc::new(std::sync::RwLock::new(l));
        self.life.adopt_loop(py, call, &inner)?;
        Ok(NativeCyclic {
            inner,
            life: Arc::clone(&self.life),
        })
    }

    /// wCK servos `ids` on the port `bus` (`None`: the only one); nothing is sent.
    #[pyo3(signature = (ids, bus))]
    fn wck_servos(
        &self,
        py: Python<'_>,
        ids: Vec<u8>,
        bus: Option<String>,
    ) -> PyResult<handles::NativeWckServos> {
        let station = self.get(py, "Station.wck_servos")?;
        robobus::station::handles::WckGroup::new(&station, bus.as_deref(), &ids)
            .map(|inner| handles::NativeWckServos {
                inner,
                life: Arc::clone(&self.life),
            })
            .map_err(|e| op_error(py, &e))
    }

    /// WHJ joints `ids` on the bus `bus` (`None`: the only one), each connected.
    #[pyo3(signature = (ids, bus))]
    fn whj_joints(
        &self,
        py: Python<'_>,
        ids: Vec<u8>,
        bus: Option<String>,
    ) -> PyResult<handles::NativeWhjJoints> {
        let station = self.get(py, "Station.whj_joints")?;
        py.detach(move || robobus::station::handles::WhjGroup::new(&station, bus.as_deref(), &ids))
            .map(|inner| handles::NativeWhjJoints {
                inner,
                life: Arc::clone(&self.life),
            })
            .map_err(|e| op_error(py, &e))
    }

    /// Starts a telemetry stream of a reading request at `rate_hz`.
    #[pyo3(signature = (request_obj, rate_hz, limit, queue))]
    fn telemetry(
        &self,
        py: Python<'_>,
        request_obj: &Bound<'_, PyAny>,
        rate_hz: f64,
        limit: Option<u64>,
        queue: usize,
    ) -> PyResult<telemetry::NativeTelemetry> {
        telemetry::start(self, py, request_obj, rate_hz, limit, queue)
    }
}

/// A checked cyclic loop on one of the station's WHJ buses (the hot path: targets in and
/// feedback out without a request per cycle).
#[pyclass(module = "robobus._robobus", name = "NativeCyclic", frozen)]
#[derive(Debug)]
struct NativeCyclic {
    /// Read-locked by every call but `stop`, so a thread setting targets never waits for
    /// one waiting for a cycle. Shared with the station's registry, which stops it when
    /// the station closes.
    inner: Arc<LoopCell>,
    life: Arc<Life>,
}

impl NativeCyclic {
    fn lock(&self) -> std::sync::RwLockReadGuard<'_, robobus::station::cyclic::CyclicLoop> {
        self.inner
            .read()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }
}

impl Drop for NativeCyclic {
    fn drop(&mut self) {
        if self.life.forked() {
            // The loop's thread is the parent's: nothing to stop or join here.
            std::mem::forget(Arc::clone(&self.inner));
            return;
        }
        let inner = &self.inner;
        without_gil(|| {
            inner
                .write()
                .unwrap_or_else(std::sync::PoisonError::into_inner)
                .stop();
        });
    }
}

/// A cycle as flat columns (what the Python side turns into arrays): `NaN` / `False`
/// where a joint's feedback did not arrive.
fn columns(c: &robobus::station::cyclic::CycleSample) -> serde_json::Value {
    let f = |get: &dyn Fn(&robobus::station::cyclic::JointFeedback) -> serde_json::Value| {
        c.feedback
            .iter()
            .map(|x| x.as_ref().map_or(serde_json::Value::Null, get))
            .collect::<Vec<_>>()
    };
    serde_json::json!({
        "cycle": c.cycle,
        "missed": c.missed,
        "round_trip_us": c.round_trip_us,
        "commanded": c.commanded,
        "valid": c.feedback.iter().map(Option::is_some).collect::<Vec<_>>(),
        "position_deg": f(&|x| serde_json::json!(x.position_deg)),
        "speed_rpm": f(&|x| serde_json::json!(x.speed_rpm)),
        "current_ma": f(&|x| serde_json::json!(x.current_ma)),
        "enabled": f(&|x| serde_json::json!(x.enabled)),
        "error": f(&|x| serde_json::json!(x.error)),
    })
}

#[pymethods]
#[allow(clippy::needless_pass_by_value)] // pyo3 signatures
impl NativeCyclic {
    /// The joints, in target and feedback order.
    #[getter]
    fn joints(&self) -> Vec<u8> {
        self.lock().joints()
    }

    /// Each joint's allowed targets `(low, high)` in the loop's unit.
    #[getter]
    fn limits(&self) -> Vec<(f64, f64)> {
        self.lock().limits().to_vec()
    }

    /// Sets the targets (one float per joint, the loop's unit), checked first.
    fn set(&self, py: Python<'_>, targets: Vec<f64>) -> PyResult<()> {
        self.life.check(py, "Cyclic.set")?;
        self.lock().set(&targets).map_err(|e| op_error(py, &e))
    }

    /// The next cycle as columns, waiting at most `timeout` s; `None` on timeout or once
    /// stopped. Ctrl-C interrupts the wait (the loop goes on until stopped).
    fn next(&self, py: Python<'_>, timeout: f64) -> PyResult<Option<Py<PyAny>>> {
        self.life.check(py, "Cyclic.next")?;
        let total = if timeout.is_finite() && timeout >= 0.0 {
            Duration::from_secs_f64(timeout.min(1e6))
        } else {
            return Err(raise(
                py,
                ErrorKind::BadInput,
                &format!("timeout {timeout}: not a finite number of seconds >= 0"),
                None,
            ));
        };
        let start = std::time::Instant::now();
        loop {
            let left = total.saturating_sub(start.elapsed());
            let slice = left.min(SIGNAL_SLICE);
            let got = py.detach(|| self.lock().next(slice));
            if let Some(c) = got {
                return to_py(py, &columns(&c)).map(Some);
            }
            if self.life.closed() {
                return Err(closed_error(py, "Cyclic.next"));
            }
            if start.elapsed() >= total {
                return Ok(None);
            }
            py.check_signals()?;
        }
    }

    /// The most recent cycle as columns, if one has finished.
    fn latest(&self, py: Python<'_>) -> PyResult<Option<Py<PyAny>>> {
        self.life.check(py, "Cyclic.latest")?;
        match self.lock().latest() {
            Some(c) => to_py(py, &columns(&c)).map(Some),
            None => Ok(None),
        }
    }

    /// Drops the queued cycles.
    fn clear(&self, py: Python<'_>) -> PyResult<()> {
        self.life.check(py, "Cyclic.clear")?;
        self.lock().clear();
        Ok(())
    }

    /// What the loop did so far (`None` once stopped).
    fn summary(&self, py: Python<'_>) -> PyResult<Option<Py<PyAny>>> {
        self.life.check(py, "Cyclic.summary")?;
        match self.lock().summary() {
            Some(s) => to_py(py, &s).map(Some),
            None => Ok(None),
        }
    }

    /// Stops the loop: what it did; `None` if it was stopped before (also by closing its
    /// station).
    fn stop(&self, py: Python<'_>) -> PyResult<Option<Py<PyAny>>> {
        if let Some(e) = self.life.fork_error(py, "Cyclic.stop", "station") {
            return Err(e);
        }
        let done = py.detach(|| {
            self.inner
                .write()
                .unwrap_or_else(std::sync::PoisonError::into_inner)
                .stop()
        });
        match done {
            Some(s) => to_py(py, &s).map(Some),
            None => Ok(None),
        }
    }
}

/// The JSON Schema of a request, a report or a plan, as JSON text.
#[pyfunction]
fn schema(py: Python<'_>, of: &str) -> PyResult<String> {
    let v = match of {
        "request" => catalogue::request_schema(),
        "report" => catalogue::report_schema(),
        "plan" => catalogue::plan_schema(),
        other => {
            return Err(raise(
                py,
                ErrorKind::BadInput,
                &format!("schema {other:?}: unknown (allowed: request, report, plan)"),
                None,
            ));
        }
    };
    Ok(v.to_string())
}

/// Device facts a front end converts with: the wCK baud rates, the wCK position range and
/// degrees per step, the WHJ position and speed units.
#[pyfunction]
fn facts(py: Python<'_>) -> PyResult<Py<PyAny>> {
    let d = pyo3::types::PyDict::new(py);
    d.set_item(
        "wck_bauds",
        robobus_wck::BaudRate::ALL
            .iter()
            .map(|b| b.bits_per_second())
            .collect::<Vec<_>>(),
    )?;
    d.set_item(
        "wck_default_baud",
        robobus_wck::BaudRate::DEFAULT.bits_per_second(),
    )?;
    d.set_item("wck_position_max", robobus_wck::Position::MAX.get())?;
    d.set_item(
        "wck_degrees_per_step",
        robobus_wck::Position::DEGREES_PER_STEP,
    )?;
    d.set_item(
        "whj_degrees_per_count",
        robobus_whj::units::Position(1).degrees(),
    )?;
    d.set_item(
        "whj_rpm_per_speed_count",
        robobus_whj::units::ActualSpeed(1).rpm(),
    )?;
    d.set_item(
        "whj_rpm_per_target_count",
        robobus_whj::units::TargetSpeed(1).rpm(),
    )?;
    Ok(d.into_any().unbind())
}

/// A benchmark's repeat count: 1..=10,000,000.
pub(crate) fn bench_count(py: Python<'_>, n: u32) -> PyResult<u32> {
    if (1..=10_000_000).contains(&n) {
        Ok(n)
    } else {
        Err(raise(
            py,
            ErrorKind::BadInput,
            &format!("n {n}: out of range (allowed: 1..=10000000)"),
            None,
        ))
    }
}

/// Benchmark: the library's parse of the request text `text` (`robobus run`'s, the
/// studio's), `n` times; the seconds each took on average.
#[pyfunction]
#[pyo3(name = "_bench_parse")]
fn bench_parse(py: Python<'_>, text: &str, n: u32) -> PyResult<f64> {
    let n = bench_count(py, n)?;
    robobus::frontend::parse::request_text(text).map_err(|e| op_error(py, &e))?;
    let start = Instant::now();
    for _ in 0..n {
        let _ = std::hint::black_box(robobus::frontend::parse::request_text(
            std::hint::black_box(text),
        ));
    }
    Ok(start.elapsed().as_secs_f64() / f64::from(n))
}

/// The library's version.
#[pyfunction]
fn version() -> &'static str {
    env!("CARGO_PKG_VERSION")
}

#[pymodule]
fn _robobus(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let _ = MAIN.set(std::thread::current().id());
    // A forked child refuses the parent's stations (life.rs).
    life::watch_forks(m)?;
    // The library's log events go to Python's `logging` (a second import keeps the first).
    let _ = pyo3_log::try_init();
    tracing::debug!(
        version = env!("CARGO_PKG_VERSION"),
        "robobus native module loaded"
    );
    m.add_class::<NativeStation>()?;
    m.add_class::<telemetry::NativeTelemetry>()?;
    m.add_class::<NativeCyclic>()?;
    m.add_class::<handles::NativeWckServos>()?;
    m.add_class::<handles::NativeWhjJoints>()?;
    m.add_class::<handles::NativeRobot>()?;
    m.add_function(wrap_pyfunction!(schema, m)?)?;
    m.add_function(wrap_pyfunction!(version, m)?)?;
    m.add_function(wrap_pyfunction!(bench_parse, m)?)?;
    m.add_function(wrap_pyfunction!(telemetry::whj_frames_sent, m)?)?;
    m.add_function(wrap_pyfunction!(facts, m)?)?;
    Ok(())
}
