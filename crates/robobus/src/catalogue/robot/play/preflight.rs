//! `robot.play`'s pre-flight on the simulator ([`crate::ops::preflight`] for a whole
//! robot): before the first tick of a play of positions, each WHJ joint of the trajectory
//! is read as `whj wave`'s pre-flight reads its joint ([`seed_whj`]: identity, status,
//! mode, settings), each WHJ bus of the robot file gets a simulated bus of those joints
//! ([`seeded_bus`], on the simulator's virtual clock, with the real bus's step limit), and
//! the play runs on them through the real run's own [`Player`] from the lead-in to the
//! last point (the same targets, the same hold-back to the step limit, the same host
//! protection), faster than real time. It is refused ([`OpError::Preflight`], nothing sent)
//! naming the tick, its time, the joint and the reason when a simulated joint's target is
//! held back to its step limit (it lagged), a command fails, the protection derates or
//! stops a joint, the run fails, or a joint latches error bits.
//!
//! wCK servos are not pre-flown: their simulator models no load and no lag a position
//! command could be refused for (a wCK servo takes any target in its range and the play
//! never holds one back), so the play's wCK columns are left out of the simulated run
//! (their ticks command nothing) and named in the report's `not_flown`.

use schemars::JsonSchema;
use serde::Serialize;

use super::{Group, Play};
#[cfg(feature = "sim")]
use crate::ops::Control;
use crate::ops::OpError;
use crate::ops::preflight::{self, WhjSeed};
#[cfg(feature = "sim")]
use crate::ops::preflight::{Refusal, seed_whj, seeded_bus};
use crate::robot::RobotConfig;
use crate::robot::trajectory::Trajectory;

/// A play's pre-flight that passed: what was simulated, from what seeds.
#[derive(Debug, Clone, PartialEq, Serialize, JsonSchema)]
pub struct PlayPreflight {
    /// Ticks the simulated play ran (the real run's: from the lead-in to the last point).
    pub ticks: u64,
    /// The simulated play's length, s (simulated time).
    pub simulated_s: f64,
    /// The WHJ joints flown, in the trajectory's order, each with the seed read from it.
    pub joints: Vec<FlownJoint>,
    /// The trajectory's wCK servos, by name: not pre-flown (their ticks command nothing
    /// on the simulators).
    pub not_flown: Vec<String>,
}

/// A WHJ joint of a play's pre-flight.
#[derive(Debug, Clone, PartialEq, Serialize, JsonSchema)]
pub struct FlownJoint {
    /// The joint, by its name in the robot file.
    pub joint: String,
    /// Its bus, by the robot file's name.
    pub bus: String,
    /// What was read from it and seeded the simulated joint.
    pub seed: WhjSeed,
}

/// The plan's words on the pre-flight of a play of positions lasting `duration_s` (empty
/// when it does not run), ending with `; `.
pub(super) fn note(asked: Option<bool>, duration_s: f64) -> String {
    let length =
        std::time::Duration::try_from_secs_f64(duration_s).unwrap_or(std::time::Duration::MAX);
    if !preflight::wanted(asked, length) {
        return String::new();
    }
    "pre-flight: the WHJ joints' identity, status, mode and settings (whj backup's \
     registers) are read, and the play (its lead-in and every tick) runs first on WHJ \
     simulators seeded with them, faster than real time; a target a simulated joint could \
     not follow (held back to its step limit), error bits it latched, a failed command or a \
     protection derating refuse the play, naming the tick, its time, the joint and the \
     reason, nothing sent (wCK servos are not pre-flown; --no-preflight plays without); "
        .to_owned()
}

/// Runs the play `r` first on WHJ simulators seeded with its WHJ joints (the real ones of
/// `groups`), from their positions `from` after the lead-in `lead_in` (see the
/// [module docs](self)); `None` when not asked for, or the trajectory has no WHJ joint.
///
/// # Errors
///
/// [`OpError::Preflight`] naming the tick, its time, the joint and the reason; a real
/// joint's error when a seed could not be read; [`OpError::NotAvailable`] for a joint
/// the simulator has no model of (or a build without it);
/// [`OpError::Interrupted`] when `control` was stopped.
#[cfg(feature = "sim")]
pub(super) fn fly(
    r: &Play,
    config: &RobotConfig,
    (traj, index): (&Trajectory, &[usize]),
    groups: &[Group],
    (from, lead_in): (&[f64], f64),
    control: &Control<'_>,
) -> Result<Option<PlayPreflight>, OpError> {
    let length = std::time::Duration::try_from_secs_f64(traj.duration_s())
        .unwrap_or(std::time::Duration::MAX);
    if !preflight::wanted(r.preflight.asked(), length) {
        return Ok(None);
    }
    let started = std::time::Instant::now();
    let Some(seeded) = seed(groups, traj.joints())? else {
        return Ok(None);
    };
    let seeded_in = started.elapsed();
    // The robot file on the simulators: its WHJ buses only (the wCK columns command
    // nothing), its joints as they are (the trajectory's columns index them).
    let mut sim_config = config.clone();
    sim_config
        .buses
        .retain(|name, _| seeded.latched.iter().any(|(bus, ..)| bus == name));
    let (sim_groups, clock) = super::groups(&seeded.station, &sim_config, traj, index)?;
    let models = super::models_of(index, &sim_groups);
    let mut player = super::Player::new(
        r,
        config,
        (traj, index),
        (&sim_groups, &clock),
        (from, lead_in),
        &models,
    )?;
    let flown: Vec<usize> = sim_groups.iter().flat_map(Group::columns).collect();
    let mut rows: Vec<super::Played> = from.iter().map(|&s| super::Played::new(s)).collect();
    let mut inner = Control::new(control.token());
    let start = clock.now();
    let mut seen = Seen::default();
    let run = player.run(&mut rows, &mut inner, &mut |t| {
        seen.tick(&flown, t);
        Ok(())
    });
    if control.stopped() {
        return Err(OpError::Interrupted {
            detail: Some("during the pre-flight on the simulator; nothing was sent".into()),
        });
    }
    seen.simulated_s = clock.now().saturating_duration_since(start).as_secs_f64();
    let names = traj.joints();
    let judged = Judged {
        names,
        groups: &sim_groups,
        rate_hz: r.rate_hz,
    };
    judged.judge(&player, &rows, &seen, run.map(|_| ()), &seeded.latched)?;
    tracing::debug!(
        "pre-flight of the play: {} joints seeded in {seeded_in:?}, {} ticks ({:.3} s) \
         simulated in {:?}",
        seeded.joints.len(),
        seen.ticks,
        seen.simulated_s,
        started.elapsed().saturating_sub(seeded_in)
    );
    Ok(Some(PlayPreflight {
        ticks: seen.ticks,
        simulated_s: seen.simulated_s,
        joints: seeded.joints,
        not_flown: (0..names.len())
            .filter(|c| !flown.contains(c))
            .filter_map(|c| names.get(c).cloned())
            .collect(),
    }))
}

/// The simulated buses of a play's WHJ joints.
#[cfg(feature = "sim")]
struct Seeded {
    station: crate::station::Station,
    joints: Vec<FlownJoint>,
    /// Per simulated bus: its name, its joints, what tells their error bits.
    latched: Vec<(String, Vec<u8>, preflight::Latched)>,
}

/// Reads the seed of every WHJ joint of `groups` (reads only) and makes a simulated bus
/// of each group's; `None` when there is none.
#[cfg(feature = "sim")]
fn seed(groups: &[Group], names: &[String]) -> Result<Option<Seeded>, OpError> {
    let mut station = crate::station::Station::new();
    let mut joints = Vec::new();
    let mut latched = Vec::new();
    for g in groups {
        let Group::Whj(h, port, cols) = g else {
            continue;
        };
        let mut seeds = Vec::with_capacity(cols.len());
        for (&(c, _), id) in cols.iter().zip(h.ids()) {
            let joint =
                robobus_whj::JointId::new(id).map_err(|e| OpError::Device(e.to_string()))?;
            let seed = seed_whj(&port.bus().joint(joint).map_err(OpError::Whj)?)?;
            joints.push(FlownJoint {
                joint: names.get(c).cloned().unwrap_or_default(),
                bus: h.bus().to_owned(),
                seed: seed.clone(),
            });
            seeds.push(seed);
        }
        let (bus, errors) = seeded_bus(&seeds, h.step_limit_deg()?)?.into_parts();
        station.add_whj(h.bus(), bus);
        latched.push((h.bus().to_owned(), h.ids(), errors));
    }
    Ok((!joints.is_empty()).then_some(Seeded {
        station,
        joints,
        latched,
    }))
}

/// What the simulated play's ticks showed.
#[cfg(feature = "sim")]
#[derive(Debug, Default)]
struct Seen {
    ticks: u64,
    simulated_s: f64,
    /// The first tick a flown joint did not answer: the tick, its time, the column.
    failed: Option<(u64, f64, usize)>,
}

#[cfg(feature = "sim")]
impl Seen {
    fn tick(&mut self, flown: &[usize], t: &super::PlayTick<'_>) {
        if self.failed.is_none()
            && let Some(&c) = flown
                .iter()
                .find(|&&c| t.positions.get(c).is_some_and(Option::is_none))
        {
            self.failed = Some((self.ticks, t.t_s, c));
        }
        self.ticks += 1;
    }
}

/// Judges a simulated play: its trajectory's joint names, the simulated groups, its rate.
#[cfg(feature = "sim")]
struct Judged<'a> {
    names: &'a [String],
    groups: &'a [Group],
    rate_hz: f64,
}

#[cfg(feature = "sim")]
impl Judged<'_> {
    /// Who column `c` is: its name, joint and bus (`j1 (joint 1 on arm)`).
    fn who(&self, c: usize) -> String {
        let name = self.names.get(c).map_or("?", String::as_str);
        self.groups
            .iter()
            .find_map(|g| match g {
                Group::Whj(h, _, cols) => {
                    let k = cols.iter().position(|x| x.0 == c)?;
                    Some(format!("{name} (joint {} on {})", h.ids().get(k)?, h.bus()))
                }
                Group::Wck(..) => None,
            })
            .unwrap_or_else(|| name.to_owned())
    }

    /// The tick at or after `at_s`.
    #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)] // ≤ 1 h × 500 Hz
    fn tick_of(&self, at_s: f64) -> u64 {
        (at_s * self.rate_hz - 1e-6).ceil().max(0.0) as u64
    }

    /// The refusal of what the simulated play did, if any: the earliest of a derating or
    /// stop, a failed command and a target held back (at the same tick in that order: a
    /// derating holds its joint's targets back too); then a failed run; then error bits.
    fn judge(
        &self,
        player: &super::Player<'_>,
        rows: &[super::Played],
        seen: &Seen,
        run: Result<(), OpError>,
        latched: &[(String, Vec<u8>, preflight::Latched)],
    ) -> Result<(), OpError> {
        let refuse = |tick: u64, at_s: f64, joint: String, reason: String| {
            Err(OpError::Preflight(Box::new(Refusal {
                frame: usize::try_from(tick).unwrap_or(usize::MAX),
                at_s,
                joint,
                reason,
            })))
        };
        let mut first: Vec<(u64, f64, String, String)> = Vec::new();
        if let Some(f) = player
            .faults
            .iter()
            .find(|f| f.action >= crate::ops::protect::Action::Derate)
        {
            let c = self
                .names
                .iter()
                .position(|n| *n == f.joint)
                .unwrap_or(usize::MAX);
            first.push((self.tick_of(f.at_s), f.at_s, self.who(c), f.to_string()));
        }
        if let Some((tick, t_s, c)) = seen.failed {
            let why = rows
                .get(c)
                .and_then(|row| row.last_error.as_ref())
                .map_or_else(|| "it did not answer".to_owned(), |f| f.error.clone());
            first.push((tick, t_s, self.who(c), format!("a command failed: {why}")));
        }
        if let Some(h) = player.held_back {
            first.push((
                h.tick,
                h.t_s,
                self.who(h.column),
                preflight::clamped((h.target - h.sent).abs(), h.sent),
            ));
        }
        if let Some((tick, at_s, joint, reason)) = first.into_iter().min_by_key(|x| x.0) {
            return refuse(tick, at_s, joint, reason);
        }
        if let Err(e) = run {
            return refuse(
                seen.ticks,
                seen.simulated_s,
                self.names.join(", "),
                e.to_string(),
            );
        }
        for (bus, ids, errors) in latched {
            for &id in ids {
                if let Some(reason) = errors.reason(id) {
                    let column = self.groups.iter().find_map(|g| match g {
                        Group::Whj(h, _, cols) if h.bus() == bus => {
                            let k = h.ids().iter().position(|&x| x == id)?;
                            cols.get(k).map(|x| x.0)
                        }
                        _ => None,
                    });
                    let joint =
                        column.map_or_else(|| format!("joint {id} on {bus}"), |c| self.who(c));
                    return refuse(
                        seen.ticks.saturating_sub(1),
                        seen.simulated_s,
                        joint,
                        reason,
                    );
                }
            }
        }
        Ok(())
    }
}

/// Without the simulator (`sim` feature) there is no pre-flight: `None` unless asked for.
///
/// # Errors
///
/// [`OpError::NotAvailable`] when asked for.
#[cfg(not(feature = "sim"))]
pub(super) fn fly(
    r: &Play,
    _config: &RobotConfig,
    _traj: (&Trajectory, &[usize]),
    _groups: &[Group],
    _from: (&[f64], f64),
    _control: &crate::ops::Control<'_>,
) -> Result<Option<PlayPreflight>, OpError> {
    if r.preflight.asked() == Some(true) {
        return Err(preflight::not_built());
    }
    Ok(None)
}
