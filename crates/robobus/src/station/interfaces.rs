//! Which of a station's joints are off their position interface: switched to velocity or
//! effort by the station's [`Driver`](super::follow::drive::Driver) (the bridge's
//! `NS/robobus/interface`), and not yet switched back.
//!
//! A motion of positions for such a joint would fight the velocity or effort it is given
//! (or, a WHJ joint in speed or current mode, be refused by the joint itself halfway), so
//! the station refuses it before anything is sent, naming the joint and its interface:
//! a `robot.play` (a ROS 2 trajectory included) or `robot.teleop` of it (its readiness
//! check), any run whose moved devices include it (`wck.move`, `whj.move`, `whj.wave`,
//! ...: the catalogue's dispatcher asks [`Interfaces::check_moved`]) and a jog of it. Switching the joint back to position lifts it.

use std::sync::{Mutex, PoisonError};

use crate::ops::{Family, OpError};
use crate::robot::Interface;

/// A joint off its position interface.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct OffPosition {
    /// Its name in the robot file.
    pub joint: String,
    /// Its family.
    pub family: Family,
    /// Its bus, as the robot file names it.
    pub bus: String,
    /// Its ID on that bus.
    pub id: u8,
    /// The interface it is on.
    pub interface: Interface,
}

/// The joints off their position interface (see the [module docs](self)).
#[derive(Debug, Default)]
pub struct Interfaces {
    off: Mutex<Vec<OffPosition>>,
}

fn refusal(off: &[&OffPosition]) -> OpError {
    let list: Vec<String> = off
        .iter()
        .map(|o| format!("{} is on its {} interface", o.joint, o.interface))
        .collect();
    OpError::Refused(format!(
        "{}: a motion of positions needs it on its position interface; switch it back to \
         position first; nothing was sent",
        list.join(", ")
    ))
}

impl Interfaces {
    fn lock(&self) -> std::sync::MutexGuard<'_, Vec<OffPosition>> {
        self.off.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// Records that `joint` is now on `joint.interface` (back on position: no longer
    /// listed).
    pub fn set(&self, joint: OffPosition) {
        let mut off = self.lock();
        off.retain(|o| o.joint != joint.joint);
        if joint.interface != Interface::Position {
            off.push(joint);
        }
    }

    /// The joints off position now.
    pub fn off_position(&self) -> Vec<OffPosition> {
        self.lock().clone()
    }

    /// Refuses a motion of positions of the joints `names` when one is off position.
    ///
    /// # Errors
    ///
    /// [`OpError::Refused`] naming each such joint and its interface.
    pub fn check_joints(&self, names: &[String]) -> Result<(), OpError> {
        let off = self.lock();
        let hit: Vec<&OffPosition> = off.iter().filter(|o| names.contains(&o.joint)).collect();
        if hit.is_empty() {
            Ok(())
        } else {
            Err(refusal(&hit))
        }
    }

    /// Refuses a run that sets the devices `ids` of `family` on `bus` moving when one is
    /// a joint off position (`bus` `None`: the station's one bus of the family).
    ///
    /// # Errors
    ///
    /// [`OpError::Refused`] naming each such joint and its interface.
    pub fn check_moved(
        &self,
        family: Family,
        bus: Option<&str>,
        ids: &[u8],
    ) -> Result<(), OpError> {
        let off = self.lock();
        let hit: Vec<&OffPosition> = off
            .iter()
            .filter(|o| o.family == family && bus.is_none_or(|b| b == o.bus) && ids.contains(&o.id))
            .collect();
        if hit.is_empty() {
            Ok(())
        } else {
            Err(refusal(&hit))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn wheel(interface: Interface) -> OffPosition {
        OffPosition {
            joint: "s0".into(),
            family: Family::Wck,
            bus: "legs".into(),
            id: 0,
            interface,
        }
    }

    #[test]
    fn a_joint_off_position_refuses_motions_of_it_until_switched_back() {
        let i = Interfaces::default();
        i.set(wheel(Interface::Velocity));
        let names = ["s0".to_owned(), "j1".to_owned()];
        let e = i.check_joints(&names).unwrap_err();
        assert_eq!(e.kind(), crate::ErrorKind::Refused);
        assert_eq!(
            e.to_string(),
            "s0 is on its velocity interface: a motion of positions needs it on its \
             position interface; switch it back to position first; nothing was sent"
        );
        let wck = |bus: Option<&str>, ids: &[u8]| i.check_moved(Family::Wck, bus, ids);
        assert!(wck(None, &[0, 1]).is_err());
        assert!(wck(Some("legs"), &[0]).is_err());
        assert!(i.check_moved(Family::Whj, None, &[0]).is_ok());
        wck(Some("arm"), &[0]).unwrap();
        wck(None, &[1, 2]).unwrap();
        i.check_joints(&["j1".to_owned()]).unwrap();
        i.set(wheel(Interface::Position));
        i.check_joints(&names).unwrap();
        wck(None, &[0]).unwrap();
        assert!(i.off_position().is_empty());
    }
}
