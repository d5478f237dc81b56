//! What a request does to its devices ([`Effect`]), and which devices it sets moving
//! ([`Moved`]): the facts a front end's safety rules are built on (a read-only server
//! serves reads only; motion needs arming; a lost operator brings the moved devices to
//! their safe state).

use serde::Serialize;

use super::Family;
use crate::ops::whj::ServoLoop;

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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::catalogue::Request;

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
