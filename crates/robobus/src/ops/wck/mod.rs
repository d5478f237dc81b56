//! wCK operations: every `robobus wck` command as a library call.
//!
//! Each operation takes typed, validated arguments, first computes its plan
//! ([`WckPlan`]: the exact packets with the time each is due) and then either hands the
//! plan back (a dry-run) or executes that same plan on a [`WckBus`]. Where a plan depends
//! on the device, the plan's notes say what it assumed ([`ASSUMED_POSITION`] for a hold,
//! silent IDs for a scan) and the real run uses the measured value.
//!
//! | operation | plan | run | report |
//! |---|---|---|---|
//! | scan (one rate / all rates) | [`ScanArgs::plan`] | [`scan`] | [`ScanOpReport`] |
//! | status, move, move10, read10, sync-move, passive, brake, get / set parameters, set-id, set-baud, program upload / download | [`WckPlan::one`], [`WckPlan::push`] | [`run_steps`] ([`run_steps_with`]: rows of the caller's type) | [`StepsReport`] |
//! | wheel (timed, watched) | [`WheelArgs::plan`] | [`wheel`] | [`WheelReport`] |
//! | play a keyframe motion | [`Motion::moves`] (streamed) | [`play`] | [`PlayReport`] |
//! | teach | [`TeachArgs::plan`] | [`teach`] (each pose to the caller as recorded) | [`TeachReport`] |
//! | safe stop | | [`SafeState::apply`] with [`WckServos`](crate::ops::safe::WckServos) | |
//!
//! # Report schema (the CLI's `--json`)
//!
//! Every report derives [`serde::Serialize`]; field names carry their units: `position`
//! (0..=254 steps, 269/255 degrees each), `position10` (0..=1023), `degrees`, `load`,
//! `milliamps`, `baud` (bit/s), `adc_volts`, `*_ms`.
//!
//! - [`StepsReport`]: `{"port", "baud", "command", "results": [...]}` with one result per
//!   packet: `{"id", ...fields}` (see [`reply_fields`]) or, for a servo that failed,
//!   `{"id", "kind", "error"}` ([`crate::ops::Failure`]). A move's reply is the status
//!   before it (`load_before`, `position_before`). A break's `meaning` says what a reply
//!   on a shared bus can tell ([`BREAK_CLEAN`], [`BREAK_COLLIDED`]).
//! - [`ScanOpReport`]: `{"port", "bauds_tried", "found": [{"id", "baud", "load",
//!   "position", "degrees"}], "duplicates": [{"id", "baud", "evidence"}]}`.
//! - [`WheelReport`]: the wheel command's result, plus `ran_ms` and `stopped` for a timed run.
//! - [`PlayReport`]: `{"port", "command", "moves", "sent", "planned_ms", "duration_ms",
//!   "last_positions"}`.
//! - [`TeachReport`]: `{"poses"}`; each [`Pose`] is `{"ms", "positions"}`.
//! - A dry-run ([`WckPlan::dry_run`]): `{"dry_run": true, "bus": {"kind", "port", "baud"},
//!   "notes", "packets": [{"t_ms", "baud", "command", "target", "hex", "bytes",
//!   "reply_len"}]}`.
//!
//! # Stop, progress, safe state
//!
//! Long operations (scan, timed wheel, play, teach) take a [`Control`](crate::ops::Control):
//! they report [`Progress`](crate::ops::Progress) and look at its stop token between
//! packets and while they wait. On a stop they bring the servos to the caller's
//! [`SafeState`] through [`SafeState::apply`] (the same function the robot watchdog uses) and return
//! [`OpError::Interrupted`](crate::ops::OpError::Interrupted).
//!
//! A timed wheel run on the simulator, stopped from another thread:
//!
//! ```
//! use std::time::Duration;
//! use robobus::ops::{Control, Progress, SafeState, StopToken};
//! use robobus::ops::wck::{WheelArgs, wheel};
//! use robobus::wck::WckBus;
//! use robobus_sim::wck::{Bus, BusConfig, Model, SimLink};
//! use robobus_wck::{BaudRate, Rotation, ServoId, WheelSpeed};
//!
//! let (link, _sim) = SimLink::new(Bus::with_servos(BusConfig::default(), Model::W1108, [0, 1]));
//! std::thread::sleep(Duration::from_millis(70)); // the modules power up
//! let mut bus = WckBus::new(link, BaudRate::B115200)?;
//! let args = WheelArgs {
//!     id: ServoId::new(1)?,
//!     rotation: Rotation::Ccw,
//!     speed: WheelSpeed::new(10)?,
//!     duration: Some(Duration::from_secs(30)),
//!     on_stop: SafeState::Passive,
//! };
//! let stop = StopToken::new();
//! let stopper = stop.clone();
//! let mut seen = 0;
//! let mut on_progress = |p: &Progress| {
//!     seen += 1;
//!     if p.done >= 400 {
//!         stopper.stop(); // e.g. a Ctrl-C handler or a web request
//!     }
//! };
//! let mut control = Control::new(&stop).with_progress(&mut on_progress);
//! let err = wheel(&mut bus, &args, &mut control).unwrap_err();
//! drop(control);
//! assert!(err.to_string().contains("passive"), "{err}");
//! assert!(seen >= 3);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

mod motion;
mod plan;
mod report;
mod run;
pub mod settings;
mod shared;
pub mod tune;

pub use motion::{
    FORMAT_HELP, Frame, MOTION_FILE_LIMIT, Motion, MotionWriter, Moves, PLAY_WATCH_MS, ParseError,
    Pose,
};
pub use plan::{DryRun, DryRunBus, PlanPacket, WckPlan, WckStep, step_line};
pub use report::{BREAK_CLEAN, BREAK_COLLIDED, FieldValue, Fields, reply_fields};
pub use run::{
    ASSUMED_POSITION, Found, PlayReport, ScanArgs, ScanOpReport, SharedId, StepResult, StepsReport,
    TeachArgs, TeachEvent, TeachReport, TeachTrigger, WHEEL_WATCH_PERIOD, WheelArgs, WheelReport,
    check_rate, confirm_reads_for, play, run_steps, run_steps_with, scan, target_value, teach,
    wheel,
};
pub use shared::{SharedServo, SharedWckBus};

pub use crate::ops::SafeState;
pub use crate::wck::WckBus;
