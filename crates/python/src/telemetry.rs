//! Python's telemetry stream: a subscription to the station's one sampling of a bus
//! (`Station::telemetry`, shared with every other reader of the bus), with `limit` and
//! `stop()`'s statistics the library's, and `Station.close` closing it.

use std::sync::{Arc, Mutex};
use std::time::Duration;

use pyo3::exceptions::PyRuntimeError;
use pyo3::prelude::*;
use robobus::ErrorKind;
use robobus::catalogue::{
    self,
    telemetry::{RecvError, Subscription},
};

use crate::life::{Life, StreamCell, closed_error};
use crate::{NativeStation, SIGNAL_SLICE, op_error, raise, request, to_py, without_gil};

/// Starts a telemetry stream of a reading request at `rate_hz` (`Station.telemetry`): a
/// subscription to the station's one sampling of the bus, which every other reader of it
/// shares.
pub(crate) fn start(
    this: &NativeStation,
    py: Python<'_>,
    request_obj: &Bound<'_, PyAny>,
    rate_hz: f64,
    limit: Option<u64>,
    queue: usize,
) -> PyResult<NativeTelemetry> {
    let call = "Station.telemetry";
    let req = request(py, request_obj)?;
    let station = this.get(py, call)?;
    let subscription = py
        .detach(|| station.telemetry_limited(req, rate_hz, queue, limit))
        .map_err(|e| op_error(py, &e))?;
    drop(station);
    let sub = subscription.receiver();
    let stream = Arc::new(Mutex::new(Some(Stream(subscription))));
    // On a closed station it is closed at once, and the call refused.
    this.life.adopt_stream(py, call, &stream)?;
    Ok(NativeTelemetry {
        stream,
        sub,
        life: Arc::clone(&this.life),
    })
}

/// A subscription as the station's registry holds it: closed when dropped (when it was
/// the sampling's last, the sampling's thread is joined, so it lets go of the station).
#[derive(Debug)]
pub(crate) struct Stream(Subscription);

impl Drop for Stream {
    fn drop(&mut self) {
        self.0.close();
    }
}

/// A running telemetry stream and this session's subscription to it.
#[pyclass(module = "robobus._robobus", name = "NativeTelemetry", frozen)]
#[derive(Debug)]
pub(crate) struct NativeTelemetry {
    /// Shared with the station's registry, which closes it when the station closes.
    stream: Arc<StreamCell>,
    /// Its queue (what was queued is still received after it was closed, then the end).
    sub: catalogue::Subscriber,
    life: Arc<Life>,
}

impl Drop for NativeTelemetry {
    fn drop(&mut self) {
        if self.life.forked() {
            // The stream's thread is the parent's: nothing to stop or join here.
            std::mem::forget(Arc::clone(&self.stream));
            return;
        }
        let taken = self
            .stream
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .take();
        without_gil(|| drop(taken));
    }
}

#[pymethods]
impl NativeTelemetry {
    /// The next sample (a dict), waiting at most `timeout` seconds (`None`: until one
    /// comes); `None` once the stream has ended. Ctrl-C interrupts the wait.
    #[pyo3(signature = (timeout=None))]
    fn next(&self, py: Python<'_>, timeout: Option<f64>) -> PyResult<Option<Py<PyAny>>> {
        self.life.check(py, "Telemetry.next")?;
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
                Err(RecvError::Ended) if self.life.closed() => {
                    return Err(closed_error(py, "Telemetry.next"));
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

    /// Leaves the station's sampling (the read under way completes when this was its
    /// last subscriber); what this stream was given: samples (lost ones too), late ones,
    /// failed ones. Stopping twice returns `None` the second time (so does stopping it
    /// after its station was closed).
    fn stop(&self, py: Python<'_>) -> PyResult<Option<Py<PyAny>>> {
        if let Some(e) = self.life.fork_error(py, "Telemetry.stop", "station") {
            return Err(e);
        }
        let taken = self
            .stream
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .take();
        match taken {
            Some(t) => {
                py.detach(|| drop(t));
                to_py(py, &self.sub.stats()).map(Some)
            }
            None => Ok(None),
        }
    }
}

/// The frames the host has sent on WHJ bus `bus` (`None`: the only one) since it was
/// opened: on a simulated bus, the frames its simulator received. For the tests that
/// count what a sampling costs the bus.
#[pyfunction]
#[pyo3(name = "_whj_frames_sent", signature = (station, bus = None))]
#[allow(clippy::needless_pass_by_value)] // pyo3 signature
pub(crate) fn whj_frames_sent(
    py: Python<'_>,
    station: PyRef<'_, NativeStation>,
    bus: Option<&str>,
) -> PyResult<u64> {
    let s = station.get(py, "_whj_frames_sent")?;
    let port = s.whj(bus).map_err(|e| op_error(py, &e))?;
    Ok(port.bus().telemetry().bus.frames_sent)
}
