//! The hot-path handles: groups of wCK servos and WHJ joints on a station's bus
//! (`robobus::station::handles`) and a robot in SI units (`robobus::robot::Robot`).
//! Results come back as flat columns (lists of floats with `NaN` where a device gave no
//! value, a `valid` mask, per-device error messages and kinds), which the Python side turns
//! into numpy arrays; no JSON on the way.

use std::sync::{Arc, Mutex};

use pyo3::prelude::*;
use pyo3::types::PyDict;
use robobus::ErrorKind;
use robobus::ops::whj::{JointSample, ServoLoop};
use robobus::ops::{DeviceResult, Outcome};
use robobus::robot::{Interface, Robot};
use robobus::station::cyclic::JointFeedback;
use robobus::station::handles::{WckGroup, WckReading, WhjGroup};

use crate::life::{Life, forked_error};
use crate::{op_error, raise};

/// The per-device columns every group result has: `id`, `valid`, `error`, `kind`.
fn base<'py, T>(py: Python<'py>, rows: &[DeviceResult<u8, T>]) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item(
        "id",
        rows.iter().map(|r| u32::from(r.id)).collect::<Vec<_>>(),
    )?;
    d.set_item(
        "valid",
        rows.iter().map(|r| r.value().is_some()).collect::<Vec<_>>(),
    )?;
    d.set_item(
        "error",
        rows.iter()
            .map(|r| r.failure().map(|f| f.error.clone()))
            .collect::<Vec<_>>(),
    )?;
    d.set_item(
        "kind",
        rows.iter()
            .map(|r| r.failure().map(|f| f.kind.name()))
            .collect::<Vec<_>>(),
    )?;
    Ok(d)
}

/// A float column: `f` of each value, `NaN` where the device gave none.
fn column<T>(rows: &[DeviceResult<u8, T>], f: impl Fn(&T) -> Option<f64>) -> Vec<f64> {
    rows.iter()
        .map(|r| r.value().and_then(&f).unwrap_or(f64::NAN))
        .collect()
}

fn wck_columns(py: Python<'_>, rows: &[DeviceResult<u8, WckReading>]) -> PyResult<Py<PyAny>> {
    let d = base(py, rows)?;
    d.set_item("position", column(rows, |v| Some(f64::from(v.position))))?;
    d.set_item("position_deg", column(rows, |v| Some(v.position_deg)))?;
    d.set_item("load", column(rows, |v| v.load.map(f64::from)))?;
    Ok(d.into_any().unbind())
}

/// A WHJ joint's values, as a status sample or a servo frame's feedback has them.
trait JointValues {
    fn position_deg(&self) -> f64;
    fn speed_rpm(&self) -> Option<f64>;
    fn current_ma(&self) -> Option<i64>;
    fn enabled(&self) -> bool;
    fn error(&self) -> &str;
}

impl JointValues for JointSample {
    fn position_deg(&self) -> f64 {
        self.position_deg
    }
    fn speed_rpm(&self) -> Option<f64> {
        self.speed_rpm
    }
    fn current_ma(&self) -> Option<i64> {
        self.current_ma
    }
    fn enabled(&self) -> bool {
        self.enabled
    }
    fn error(&self) -> &str {
        &self.error
    }
}

impl JointValues for JointFeedback {
    fn position_deg(&self) -> f64 {
        self.position_deg
    }
    fn speed_rpm(&self) -> Option<f64> {
        Some(self.speed_rpm)
    }
    fn current_ma(&self) -> Option<i64> {
        Some(self.current_ma)
    }
    fn enabled(&self) -> bool {
        self.enabled
    }
    fn error(&self) -> &str {
        &self.error
    }
}

#[allow(clippy::cast_precision_loss)] // currents far below 2^52 mA
fn whj_columns<T: JointValues>(
    py: Python<'_>,
    rows: &[DeviceResult<u8, T>],
) -> PyResult<Py<PyAny>> {
    let d = base(py, rows)?;
    d.set_item("position_deg", column(rows, |v| Some(v.position_deg())))?;
    d.set_item("speed_rpm", column(rows, JointValues::speed_rpm))?;
    d.set_item(
        "current_ma",
        column(rows, |v| v.current_ma().map(|c| c as f64)),
    )?;
    d.set_item(
        "enabled",
        rows.iter()
            .map(|r| r.value().is_some_and(JointValues::enabled))
            .collect::<Vec<_>>(),
    )?;
    d.set_item(
        "errors",
        rows.iter()
            .map(|r| r.value().map(|v| v.error().to_owned()))
            .collect::<Vec<_>>(),
    )?;
    Ok(d.into_any().unbind())
}

/// The one device's value of a single-device call, or its failure raised as its kind's
/// class.
fn one<T>(py: Python<'_>, rows: Vec<DeviceResult<u8, T>>) -> PyResult<T> {
    match rows.into_iter().next().map(|r| r.outcome) {
        Some(Outcome::Ok(v)) => Ok(v),
        Some(Outcome::Failed(f)) => Err(raise(py, f.kind, &f.error, None)),
        None => Err(raise(
            py,
            ErrorKind::BadInput,
            "no device in the handle",
            None,
        )),
    }
}

/// A wCK servo's reading as a dict: `position` (steps), `position_deg` and, where the reply
/// has it, `load`.
fn wck_dict(py: Python<'_>, v: &WckReading) -> PyResult<Py<PyAny>> {
    let d = PyDict::new(py);
    d.set_item("position", f64::from(v.position))?;
    d.set_item("position_deg", v.position_deg)?;
    if let Some(load) = v.load {
        d.set_item("load", f64::from(load))?;
    }
    Ok(d.into_any().unbind())
}

/// A WHJ joint's values as a dict: `position_deg`, `speed_rpm`, `current_ma` (`NaN` where
/// the device gave none), `enabled`, `errors`.
#[allow(clippy::cast_precision_loss)] // currents far below 2^52 mA
fn whj_dict<T: JointValues>(py: Python<'_>, v: &T) -> PyResult<Py<PyAny>> {
    let d = PyDict::new(py);
    d.set_item("position_deg", v.position_deg())?;
    d.set_item("speed_rpm", v.speed_rpm().unwrap_or(f64::NAN))?;
    d.set_item("current_ma", v.current_ma().map_or(f64::NAN, |c| c as f64))?;
    d.set_item("enabled", v.enabled())?;
    d.set_item("errors", v.error())?;
    Ok(d.into_any().unbind())
}

/// A number argument as `f64`, or bad input naming it (nothing sent).
fn number(py: Python<'_>, what: &str, v: &Bound<'_, PyAny>) -> PyResult<f64> {
    if v.is_instance_of::<pyo3::types::PyString>() {
        return Err(bad_number(py, what, v));
    }
    v.extract::<f64>().map_err(|_| bad_number(py, what, v))
}

fn bad_number(py: Python<'_>, what: &str, v: &Bound<'_, PyAny>) -> PyErr {
    let shown = v.repr().map_or_else(|_| "?".to_owned(), |r| r.to_string());
    raise(
        py,
        ErrorKind::BadInput,
        &format!("{what}: {shown} is not a number; nothing was sent"),
        None,
    )
}

/// Benchmark: `f` run `n` times with the GIL released; seconds each on average.
fn bench<E>(py: Python<'_>, n: u32, f: impl Fn() -> Result<(), E> + Send + Sync) -> PyResult<f64>
where
    E: Send,
    robobus::ops::OpError: From<E>,
{
    let n = crate::bench_count(py, n)?;
    py.detach(|| {
        let start = std::time::Instant::now();
        for _ in 0..n {
            f()?;
        }
        Ok(start.elapsed().as_secs_f64() / f64::from(n))
    })
    .map_err(|e: E| op_error(py, &robobus::ops::OpError::from(e)))
}

pub(crate) fn servo_loop(py: Python<'_>, mode: &str) -> PyResult<ServoLoop> {
    match mode {
        "position" => Ok(ServoLoop::Position),
        "speed" => Ok(ServoLoop::Speed),
        "current" => Ok(ServoLoop::Current),
        other => Err(raise(
            py,
            ErrorKind::BadInput,
            &format!("mode {other:?}: unknown (allowed: position, speed, current)"),
            None,
        )),
    }
}

/// wCK servos on one of a station's ports.
#[pyclass(module = "robobus._robobus", name = "NativeWckServos", frozen)]
#[derive(Debug)]
pub(crate) struct NativeWckServos {
    pub(crate) inner: WckGroup,
    /// Its station's.
    pub(crate) life: Arc<Life>,
}

#[pymethods]
#[allow(clippy::needless_pass_by_value)] // pyo3 signatures
impl NativeWckServos {
    /// The servos, in the order of every call's values and results.
    #[getter]
    fn ids(&self) -> Vec<u8> {
        self.inner.ids()
    }

    /// The port's name.
    #[getter]
    fn bus(&self) -> String {
        self.inner.bus().to_owned()
    }

    /// Each servo's position and load, as columns.
    fn status(&self, py: Python<'_>) -> PyResult<Py<PyAny>> {
        self.life.check(py, "WckServos.status")?;
        let rows = py
            .detach(|| self.inner.status())
            .map_err(|e| op_error(py, &e))?;
        wck_columns(py, &rows)
    }

    /// Moves each servo (one position command each), every value checked first.
    fn move_to(&self, py: Python<'_>, positions: Vec<f64>, torque: u8) -> PyResult<Py<PyAny>> {
        self.life.check(py, "WckServos.move")?;
        self.life
            .admission
            .check_motion(robobus::frontend::Arming::Local, "WckServos.move")
            .map_err(|r| op_error(py, &r.error))?;
        let rows = py
            .detach(|| self.inner.move_to(&positions, torque))
            .map_err(|e| op_error(py, &e))?;
        wck_columns(py, &rows)
    }

    /// One synchronized position packet for servos 0..N-1.
    fn sync_move(&self, py: Python<'_>, positions: Vec<f64>, torque: u8) -> PyResult<()> {
        self.life.check(py, "WckServos.sync_move")?;
        self.life
            .admission
            .check_motion(robobus::frontend::Arming::Local, "WckServos.sync_move")
            .map_err(|r| op_error(py, &r.error))?;
        py.detach(|| self.inner.sync_move(&positions, torque))
            .map_err(|e| op_error(py, &e))
    }

    /// Makes each servo passive; each one's position, as columns.
    fn passive(&self, py: Python<'_>) -> PyResult<Py<PyAny>> {
        self.life.check(py, "WckServos.passive")?;
        self.life
            .admission
            .check_change("WckServos.passive")
            .map_err(|r| op_error(py, &r.error))?;
        let rows = py
            .detach(|| self.inner.passive())
            .map_err(|e| op_error(py, &e))?;
        wck_columns(py, &rows)
    }

    /// The first servo's position and load as a dict; its failure raised.
    fn status_one(&self, py: Python<'_>) -> PyResult<Py<PyAny>> {
        self.life.check(py, "WckServos.status")?;
        let rows = py
            .detach(|| self.inner.status())
            .map_err(|e| op_error(py, &e))?;
        wck_dict(py, &one(py, rows)?)
    }

    /// Moves the one servo of the handle; its reply as a dict, its failure raised.
    fn move_one(
        &self,
        py: Python<'_>,
        position: &Bound<'_, PyAny>,
        torque: u8,
    ) -> PyResult<Py<PyAny>> {
        self.life.check(py, "WckServos.move")?;
        self.life
            .admission
            .check_motion(robobus::frontend::Arming::Local, "WckServos.move")
            .map_err(|r| op_error(py, &r.error))?;
        let p = number(py, "position", position)?;
        let rows = py
            .detach(|| self.inner.move_to(&[p], torque))
            .map_err(|e| op_error(py, &e))?;
        wck_dict(py, &one(py, rows)?)
    }

    /// Makes the one servo of the handle passive; its position as a dict.
    fn passive_one(&self, py: Python<'_>) -> PyResult<Py<PyAny>> {
        self.life.check(py, "WckServos.passive")?;
        self.life
            .admission
            .check_change("WckServos.passive")
            .map_err(|r| op_error(py, &r.error))?;
        let rows = py
            .detach(|| self.inner.passive())
            .map_err(|e| op_error(py, &e))?;
        wck_dict(py, &one(py, rows)?)
    }

    /// Each servo's position in degrees (`NaN` where it did not answer; with `check`, the
    /// first failure raised instead).
    fn positions(&self, py: Python<'_>, check: bool) -> PyResult<Vec<f64>> {
        self.life.check(py, "WckServos.read_positions")?;
        let rows = py
            .detach(|| self.inner.status())
            .map_err(|e| op_error(py, &e))?;
        position_column(py, &rows, check, |v| v.position_deg)
    }

    /// Benchmark: the same status read `n` times in Rust; seconds each.
    #[pyo3(name = "_bench_status")]
    fn bench_status(&self, py: Python<'_>, n: u32) -> PyResult<f64> {
        self.life.check(py, "WckServos._bench_status")?;
        bench(py, n, || self.inner.status().map(drop))
    }
}

/// A position column (`NaN` where a device failed), or with `check` the first failure.
fn position_column<T>(
    py: Python<'_>,
    rows: &[DeviceResult<u8, T>],
    check: bool,
    f: impl Fn(&T) -> f64,
) -> PyResult<Vec<f64>> {
    if check && let Some(fail) = rows.iter().find_map(DeviceResult::failure) {
        return Err(raise(py, fail.kind, &fail.error, None));
    }
    Ok(column(rows, |v| Some(f(v))))
}

/// WHJ joints on one of a station's buses.
#[pyclass(module = "robobus._robobus", name = "NativeWhjJoints", frozen)]
#[derive(Debug)]
pub(crate) struct NativeWhjJoints {
    pub(crate) inner: WhjGroup,
    /// Its station's.
    pub(crate) life: Arc<Life>,
}

#[pymethods]
#[allow(clippy::needless_pass_by_value)] // pyo3 signatures
impl NativeWhjJoints {
    /// The joints, in the order of every call's values and results.
    #[getter]
    fn ids(&self) -> Vec<u8> {
        self.inner.ids()
    }

    /// The bus's name.
    #[getter]
    fn bus(&self) -> String {
        self.inner.bus().to_owned()
    }

    /// What each joint accepts as a `mode` target, `(low, high)` in its unit.
    fn limits(&self, py: Python<'_>, mode: &str) -> PyResult<Vec<(f64, f64)>> {
        Ok(self.inner.limits(servo_loop(py, mode)?))
    }

    /// Each joint's status, as columns.
    fn status(&self, py: Python<'_>) -> PyResult<Py<PyAny>> {
        self.life.check(py, "WhjJoints.status")?;
        let rows = py
            .detach(|| self.inner.status())
            .map_err(|e| op_error(py, &e))?;
        whj_columns(py, &rows)
    }

    /// One `mode` servo frame per joint; each joint's feedback, as columns.
    fn command(&self, py: Python<'_>, mode: &str, targets: Vec<f64>) -> PyResult<Py<PyAny>> {
        self.life.check(py, "WhjJoints.command")?;
        self.life
            .admission
            .check_motion(robobus::frontend::Arming::Local, "WhjJoints.command")
            .map_err(|r| op_error(py, &r.error))?;
        let servo = servo_loop(py, mode)?;
        let rows = py
            .detach(|| self.inner.command(servo, &targets))
            .map_err(|e| op_error(py, &e))?;
        whj_columns(py, &rows)
    }

    /// The one joint's status as a dict; its failure raised.
    fn status_one(&self, py: Python<'_>) -> PyResult<Py<PyAny>> {
        self.life.check(py, "WhjJoints.status")?;
        let rows = py
            .detach(|| self.inner.status())
            .map_err(|e| op_error(py, &e))?;
        whj_dict(py, &one(py, rows)?)
    }

    /// One `mode` servo frame to the one joint of the handle; its feedback as a dict, its
    /// failure raised.
    fn command_one(
        &self,
        py: Python<'_>,
        mode: &str,
        target: &Bound<'_, PyAny>,
    ) -> PyResult<Py<PyAny>> {
        self.life.check(py, "WhjJoints.command")?;
        self.life
            .admission
            .check_motion(robobus::frontend::Arming::Local, "WhjJoints.command")
            .map_err(|r| op_error(py, &r.error))?;
        let servo = servo_loop(py, mode)?;
        let t = number(py, "target", target)?;
        let rows = py
            .detach(|| self.inner.command(servo, &[t]))
            .map_err(|e| op_error(py, &e))?;
        whj_dict(py, &one(py, rows)?)
    }

    /// Each joint's position in degrees, the status queries pipelined (`NaN` where a joint
    /// did not answer; with `check`, the first failure raised instead).
    fn positions(&self, py: Python<'_>, check: bool) -> PyResult<Vec<f64>> {
        self.life.check(py, "WhjJoints.read_positions")?;
        let rows = py
            .detach(|| self.inner.positions())
            .map_err(|e| op_error(py, &e))?;
        position_column(py, &rows, check, |&deg| deg)
    }

    /// Benchmark: the same `mode` servo frames `n` times in Rust; seconds each.
    #[pyo3(name = "_bench_command")]
    fn bench_command(
        &self,
        py: Python<'_>,
        mode: &str,
        targets: Vec<f64>,
        n: u32,
    ) -> PyResult<f64> {
        self.life.check(py, "WhjJoints._bench_command")?;
        self.life
            .admission
            .check_motion(robobus::frontend::Arming::Local, "WhjJoints._bench_command")
            .map_err(|r| op_error(py, &r.error))?;
        let servo = servo_loop(py, mode)?;
        bench(py, n, || self.inner.command(servo, &targets).map(drop))
    }

    /// Benchmark: the pipelined position read `n` times in Rust; seconds each.
    #[pyo3(name = "_bench_positions")]
    fn bench_positions(&self, py: Python<'_>, n: u32) -> PyResult<f64> {
        self.life.check(py, "WhjJoints._bench_positions")?;
        bench(py, n, || self.inner.positions().map(drop))
    }

    /// Benchmark: the status read `n` times in Rust; seconds each.
    #[pyo3(name = "_bench_status")]
    fn bench_status(&self, py: Python<'_>, n: u32) -> PyResult<f64> {
        self.life.check(py, "WhjJoints._bench_status")?;
        bench(py, n, || self.inner.status().map(drop))
    }
}

/// A robot: its joints by name in SI units, behind its soft limits, speed limits and
/// watchdog.
#[pyclass(module = "robobus._robobus", name = "NativeRobot", frozen)]
#[derive(Debug)]
pub(crate) struct NativeRobot {
    robot: Mutex<Option<Robot>>,
    names: Vec<String>,
    /// The process it was opened in.
    pid: u32,
}

impl Drop for NativeRobot {
    fn drop(&mut self) {
        let taken = self
            .robot
            .get_mut()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .take();
        if self.forked() {
            // In a forked child: the parent's buses and threads are left alone.
            std::mem::forget(taken);
        } else {
            crate::without_gil(|| drop(taken));
        }
    }
}

impl NativeRobot {
    fn wrap(robot: Robot) -> Self {
        Self {
            names: robot.joint_names().to_vec(),
            robot: Mutex::new(Some(robot)),
            pid: std::process::id(),
        }
    }

    fn forked(&self) -> bool {
        crate::life::forked_from(self.pid)
    }

    fn with<R>(&self, py: Python<'_>, f: impl FnOnce(&mut Robot) -> R + Send) -> PyResult<R>
    where
        R: Send,
    {
        if self.forked() {
            return Err(forked_error(py, "Robot", "robot", self.pid));
        }
        py.detach(|| {
            let mut guard = self
                .robot
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner);
            guard.as_mut().map(f)
        })
        .ok_or_else(|| {
            raise(
                py,
                ErrorKind::BadInput,
                "the robot is closed; open a new one",
                None,
            )
        })
    }
}

fn robot_error(py: Python<'_>, e: &robobus::robot::RobotError) -> PyErr {
    let robobus::robot::RobotError::Protection { fault, .. } = e else {
        return raise(py, e.kind(), &e.to_string(), None);
    };
    // The host's protection stopped a joint: robobus.errors.ProtectionError, its fault's
    // facts as attributes.
    let made = crate::to_py(py, &**fault).and_then(|f| {
        py.import("robobus.errors")
            .and_then(|m| m.getattr("ProtectionError"))
            .and_then(|c| c.call1((e.to_string(), e.kind().name(), py.None(), f)))
    });
    match made {
        Ok(err) => PyErr::from_value(err),
        Err(err) => err,
    }
}

/// Faults as a list of dicts (`joint`, `check`, `quantity`, `value`, `limit`, `at_s`,
/// `action`).
fn faults(py: Python<'_>, faults: &[robobus::ops::protect::Fault]) -> PyResult<Py<PyAny>> {
    crate::to_py(py, &faults)
}

fn stop_report(py: Python<'_>, r: &robobus::robot::SafeStopReport) -> PyResult<Py<PyAny>> {
    let d = PyDict::new(py);
    d.set_item("cause", r.cause.to_string())?;
    d.set_item("applied_in_ms", r.applied_in.as_secs_f64() * 1e3)?;
    d.set_item("errors", r.errors.clone())?;
    Ok(d.into_any().unbind())
}

/// A robot command's report: `sent_rad` (rad, rad/s or N·m by each joint's interface),
/// `interfaces` and the `limited` targets.
fn command_report(py: Python<'_>, report: &robobus::robot::CommandReport) -> PyResult<Py<PyAny>> {
    let d = PyDict::new(py);
    d.set_item(
        "interfaces",
        report
            .interfaces
            .iter()
            .map(|i| i.keyword())
            .collect::<Vec<_>>(),
    )?;
    d.set_item("sent_rad", &report.sent_rad)?;
    let limited = pyo3::types::PyList::empty(py);
    for l in &report.limited {
        let e = PyDict::new(py);
        e.set_item("joint", &l.joint)?;
        e.set_item(
            "kind",
            match l.kind {
                robobus::robot::LimitKind::Position => "position",
                robobus::robot::LimitKind::Motion => "motion",
                robobus::robot::LimitKind::Step => "step",
            },
        )?;
        e.set_item("requested_rad", l.requested_rad)?;
        e.set_item("limited_rad", l.limited_rad)?;
        limited.append(e)?;
    }
    d.set_item("limited", limited)?;
    Ok(d.into_any().unbind())
}

#[pymethods]
#[allow(clippy::needless_pass_by_value)] // pyo3 signatures
impl NativeRobot {
    /// Opens the robot of a robot file (every bus it names); `protection`: whether the
    /// host's protection watches its commands.
    #[staticmethod]
    #[pyo3(signature = (path, protection=true))]
    fn open(py: Python<'_>, path: std::path::PathBuf, protection: bool) -> PyResult<Self> {
        py.detach(|| {
            Robot::from_toml_file(&path).map(|mut r| {
                r.set_protection(protection);
                r
            })
        })
        .map(Self::wrap)
        .map_err(|e| robot_error(py, &e))
    }

    /// The built-in simulated robot, in-process; with `robot_toml`, driven through that
    /// robot file (buses `sim-wck` and `sim-whj`); `protection` as for `open`.
    #[staticmethod]
    #[pyo3(signature = (robot_toml=None, protection=true))]
    fn simulated(py: Python<'_>, robot_toml: Option<String>, protection: bool) -> PyResult<Self> {
        py.detach(|| {
            match robot_toml {
                None => Robot::simulated(),
                Some(text) => robobus::robot::RobotConfig::from_toml_str(&text)
                    .and_then(Robot::simulated_with),
            }
            .map(|mut r| {
                r.set_protection(protection);
                r
            })
        })
        .map(Self::wrap)
        .map_err(|e| robot_error(py, &e))
    }

    /// The joint names, in the order of every array.
    #[getter]
    fn joint_names(&self) -> Vec<String> {
        self.names.clone()
    }

    /// Each joint's soft limits: `(min rad, max rad, max rad/s, max rad/s²)`.
    fn limits(&self, py: Python<'_>) -> PyResult<Vec<(f64, f64, f64, f64)>> {
        self.with(py, |r| {
            r.limits()
                .iter()
                .map(|l| {
                    (
                        l.min_rad,
                        l.max_rad,
                        l.max_velocity_rad_s,
                        l.max_acceleration_rad_s2,
                    )
                })
                .collect()
        })
    }

    /// The watchdog timeout, seconds.
    fn watchdog_timeout(&self, py: Python<'_>) -> PyResult<f64> {
        self.with(py, |r| r.watchdog_timeout().as_secs_f64())
    }

    /// Reads every joint: columns `position_rad`, `velocity_rad_s`, `current_a` (`NaN`
    /// where the device reports no such value).
    fn read(&self, py: Python<'_>) -> PyResult<Py<PyAny>> {
        let states = self
            .with(py, Robot::read)?
            .map_err(|e| robot_error(py, &e))?;
        let d = PyDict::new(py);
        d.set_item(
            "position_rad",
            states.iter().map(|s| s.position_rad).collect::<Vec<_>>(),
        )?;
        d.set_item(
            "velocity_rad_s",
            states
                .iter()
                .map(|s| s.velocity_rad_s.unwrap_or(f64::NAN))
                .collect::<Vec<_>>(),
        )?;
        d.set_item(
            "current_a",
            states
                .iter()
                .map(|s| s.current_a.unwrap_or(f64::NAN))
                .collect::<Vec<_>>(),
        )?;
        Ok(d.into_any().unbind())
    }

    /// Sends one cycle of targets (rad, joint order): `sent_rad` and the `limited`
    /// targets (`joint`, `kind`, `requested_rad`, `limited_rad`).
    fn command(&self, py: Python<'_>, targets: Vec<f64>) -> PyResult<Py<PyAny>> {
        let report = self
            .with(py, |r| r.command(&targets))?
            .map_err(|e| robot_error(py, &e))?;
        command_report(py, &report)
    }

    /// Sends one cycle of speeds (rad/s, joint order; every joint on velocity), as
    /// `command`.
    fn command_velocity(&self, py: Python<'_>, rad_s: Vec<f64>) -> PyResult<Py<PyAny>> {
        let report = self
            .with(py, |r| r.command_velocity(&rad_s))?
            .map_err(|e| robot_error(py, &e))?;
        command_report(py, &report)
    }

    /// Sends one cycle of efforts (N·m, joint order; every joint on effort), as
    /// `command`.
    fn command_effort(&self, py: Python<'_>, nm: Vec<f64>) -> PyResult<Py<PyAny>> {
        let report = self
            .with(py, |r| r.command_effort(&nm))?
            .map_err(|e| robot_error(py, &e))?;
        command_report(py, &report)
    }

    /// Switches joint `index` to `interface` (`position`, `velocity`, `effort`).
    fn set_interface(&self, py: Python<'_>, index: usize, interface: &str) -> PyResult<()> {
        let Some(to) = Interface::ALL
            .into_iter()
            .find(|i| i.keyword() == interface)
        else {
            return Err(raise(
                py,
                robobus::ErrorKind::BadInput,
                &format!(
                    "interface: {interface:?} is not allowed; expected position, velocity or \
                     effort"
                ),
                None,
            ));
        };
        self.with(py, |r| r.set_interface(index, to))?
            .map_err(|e| robot_error(py, &e))
    }

    /// The interface each joint is on now (joint order).
    fn interfaces(&self, py: Python<'_>) -> PyResult<Vec<&'static str>> {
        self.with(py, |r| r.interfaces().iter().map(|i| i.keyword()).collect())
    }

    /// Puts every bus in its safe state now (once); what it did.
    fn safe_stop(&self, py: Python<'_>) -> PyResult<Py<PyAny>> {
        let r = self.with(py, |r| r.safe_stop())?;
        stop_report(py, &r)
    }

    /// The safe stop the robot is in, if any.
    fn safe_stop_report(&self, py: Python<'_>) -> PyResult<Option<Py<PyAny>>> {
        match self.with(py, |r| r.safe_stop_report())? {
            Some(r) => stop_report(py, &r).map(Some),
            None => Ok(None),
        }
    }

    /// Leaves the safe state (WHJ joints re-enabled in position mode).
    fn resume(&self, py: Python<'_>) -> PyResult<()> {
        self.with(py, Robot::resume)?
            .map_err(|e| robot_error(py, &e))
    }

    /// Whether the host's protection watches the robot's commands.
    fn protection(&self, py: Python<'_>) -> PyResult<bool> {
        self.with(py, |r| r.protection())
    }

    /// Turns the host's protection of the robot's commands on or off.
    fn set_protection(&self, py: Python<'_>, on: bool) -> PyResult<()> {
        self.with(py, |r| r.set_protection(on))
    }

    /// The host's protection events so far.
    fn protection_events(&self, py: Python<'_>) -> PyResult<Py<PyAny>> {
        let events = self.with(py, |r| r.protection_events())?;
        faults(py, &events)
    }

    /// The stops the host's protection latched.
    fn protection_stops(&self, py: Python<'_>) -> PyResult<Py<PyAny>> {
        let stops = self.with(py, |r| r.protection_stops())?;
        faults(py, &stops)
    }

    /// Takes commands again after protection stops; the stops cleared.
    fn clear_protection(&self, py: Python<'_>) -> PyResult<Py<PyAny>> {
        let cleared = self
            .with(py, Robot::clear_protection)?
            .map_err(|e| robot_error(py, &e))?;
        faults(py, &cleared)
    }

    /// Closes the robot: every bus to its safe state, the ports released. A second call
    /// does nothing.
    fn close(&self, py: Python<'_>) -> PyResult<()> {
        if self.forked() {
            return Err(forked_error(py, "Robot.close", "robot", self.pid));
        }
        let taken = self
            .robot
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .take();
        py.detach(|| drop(taken));
        Ok(())
    }

    /// Whether `close` was called.
    #[getter]
    fn closed(&self) -> bool {
        self.robot
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .is_none()
    }
}
