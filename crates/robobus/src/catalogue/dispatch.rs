//! The one dispatcher: [`plan`] and [`run`] of every [`Request`], each through the
//! [`Operation`](super::operation::Operation) the request holds.

use robobus_wck::BaudRate;

use super::Request;
use super::bounds::refused;
use super::effect::{Effect, Moved};
use super::operation::{Interaction, NoInteraction, Operation, Report, RunCx};
use super::plan::Plan;
use super::registry::DynOperation;
use crate::ops::{Control, OpError};
use crate::station::Station;

/// The plan of `request`: the exact packets / frames a run sends (its text form is what
/// the CLI's `--dry-run` prints), validated against the protocol's ranges and the host
/// bounds. Nothing is opened; the wCK packets are shown at 115200 bit/s (`wck.scan`
/// scans at that rate).
pub fn plan(request: &Request) -> Result<Plan, OpError> {
    plan_at(request, BaudRate::B115200)
}

/// [`plan`] with the wCK packets shown at `baud` (the rate of the port a run would use;
/// `wck.scan` starts there). WHJ plans do not depend on it.
pub fn plan_at(request: &Request, baud: BaudRate) -> Result<Plan, OpError> {
    request.operation().plan(baud)
}

/// Validates `request` as [`run`] will, without a station: its arguments against the
/// protocol's ranges and the host bounds. (A plan of a WHJ current target needs the
/// joint's model; a run reads it from the joint, so this does not ask for it.)
pub fn validate(request: &Request) -> Result<(), OpError> {
    request.operation().check().map(drop)
}

/// What `request` needs confirmed before it runs (the text a front end asks the user,
/// the CLI's prompt), validated as [`run`] validates it; `None` when it runs without
/// confirmation or carries `confirm: true` already.
pub fn confirmation(request: &Request) -> Result<Option<String>, OpError> {
    asked(request.operation())
}

/// What `op` asks before it runs (validated), `None` once it carries `confirm: true`.
fn asked(op: &dyn DynOperation) -> Result<Option<String>, OpError> {
    let confirm = op.check()?;
    Ok(if op.confirmed() { None } else { confirm.text })
}

/// Runs `request` on the station's bus it names (or the station's only bus of the
/// family): validates it, refuses it when it needs confirmation and lacks it, or when it
/// is a motion of a joint off its position interface ([`crate::station::interfaces`])
/// ([`crate::ErrorKind::Refused`], nothing sent), then runs the operation with
/// `control`'s stop token and progress. Device failures are in the report (`failed`);
/// an error is a failure of the whole request.
pub fn run(
    station: &Station,
    request: &Request,
    control: &mut Control<'_>,
) -> Result<Report, OpError> {
    run_with(station, request, control, &mut NoInteraction)
}

/// [`run`] with a front end's [`Interaction`] (key presses and live poses of a teach).
pub fn run_with(
    station: &Station,
    request: &Request,
    control: &mut Control<'_>,
    interaction: &mut dyn Interaction,
) -> Result<Report, OpError> {
    if let Some(text) = confirmation(request)? {
        return Err(refused(&text));
    }
    off_position(station, request.operation().effect(), || {
        request.operation().moved()
    })?;
    let mut cx = RunCx {
        station,
        control,
        interaction,
    };
    request.operation().run(&mut cx)
}

/// Refuses a motion whose moved devices include a joint off its position interface
/// (see [`crate::station::interfaces`]); nothing sent.
fn off_position(
    station: &Station,
    effect: Effect,
    moved: impl FnOnce() -> Result<Option<Moved>, OpError>,
) -> Result<(), OpError> {
    if effect == Effect::Motion
        && let Some(m) = moved()?
    {
        station
            .interfaces()
            .check_moved(m.family, m.bus.as_deref(), &m.ids)?;
    }
    Ok(())
}

/// [`run_with`] of one operation, its report typed: a Rust front end gets the
/// operation's own rows and summary.
pub fn run_typed<O: Operation>(
    station: &Station,
    operation: &O,
    control: &mut Control<'_>,
    interaction: &mut dyn Interaction,
) -> Result<Report<O::Row, O::Summary>, OpError> {
    if let Some(text) = asked(operation)? {
        return Err(refused(&text));
    }
    off_position(station, operation.effect(), || operation.moved())?;
    let mut cx = RunCx {
        station,
        control,
        interaction,
    };
    operation.run(&mut cx)
}
