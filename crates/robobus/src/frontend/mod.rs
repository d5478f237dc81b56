//! The front-end kit: what every front end (the web studio, the Zenoh bridge, the Python
//! package, the CLI) needs to take requests from its users safely, so that none of them
//! decides it on its own.
//!
//! - [`parse`]: one parser of a request (JSON text, bytes, a JSON value), one wording of
//!   every refusal.
//! - [`admission`]: whether a request runs now: read-only mode, arming, the write rate
//!   of non-volatile memory.
//! - [`plan_view`]: one JSON view of a plan.
//! - [`wording`]: each front end's name for a refused argument (`<IDS>` on the command
//!   line, `ids=` in Python).
//! - Front-end safety: [`guard`] (one controlling session, arming, the dead man's switch)
//!   and `live` (feature `sim`: the built-in robot on the wall clock). The bounded motions
//!   a front end sends through it are the station's: [`crate::station::jog`] (one bounded
//!   step of one device) and [`crate::station::follow`] (a robot's joint targets, checked
//!   whole; `robot.teleop` follows its leaders through it too).

pub mod admission;
pub mod guard;
#[cfg(feature = "sim")]
pub mod live;
pub mod parse;
pub mod plan_view;
pub mod wording;

pub use admission::{Admission, Admitted, Arming, FrontEnd, Refusal, RefusalKind};
pub use plan_view::PlanView;
pub use wording::Wording;
