//! The native part of the `robobus` Python package: the catalogue's [`Station`], its
//! dispatcher and its telemetry stream, with requests and reports as Python dicts in the
//! catalogue's JSON form. The Python side (`python/robobus`) adds the methods generated
//! from the request schema, the exception classes and the type stubs.
//!
//! - Every call that waits on a device releases the GIL.
//! - On the main thread a request runs on a worker thread while the caller waits in short
//!   slices and checks Python's signals between them: Ctrl-C stops the request through its
//!   stop token (the operation brings its devices to their safe state) and raises
//!   `KeyboardInterrupt` once it has. Python's own SIGINT handler stays in place; no
//!   handler is installed here.
//! - Errors are raised as `robobus.errors` classes chosen by the error kind, with the
//!   library's message.
//! - The library's log events go to Python's `logging` (pyo3-log).

// OpError carries the client errors by value, as the library returns them.
#![allow(clippy::result_large_err)]

use std::sync::mpsc;
use std::sync::{Arc, Mutex, OnceLock};
use std::thread::ThreadId;
use std::time::Duration;

use pyo3::exceptions::PyRuntimeError;
use pyo3::prelude::*;
use robobus::ErrorKind;
use robobus::catalogue::telemetry::RecvError;
use robobus::catalogue::{self, Request, StationConfig};
use robobus::ops::{Control, OpError, StopToken};

mod handles;

/// How often a wait on the main thread looks at Python's signals.
const SIGNAL_SLICE: Duration = Duration::from_millis(10);

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

fn op_error(py: Python<'_>, e: &OpError) -> PyErr {
    raise(py, e.kind(), &e.to_string(), None)
}

/// A Python object as JSON text (through Python's own `json`, so a dict, a list, a str or
/// numbers all work).
fn to_json(py: Python<'_>, value: &Bound<'_, PyAny>) -> PyResult<String> {
    py.import("json")?
        .call_method1("dumps", (value,))?
        .extract::<String>()
}

fn from_json(py: Python<'_>, text: &str) -> PyResult<Py<PyAny>> {
    Ok(py.import("json")?.call_method1("loads", (text,))?.unbind())
}

fn to_py(py: Python<'_>, value: &impl serde::Serialize) -> PyResult<Py<PyAny>> {
    let text = serde_json::to_string(value)
        .map_err(|e| PyRuntimeError::new_err(format!("serialising a report: {e}")))?;
    from_json(py, &text)
}

/// A request from a dict (or its JSON text): bad input naming what is wrong.
fn request(py: Python<'_>, value: &Bound<'_, PyAny>) -> PyResult<Request> {
    let text = match value.extract::<String>() {
        Ok(s) => s,
        Err(_) => to_json(py, value)?,
    };
    serde_json::from_str(&text).map_err(|e| {
        raise(
            py,
            ErrorKind::BadInput,
            &format!("request: {e}; nothing was sent"),
            None,
        )
    })
}

/// A job the main thread hands to its worker.
type Job = Box<dyn FnOnce() + Send>;

/// The main thread's worker: one long-lived thread that runs its requests while the main
/// thread waits and watches for signals (a thread per request would cost its start-up on
/// every call).
static WORKER: OnceLock<Mutex<mpsc::Sender<Job>>> = OnceLock::new();

fn main_worker(job: Job) -> PyResult<()> {
    let worker = WORKER.get_or_init(|| {
        let (tx, rx) = mpsc::channel::<Job>();
        let spawned = std::thread::Builder::new()
            .name("robobus-main-worker".into())
            .spawn(move || {
                for job in rx {
                    job();
                }
            });
        if let Err(e) = spawned {
            tracing::error!("starting the robobus worker thread: {e}");
        }
        Mutex::new(tx)
    });
    worker
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
        .send(job)
        .map_err(|_| PyRuntimeError::new_err("the robobus worker thread is not running"))
}

/// Waits for `rx` with the GIL released; on the main thread in slices, checking Python's
/// signals between them: on a signal `stop` is set, the wait goes on until the worker has
/// ended (its devices in their safe state), and the signal's exception is returned.
fn wait_for<T: Send>(py: Python<'_>, rx: mpsc::Receiver<T>, stop: &StopToken) -> PyResult<T> {
    // Behind a mutex so that a reference to it may cross into the GIL-free closure.
    let rx = Mutex::new(rx);
    let mut signal: Option<PyErr> = None;
    loop {
        let got = py.detach(|| {
            rx.lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner)
                .recv_timeout(SIGNAL_SLICE)
        });
        match got {
            Ok(v) => return signal.map_or(Ok(v), Err),
            Err(mpsc::RecvTimeoutError::Disconnected) => {
                return Err(signal.unwrap_or_else(|| {
                    PyRuntimeError::new_err("the request's worker thread ended without a report")
                }));
            }
            Err(mpsc::RecvTimeoutError::Timeout) => {}
        }
        if signal.is_none()
            && let Err(e) = py.check_signals()
        {
            stop.stop();
            signal = Some(e);
        }
    }
}

/// The station: the buses a Python session holds (see the module docs of
/// `robobus.Station`).
#[pyclass(module = "robobus._robobus", name = "NativeStation", frozen)]
#[derive(Debug)]
struct NativeStation {
    station: Mutex<Option<Arc<catalogue::Station>>>,
}

impl NativeStation {
    fn get(&self, py: Python<'_>) -> PyResult<Arc<catalogue::Station>> {
        self.station
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .clone()
            .ok_or_else(|| {
                raise(
                    py,
                    ErrorKind::BadInput,
                    "the station is closed; open a new one",
                    None,
                )
            })
    }

    fn wrap(station: catalogue::Station) -> Self {
        Self {
            station: Mutex::new(Some(Arc::new(station))),
        }
    }
}

#[pymethods]
#[allow(clippy::needless_pass_by_value, clippy::unused_self)] // pyo3 signatures
impl NativeStation {
    /// The built-in simulated robot, in-process.
    #[staticmethod]
    fn simulated(py: Python<'_>) -> PyResult<Self> {
        let s = py
            .detach(catalogue::Station::simulated)
            .map_err(|e| op_error(py, &e))?;
        Ok(Self::wrap(s))
    }

    /// Opens wCK ports, WHJ buses and a robot file from the CLI's address strings.
    #[staticmethod]
    #[pyo3(signature = (wck_ports, whj_buses, robot, wck_baud, reply_margin_ms, wait = "sleep"))]
    fn open(
        py: Python<'_>,
        wck_ports: Vec<String>,
        whj_buses: Vec<String>,
        robot: Option<std::path::PathBuf>,
        wck_baud: u32,
        reply_margin_ms: Option<f64>,
        wait: &str,
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
            .detach(|| catalogue::Station::open(&config))
            .map_err(|e| op_error(py, &e))?;
        Ok(Self::wrap(s))
    }

    /// Runs one request (a dict in the catalogue's JSON form) and returns its report.
    fn run(&self, py: Python<'_>, request_obj: &Bound<'_, PyAny>) -> PyResult<Py<PyAny>> {
        let req = request(py, request_obj)?;
        // Checked before anything is opened or sent, as `robobus run` does.
        catalogue::validate(&req).map_err(|e| op_error(py, &e))?;
        let station = self.get(py)?;
        let stop = StopToken::new();
        let outcome = if on_main_thread() {
            let (tx, rx) = mpsc::channel();
            let job_stop = stop.clone();
            main_worker(Box::new(move || {
                let r = catalogue::run(&station, &req, &mut Control::new(&job_stop));
                // Let go of the station before the caller hears of the report, so that a
                // `close()` right after it finds the station unshared and closes it.
                drop(station);
                let _ = tx.send(r);
            }))?;
            wait_for(py, rx, &stop)?
        } else {
            // Python delivers signals to the main thread only: run here, GIL released.
            py.detach(|| catalogue::run(&station, &req, &mut Control::new(&stop)))
        };
        let report = outcome.map_err(|e| op_error(py, &e))?;
        to_py(py, &report)
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
        let plan = catalogue::plan(&req).map_err(|e| op_error(py, &e))?;
        let mut value = serde_json::to_value(&plan)
            .map_err(|e| PyRuntimeError::new_err(format!("serialising a plan: {e}")))?;
        value["text"] = serde_json::Value::String(plan.to_text().to_owned());
        to_py(py, &value)
    }

    /// The names of the wCK ports and the WHJ buses.
    fn names(&self, py: Python<'_>) -> PyResult<(Vec<String>, Vec<String>)> {
        Ok(self.get(py)?.names())
    }

    /// Whether the station has a robot file (for `robot.sample`).
    fn has_robot(&self, py: Python<'_>) -> PyResult<bool> {
        Ok(self.get(py)?.robot().is_some())
    }

    /// Closes the station: every device to its safe state (the wCK bus-wide break, every
    /// connected WHJ joint disabled), the ports released. The failures, one message per
    /// device. Closing twice does nothing the second time.
    fn close(&self, py: Python<'_>) -> Vec<String> {
        let taken = self
            .station
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .take();
        let Some(station) = taken else {
            return Vec::new();
        };
        // A telemetry stream still running holds the station: it closes when that ends.
        py.detach(|| match Arc::try_unwrap(station) {
            Ok(s) => s.close(),
            Err(_) => Vec::new(),
        })
    }

    /// Closes the station leaving every device as the last request left it.
    fn leave(&self) {
        let taken = self
            .station
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .take();
        if let Some(s) = taken.and_then(|s| Arc::try_unwrap(s).ok()) {
            s.leave();
        }
    }

    /// Whether `close` (or `leave`) was called.
    #[getter]
    fn closed(&self) -> bool {
        self.station
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .is_none()
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
        let servo = handles::servo_loop(py, mode)?;
        let station = self.get(py)?;
        let l = py
            .detach(|| {
                catalogue::cyclic::CyclicLoop::start(
                    &station,
                    bus.as_deref(),
                    &joints,
                    servo,
                    rate_hz,
                )
            })
            .map_err(|e| op_error(py, &e))?;
        Ok(NativeCyclic {
            inner: std::sync::RwLock::new(l),
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
        let station = self.get(py)?;
        catalogue::handles::WckServos::new(&station, bus.as_deref(), &ids)
            .map(|inner| handles::NativeWckServos { inner })
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
        let station = self.get(py)?;
        py.detach(|| catalogue::handles::WhjJoints::new(&station, bus.as_deref(), &ids))
            .map(|inner| handles::NativeWhjJoints { inner })
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
    ) -> PyResult<NativeTelemetry> {
        let req = request(py, request_obj)?;
        let station = self.get(py)?;
        let t = catalogue::Telemetry::paused(&station, req, rate_hz, limit)
            .map_err(|e| op_error(py, &e))?;
        let sub = t.subscribe(queue).map_err(|e| op_error(py, &e))?;
        t.resume();
        Ok(NativeTelemetry {
            stream: Mutex::new(Some(t)),
            sub,
        })
    }
}

/// A checked cyclic loop on one of the station's WHJ buses (the hot path: targets in and
/// feedback out without a request per cycle).
#[pyclass(module = "robobus._robobus", name = "NativeCyclic", frozen)]
#[derive(Debug)]
struct NativeCyclic {
    /// Read-locked by every call but `stop`, so a thread setting targets never waits for
    /// one waiting for a cycle.
    inner: std::sync::RwLock<catalogue::cyclic::CyclicLoop>,
}

impl NativeCyclic {
    fn lock(&self) -> std::sync::RwLockReadGuard<'_, catalogue::cyclic::CyclicLoop> {
        self.inner
            .read()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }
}

/// A cycle as flat columns (what the Python side turns into arrays): `NaN` / `False`
/// where a joint's feedback did not arrive.
fn columns(c: &catalogue::cyclic::CycleSample) -> serde_json::Value {
    let f = |get: &dyn Fn(&catalogue::cyclic::JointFeedback) -> serde_json::Value| {
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
        self.lock().set(&targets).map_err(|e| op_error(py, &e))
    }

    /// The next cycle as columns, waiting at most `timeout` s; `None` on timeout or once
    /// stopped. Ctrl-C interrupts the wait (the loop goes on until stopped).
    fn next(&self, py: Python<'_>, timeout: f64) -> PyResult<Option<Py<PyAny>>> {
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
            if start.elapsed() >= total {
                return Ok(None);
            }
            py.check_signals()?;
        }
    }

    /// The most recent cycle as columns, if one has finished.
    fn latest(&self, py: Python<'_>) -> PyResult<Option<Py<PyAny>>> {
        match self.lock().latest() {
            Some(c) => to_py(py, &columns(&c)).map(Some),
            None => Ok(None),
        }
    }

    /// Drops the queued cycles.
    fn clear(&self) {
        self.lock().clear();
    }

    /// What the loop did so far (`None` once stopped).
    fn summary(&self, py: Python<'_>) -> PyResult<Option<Py<PyAny>>> {
        match self.lock().summary() {
            Some(s) => to_py(py, &s).map(Some),
            None => Ok(None),
        }
    }

    /// Stops the loop: what it did; `None` if it was stopped before.
    fn stop(&self, py: Python<'_>) -> PyResult<Option<Py<PyAny>>> {
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

/// A running telemetry stream and this session's subscription to it.
#[pyclass(module = "robobus._robobus", name = "NativeTelemetry", frozen)]
#[derive(Debug)]
struct NativeTelemetry {
    stream: Mutex<Option<catalogue::Telemetry>>,
    sub: catalogue::Subscriber,
}

#[pymethods]
impl NativeTelemetry {
    /// The next sample (a dict), waiting at most `timeout` seconds (`None`: until one
    /// comes); `None` once the stream has ended. Ctrl-C interrupts the wait.
    #[pyo3(signature = (timeout=None))]
    fn next(&self, py: Python<'_>, timeout: Option<f64>) -> PyResult<Option<Py<PyAny>>> {
        let deadline = timeout
            .filter(|t| t.is_finite() && *t >= 0.0)
            .map(|t| std::time::Instant::now() + Duration::from_secs_f64(t.min(1e6)));
        loop {
            let slice = deadline.map_or(SIGNAL_SLICE, |d| {
                d.saturating_duration_since(std::time::Instant::now())
                    .min(SIGNAL_SLICE)
            });
            match py.detach(|| self.sub.recv_timeout(slice)) {
                Ok(d) => {
                    let mut v = serde_json::to_value(&*d.sample).map_err(|e| {
                        PyRuntimeError::new_err(format!("serialising a sample: {e}"))
                    })?;
                    v["lost"] = serde_json::json!(d.lost);
                    v["age_ms"] = serde_json::json!(d.sample.age().as_secs_f64() * 1e3);
                    return to_py(py, &v).map(Some);
                }
                Err(RecvError::Ended) => return Ok(None),
                Err(RecvError::Timeout) => {
                    if deadline.is_some_and(|d| std::time::Instant::now() >= d) {
                        return Err(raise(
                            py,
                            ErrorKind::NoDevice,
                            "no sample within the timeout",
                            None,
                        ));
                    }
                }
            }
            py.check_signals()?;
        }
    }

    /// Samples this subscriber lost so far (its queue was full).
    #[getter]
    fn lost(&self) -> u64 {
        self.sub.lost()
    }

    /// Stops the stream (the read under way completes); what it did: samples, late ones,
    /// failed ones. Stopping twice returns `None` the second time.
    fn stop(&self, py: Python<'_>) -> PyResult<Option<Py<PyAny>>> {
        let taken = self
            .stream
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .take();
        match taken {
            Some(t) => {
                let stats = py.detach(|| t.stop());
                to_py(py, &stats).map(Some)
            }
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

/// The library's version.
#[pyfunction]
fn version() -> &'static str {
    env!("CARGO_PKG_VERSION")
}

#[pymodule]
fn _robobus(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let _ = MAIN.set(std::thread::current().id());
    // The library's log events go to Python's `logging` (a second import keeps the first).
    let _ = pyo3_log::try_init();
    tracing::debug!(
        version = env!("CARGO_PKG_VERSION"),
        "robobus native module loaded"
    );
    m.add_class::<NativeStation>()?;
    m.add_class::<NativeTelemetry>()?;
    m.add_class::<NativeCyclic>()?;
    m.add_class::<handles::NativeWckServos>()?;
    m.add_class::<handles::NativeWhjJoints>()?;
    m.add_class::<handles::NativeRobot>()?;
    m.add_function(wrap_pyfunction!(schema, m)?)?;
    m.add_function(wrap_pyfunction!(version, m)?)?;
    m.add_function(wrap_pyfunction!(facts, m)?)?;
    Ok(())
}
