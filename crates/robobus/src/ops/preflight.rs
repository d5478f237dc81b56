//! Pre-flight on the simulator: a timed motion is run first, faster than real time, on the
//! WHJ simulator seeded with the real joint, and refused before its first frame if the
//! simulated joint would fault or have its set-points clamped.
//!
//! The real run computes its plan once (a move's or a wave's frames from the measured
//! position, [`prepare_move`](super::whj::prepare_move) /
//! [`prepare_wave`](super::whj::prepare_wave)); [`seed_whj`] then reads what the simulator
//! needs of the joint ([`WhjSeed`]: its identity, model and firmware, its settings as
//! `whj backup` reads them (current, speed and acceleration limits, position limits,
//! following-error limit, ...), its position, mode, drive state, temperature and supply
//! voltage), and [`whj_move`] / [`whj_wave`] run *that plan* through the same code the
//! real run uses (the step hold-back, the feedback checks, the host's protection) on an
//! in-process simulated joint on the virtual clock: no thread, no wall clock, a 4 s wave
//! in a few milliseconds. The run is refused ([`OpError::Preflight`], kind *refused*:
//! nothing was sent to the joint) with a [`Refusal`] naming the frame, its time, the joint
//! and the reason when, on the simulator:
//!
//! - a frame's set-point had to be held back to the step limit (the joint fell further
//!   behind the plan than its step protection allows: clamped);
//! - the joint latched error bits (a step fault, a following error, over-current, heat);
//! - the run failed (the joint did not follow, a protection stop, a move that did not
//!   arrive);
//! - the host's protection derated it.
//!
//! What the simulator does not model is in `docs/hardware.md` ("Pre-flight on the
//! simulator"): the load and friction on the real output, a drive weaker than its current
//! limit register says, the real loop gains (the simulator's position loop has its model's
//! bandwidth), other joints and traffic on the bus, and the real adapter's timing.

use std::fmt;
use std::time::Duration;

use schemars::JsonSchema;
use serde::Serialize;

use super::OpError;
pub use super::{PreflightReport, WhjSeed};
use crate::whj::Joint;

/// The longest plan (in its own time) a pre-flight runs by default: 60 s, simulated in
/// well under a second. Longer plans are simulated only when asked for.
pub const DEFAULT_MAX_PLAN: Duration = Duration::from_secs(60);

/// Whether a run asks for a pre-flight: `Some(true)` always, `Some(false)` never, `None`
/// (the default) when the plan lasts at most [`DEFAULT_MAX_PLAN`].
/// (Without the `sim` feature there is no simulator: the default is off.)
pub fn wanted(asked: Option<bool>, plan_length: Duration) -> bool {
    asked.unwrap_or(cfg!(feature = "sim") && plan_length <= DEFAULT_MAX_PLAN)
}

/// How long a plan's frames last, from the first to the last.
pub fn plan_length(plan: &super::whj::Plan) -> Duration {
    plan.frames.last().map_or(Duration::ZERO, |f| f.at)
}

/// Reads the seed of a pre-flight from the joint `j` (its identity, status and settings:
/// reads only, nothing written).
///
/// # Errors
///
/// The joint's error when it does not answer a read.
pub fn seed_whj(j: &Joint<'_>) -> Result<WhjSeed, OpError> {
    let identity = j.identity().map_err(OpError::Whj)?;
    let status = j.status().map_err(OpError::Whj)?;
    let mode = j.mode().map_err(OpError::Whj)?;
    let settings = super::whj::settings::backup(j.bus(), j.id())?;
    Ok(WhjSeed {
        id: j.id().get(),
        model: identity.model.to_string(),
        firmware: identity.firmware.to_string(),
        position_deg: status.position.degrees(),
        mode: super::whj::mode_name(mode).to_owned(),
        work_mode: mode,
        firmware_version: identity.firmware,
        enabled: status.is_enabled(),
        temperature_c: f64::from(status.temperature.celsius()),
        voltage_v: f64::from(status.voltage.volts()),
        settings_copied: settings.settings.len(),
        settings,
    })
}

/// Why a pre-flight refused a run: where in the plan the simulated joint went wrong.
#[derive(Debug, Clone, PartialEq, Serialize, JsonSchema)]
pub struct Refusal {
    /// The frame's index in the plan (0 = the first; the frame after the last one the
    /// simulator answered when the run failed between frames).
    pub frame: usize,
    /// Its time from the plan's start, s.
    pub at_s: f64,
    /// The joint (`joint 1`).
    pub joint: String,
    /// What happened on the simulator.
    pub reason: String,
}

/// How a pre-flight refusal ends: how to run it anyway, on the command line (a front end
/// with its own wording replaces it: [`crate::frontend::wording`]).
pub const ANYWAY: &str = "(--no-preflight runs it anyway)";

impl fmt::Display for Refusal {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "pre-flight on the simulator: frame {} at {:.3} s: {}: {}; nothing was sent \
             {ANYWAY}",
            self.frame, self.at_s, self.joint, self.reason
        )
    }
}

#[cfg(feature = "sim")]
pub use simulate::{Latched, SeededBus, seeded_bus, whj_move, whj_wave};

/// Why a frame is refused when the simulated joint lagged: its set-point was held back
/// `off` degrees short, to `sent` degrees.
pub fn clamped(off: f64, sent: f64) -> String {
    format!(
        "the joint lagged behind the plan: its set-point was clamped {off:.4} deg short, to \
         {sent:.4} deg, to keep within its step protection (on the joint a lagging motion \
         ends in the step fault or the run's hold-back)"
    )
}

/// Without the simulator (`sim` feature) there is no pre-flight.
///
/// # Errors
///
/// Always [`OpError::NotAvailable`].
#[cfg(not(feature = "sim"))]
pub fn whj_wave(
    _seed: &WhjSeed,
    _args: &super::whj::WaveArgs,
    _plan: &super::whj::Plan,
    _control: &super::Control<'_>,
) -> Result<PreflightReport, OpError> {
    Err(not_built())
}

/// Without the simulator (`sim` feature) there is no pre-flight.
///
/// # Errors
///
/// Always [`OpError::NotAvailable`].
#[cfg(not(feature = "sim"))]
pub fn whj_move(
    _seed: &WhjSeed,
    _args: &super::whj::MoveArgs,
    _plan: &super::whj::Plan,
    _control: &super::Control<'_>,
) -> Result<PreflightReport, OpError> {
    Err(not_built())
}

/// The refusal of a pre-flight asked for in a build without the simulator.
#[cfg(not(feature = "sim"))]
pub fn not_built() -> OpError {
    OpError::NotAvailable(
        "pre-flight: this build has no simulator (robobus's `sim` feature); run it with \
         --no-preflight"
            .into(),
    )
}

#[cfg(feature = "sim")]
mod simulate {
    use std::time::Duration;

    use robobus_sim::whj::{JointConfig, WhjBus, WhjModel, WhjSimHandle, WhjSimLink};
    use robobus_whj::reply::ServoFeedback;
    use robobus_whj::{JointId, WorkMode};

    use super::{PreflightReport, Refusal, WhjSeed};
    use crate::ops::protect::Action;
    use crate::ops::whj::{self as ops, FrameTimes, MoveArgs, Plan, WaveArgs};
    use crate::ops::{Control, OpError, SafeState};
    use crate::whj::{Joint, JointBus, JointBusConfig};

    /// The simulated model of a joint that identified as `model` (a WHJ10 is made with
    /// and without a brake under one code: simulated with it).
    fn sim_model(model: &str) -> Option<WhjModel> {
        WhjModel::ALL
            .into_iter()
            .find(|m| m.model().to_string() == model)
    }

    /// A simulated bus of the joints of `seeds`, each set up as the real one: its
    /// settings restored, its mode, its drive state; the bus on the virtual clock with
    /// the step limit `step_limit_deg`.
    ///
    /// # Errors
    ///
    /// [`OpError::NotAvailable`] for a joint the simulator has no model of;
    /// [`OpError::Device`] when a simulated joint could not be seeded.
    pub fn seeded_bus(seeds: &[WhjSeed], step_limit_deg: f64) -> Result<SeededBus, OpError> {
        let not_simulated = |what: String| {
            OpError::NotAvailable(format!(
                "pre-flight: {what}; run it without the pre-flight (--no-preflight)"
            ))
        };
        let mut configs = Vec::with_capacity(seeds.len());
        for seed in seeds {
            let model = sim_model(&seed.model)
                .ok_or_else(|| not_simulated(format!("the simulator has no {}", seed.model)))?;
            JointId::new(seed.id)
                .map_err(|_| not_simulated(format!("joint {} has no simulated ID", seed.id)))?;
            let mut cfg = JointConfig::new(seed.id, model).without_iap();
            cfg.firmware = seed.firmware_version;
            cfg.initial_position_deg = seed.position_deg;
            cfg.ambient_temp_c = seed.temperature_c;
            cfg.supply_voltage_v = seed.voltage_v;
            configs.push(cfg);
        }
        let (link, sim) = WhjSimLink::new(WhjBus::with_configs(configs, 1));
        let config = JointBusConfig {
            step_limit_deg,
            ..JointBusConfig::default()
        };
        let bus = JointBus::open_with(link, config).map_err(OpError::Whj)?;
        for seed in seeds {
            seed_joint(&bus, seed)?;
        }
        Ok(SeededBus { bus, sim })
    }

    /// Sets the simulated joint of `seed` up as the real one.
    fn seed_joint(bus: &JointBus, seed: &WhjSeed) -> Result<(), OpError> {
        let id = JointId::new(seed.id).map_err(|e| OpError::Device(e.to_string()))?;
        let simulated = |e: OpError| {
            OpError::Device(format!(
                "pre-flight: the simulated joint {} could not be seeded: {e}",
                seed.id
            ))
        };
        // Settings change only on a disabled drive (as on the real joint).
        bus.joint(id)
            .and_then(|j| j.disable())
            .map_err(|e| simulated(OpError::Whj(e)))?;
        ops::settings::restore(bus, id, &seed.settings, true).map_err(simulated)?;
        let j = bus.joint(id).map_err(OpError::Whj)?;
        if !matches!(seed.work_mode, WorkMode::Unknown(_)) {
            j.set_mode(seed.work_mode)
                .map_err(|e| simulated(OpError::Whj(e)))?;
        }
        if seed.enabled {
            j.enable().map_err(|e| simulated(OpError::Whj(e)))?;
        }
        Ok(())
    }

    /// A simulated WHJ bus seeded with real joints ([`seeded_bus`]).
    #[derive(Debug)]
    pub struct SeededBus {
        /// The bus, on the simulator's virtual clock.
        pub bus: JointBus,
        sim: WhjSimHandle,
    }

    impl SeededBus {
        /// The bus, and what tells the error bits its joints latched.
        pub fn into_parts(self) -> (JointBus, Latched) {
            (self.bus, Latched(self.sim))
        }
    }

    /// What tells the error bits a seeded bus's simulated joints latched.
    #[derive(Debug, Clone)]
    pub struct Latched(WhjSimHandle);

    impl Latched {
        /// Why joint `id` would refuse the run: the error bits it latched (`None`: none).
        pub fn reason(&self, id: u8) -> Option<String> {
            self.0
                .with_bus(|b| b.joint(id).map(|j| j.state().error))
                .filter(|e| !e.is_empty())
                .map(|error| format!("the joint latched error bits: {error}"))
        }
    }

    /// What the observer saw of the simulated run.
    #[derive(Default)]
    struct Seen {
        /// The last frame answered: index and time.
        last: Option<(usize, Duration)>,
        /// The first frame whose set-point was held back, with its time and how far.
        held_back: Option<(usize, Duration, f64, f64)>,
        frames: u64,
    }

    impl Seen {
        fn observe(&mut self, k: usize, _fb: Option<&ServoFeedback>, t: &FrameTimes) {
            self.frames += 1;
            self.last = Some((k, t.at));
            if t.held_back
                && self.held_back.is_none()
                && let Some((sent, off)) = t.set_point
            {
                self.held_back = Some((k, t.at, sent, off));
            }
        }

        /// The frame after the last answered one (where a failure between frames is
        /// placed), with its time.
        fn next(&self, plan: &Plan) -> (usize, f64) {
            let k = self.last.map_or(0, |(k, _)| k + 1);
            let at = plan
                .frames
                .get(k)
                .map(|f| f.at)
                .or(self.last.map(|(_, at)| at))
                .unwrap_or_default();
            (k, at.as_secs_f64())
        }
    }

    /// The refusal of a simulated run that ended `result`, or its report.
    fn judge(
        seed: &WhjSeed,
        plan: &Plan,
        observed: &Seen,
        sim: &Latched,
        result: Result<Vec<crate::ops::protect::Fault>, OpError>,
        started: std::time::Instant,
        bus: &JointBus,
    ) -> Result<PreflightReport, OpError> {
        let joint = format!("joint {}", seed.id);
        let refuse = |frame: usize, at_s: f64, reason: String| {
            OpError::Preflight(Box::new(Refusal {
                frame,
                at_s,
                joint: joint.clone(),
                reason,
            }))
        };
        if let Some((k, at, sent, off)) = observed.held_back {
            return Err(refuse(k, at.as_secs_f64(), super::clamped(off, sent)));
        }
        let latched = sim.reason(seed.id);
        match result {
            Err(e) => {
                let (k, at) = observed.next(plan);
                return Err(refuse(k, at, e.to_string()));
            }
            Ok(events) => {
                if let Some(f) = events.iter().find(|f| f.action >= Action::Derate) {
                    let k = plan
                        .frames
                        .iter()
                        .position(|p| p.at.as_secs_f64() >= f.at_s)
                        .unwrap_or(plan.frames.len());
                    return Err(refuse(k, f.at_s, f.to_string()));
                }
            }
        }
        if let Some(reason) = latched {
            let (k, at) = observed.next(plan);
            return Err(refuse(k.saturating_sub(1), at, reason));
        }
        Ok(PreflightReport {
            frames: observed.frames,
            simulated_s: bus.now().saturating_duration_since(started).as_secs_f64(),
            seed: seed.clone(),
        })
    }

    /// Runs `run` (a wave's or a move's execution, each frame observed) on the simulator
    /// seeded with `seed`, and judges what the simulated joint did.
    fn fly<R>(
        seed: &WhjSeed,
        (joint, step_limit_deg): (JointId, f64),
        plan: &Plan,
        control: &Control<'_>,
        run: impl FnOnce(&Joint<'_>, &mut Control<'_>, ops::FrameObserver<'_>) -> Result<R, OpError>,
        protection: impl FnOnce(R) -> Vec<crate::ops::protect::Fault>,
    ) -> Result<PreflightReport, OpError> {
        let (bus, sim) = seeded_bus(std::slice::from_ref(seed), step_limit_deg)?.into_parts();
        let j = bus.joint(joint).map_err(OpError::Whj)?;
        let started = bus.now();
        let mut observed = Seen::default();
        let mut inner = Control::new(control.token());
        let result = run(&j, &mut inner, &mut |k, fb, t| observed.observe(k, fb, t));
        if control.stopped() {
            return Err(OpError::Interrupted {
                detail: Some("during the pre-flight on the simulator; nothing was sent".into()),
            });
        }
        judge(
            seed,
            plan,
            &observed,
            &sim,
            result.map(protection),
            started,
            &bus,
        )
    }

    /// Runs a wave's `plan` on the simulator seeded with `seed` (see the
    /// [module docs](super)).
    ///
    /// # Errors
    ///
    /// [`OpError::Preflight`] naming the frame, its time, the joint and the reason;
    /// [`OpError::NotAvailable`] for a joint the simulator has no model of;
    /// [`OpError::Interrupted`] when `control` was stopped.
    pub fn whj_wave(
        seed: &WhjSeed,
        args: &WaveArgs,
        plan: &Plan,
        control: &Control<'_>,
    ) -> Result<PreflightReport, OpError> {
        fly(
            seed,
            (args.joint, args.step_limit_deg),
            plan,
            control,
            |j, inner, observe| {
                ops::execute_wave_observed(j, args, plan, inner, SafeState::Hold, observe)
            },
            |r| r.protection,
        )
    }

    /// Runs a move's `plan` on the simulator seeded with `seed` (see [`whj_wave`]).
    ///
    /// # Errors
    ///
    /// As [`whj_wave`]'s.
    pub fn whj_move(
        seed: &WhjSeed,
        args: &MoveArgs,
        plan: &Plan,
        control: &Control<'_>,
    ) -> Result<PreflightReport, OpError> {
        fly(
            seed,
            (args.joint, args.step_limit_deg),
            plan,
            control,
            |j, inner, observe| {
                ops::execute_move_observed(j, args, plan, inner, SafeState::Hold, observe)
            },
            |r| r.protection,
        )
    }
}
