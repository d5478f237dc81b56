//! What a request does to its devices ([`Effect`]), and which devices it sets moving
//! ([`Moved`]): the facts a front end's safety rules are built on (a read-only server
//! serves reads only; motion needs arming; a lost operator brings the moved devices to
//! their safe state).

use serde::Serialize;

use super::{Family, Request, wck, whj};
use robobus_wck::ServoId;
use robobus_whj::JointId;

use crate::ops::whj::ServoLoop;
use crate::ops::{ListId, OpError};

/// What a request does to its devices.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Effect {
    /// Reads only (status, registers, scans, plans): nothing on a device changes.
    Read,
    /// Changes a device's settings or state without setting it moving (gains, IDs,
    /// modes, saves, making it passive or disabling it).
    Configure,
    /// Moves or energises a device (moves, waves, speed and current targets, enabling a
    /// drive, playing or teaching a motion, uploading a wCK motion program, which the
    /// servo starts running at once).
    Motion,
}

impl Effect {
    /// Its name (`"read"`, `"configure"`, `"motion"`).
    pub const fn name(self) -> &'static str {
        match self {
            Self::Read => "read",
            Self::Configure => "configure",
            Self::Motion => "motion",
        }
    }
}

/// The devices a motion request sets moving, and the loop a WHJ joint then runs (what a
/// hold sends it).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Moved {
    /// The family.
    pub family: Family,
    /// The bus the request names (`None`: the station's only one).
    pub bus: Option<String>,
    /// The devices.
    pub ids: Vec<u8>,
    /// For WHJ joints: the loop they run.
    pub servo: ServoLoop,
}

impl Request {
    /// What the request does to its devices (for an operation not yet in a file of its
    /// own).
    pub(super) const fn legacy_effect(&self) -> Effect {
        match self {
            Self::WckMove(_)
            | Self::WckMove10(_)
            | Self::WckSyncMove(_)
            | Self::WckWheel(_)
            | Self::WckPlay(_)
            | Self::WckTeach(_)
            | Self::WckTune(_)
            // An uploaded program starts at once: the servo runs it by itself.
            | Self::WckProgramUpload(_)
            | Self::WhjEnable(_)
            | Self::WhjMove(_)
            | Self::WhjSpeed(_)
            | Self::WhjCurrent(_)
            | Self::WhjWave(_)
            | Self::RobotTeleop(_)
            | Self::RobotPlay(_)
            // Limp joints: an arm falls unless held.
            | Self::RobotTeach(_) => Effect::Motion,
            Self::WckPassive(_)
            | Self::WckBrake(_)
            | Self::WckSet(_)
            | Self::WckSetId(_)
            | Self::WckSetBaud(_)
            | Self::WhjDisable(_)
            | Self::WhjMode(_)
            | Self::WhjZero(_)
            | Self::WhjClear(_)
            | Self::WhjSave(_)
            | Self::WhjWrite(_)
            | Self::WhjSetId(_)
            | Self::WhjSetRates(_)
            | Self::WhjRestore(_)
            | Self::WckRestore(_)
            // wCK servos made passive while the joints are moved by hand.
            | Self::RobotCalibrate(_) => Effect::Configure,
            Self::WckScan(_)
            | Self::WckStatus(_)
            | Self::WckRead10(_)
            | Self::WckGet(_)
            | Self::WckProgramDownload(_)
            | Self::WckProgramCheck(_)
            | Self::WckSample(_)
            | Self::WhjScan(_)
            | Self::WhjInfo(_)
            | Self::WhjStatus(_)
            | Self::WhjRegisters(_)
            | Self::WhjReleaseIap(_)
            | Self::WhjRead(_)
            | Self::WhjSample(_)
            | Self::WhjBackup(_)
            | Self::WhjDefaults(_)
            | Self::WhjCanHealth(_)
            | Self::WhjDiff(_)
            | Self::WckBackup(_)
            | Self::WckDiff(_)
            | Self::RobotSample(_)
            | Self::HostPorts(_) => Effect::Read,
            #[cfg(test)]
            Self::TestEcho(_) => Effect::Read,
            Self::WhjEndBoard(r) => match (r.action, r.volts) {
                (super::whj::EndBoardAction::Status | super::whj::EndBoardAction::Force, _) => {
                    Effect::Read
                }
                // Power on for a tool can make it move (a gripper).
                (super::whj::EndBoardAction::Power, Some(v)) if v > 0 => Effect::Motion,
                _ => Effect::Configure,
            },
        }
    }

    /// The devices a [`Effect::Motion`] request sets moving (`None` for any other
    /// request), validated as a run validates them.
    #[allow(clippy::result_large_err)] // OpError carries the client errors by value
    pub(super) fn legacy_moved(&self) -> Result<Option<Moved>, OpError> {
        let wck = |ids: Vec<u8>| Moved {
            family: Family::Wck,
            bus: self.bus().map(str::to_owned),
            ids,
            servo: ServoLoop::Position,
        };
        let whj = |ids: Vec<u8>, servo| Moved {
            family: Family::Whj,
            bus: self.bus().map(str::to_owned),
            ids,
            servo,
        };
        let one = |id: u32| vec![u8::try_from(id).unwrap_or(u8::MAX)];
        super::validate(self)?;
        Ok(Some(match self {
            Self::WckMove(r) => wck(one(r.id)),
            Self::WckMove10(r) => wck(one(r.id)),
            Self::WckWheel(r) => wck(one(r.id)),
            Self::WckTune(r) => wck(one(r.id)),
            Self::WckProgramUpload(r) => wck(one(r.id)),
            Self::WckSyncMove(r) => wck(count(r.positions.len())),
            Self::WckTeach(r) => wck(ids::<ServoId>(&r.ids, "ids")?),
            Self::WckPlay(_) => {
                let prepared = wck::prepare(self, robobus_wck::BaudRate::B115200)?;
                let wck::Job::Play(motion, ..) = prepared.job else {
                    return Ok(None);
                };
                let servos = motion.frames.iter().filter_map(|f| match f {
                    crate::ops::wck::Frame::Pose(p) => Some(p.positions.len()),
                    crate::ops::wck::Frame::Hold(_) => None,
                });
                wck(count(servos.max().unwrap_or(0)))
            }
            Self::WhjEnable(r) => whj(ids::<JointId>(&r.joints, "joints")?, ServoLoop::Position),
            Self::WhjMove(r) => whj(one(r.joint), ServoLoop::Position),
            Self::WhjSpeed(r) => whj(one(r.joint), ServoLoop::Speed),
            Self::WhjCurrent(r) => whj(one(r.joint), ServoLoop::Current),
            Self::WhjWave(r) => whj(
                one(r.joint),
                match r.mode {
                    whj::WaveMode::Position => ServoLoop::Position,
                    whj::WaveMode::Speed => ServoLoop::Speed,
                    whj::WaveMode::Current => ServoLoop::Current,
                },
            ),
            _ => return Ok(None),
        }))
    }
}

/// Servos `0..n`.
fn count(n: usize) -> Vec<u8> {
    (0..n).filter_map(|i| u8::try_from(i).ok()).collect()
}

#[allow(clippy::result_large_err)] // OpError carries the client errors by value
fn ids<T: ListId>(list: &super::args::Ids, option: &str) -> Result<Vec<u8>, OpError> {
    list.parse::<T>(option).map(|v| {
        v.into_iter()
            .filter_map(|i| u8::try_from(i.raw()).ok())
            .collect()
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn req(json: &str) -> Request {
        serde_json::from_str(json).unwrap()
    }

    #[test]
    fn effects_and_moved_devices() {
        assert_eq!(
            req(r#"{"op":"wck.status","ids":"0-2"}"#).effect(),
            Effect::Read
        );
        assert_eq!(
            req(r#"{"op":"whj.save","joints":"1"}"#).effect(),
            Effect::Configure
        );
        let wave = req(r#"{"op":"whj.wave","joint":3,"mode":"speed","amplitude":1}"#);
        assert_eq!(wave.effect(), Effect::Motion);
        let m = wave.moved().unwrap().unwrap();
        assert_eq!(
            (m.family, m.ids, m.servo),
            (Family::Whj, vec![3], ServoLoop::Speed)
        );
        let sync = req(r#"{"op":"wck.sync-move","positions":[1,2,3]}"#);
        assert_eq!(sync.moved().unwrap().unwrap().ids, vec![0, 1, 2]);
        let en = req(r#"{"op":"whj.enable","joints":"2-4","bus":"arm"}"#);
        let m = en.moved().unwrap().unwrap();
        assert_eq!((m.ids, m.bus.as_deref()), (vec![2, 3, 4], Some("arm")));
        assert_eq!(
            req(r#"{"op":"whj.status","joints":"1"}"#).moved().unwrap(),
            None
        );
        // A request that does not validate names what is wrong.
        let bad = req(r#"{"op":"wck.move","id":40,"position":3}"#);
        assert_eq!(bad.moved().unwrap_err().kind(), crate::ErrorKind::BadInput);
    }
}
