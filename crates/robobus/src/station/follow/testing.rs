//! What the follower's tests share: the built-in simulated station on a robot file of
//! their own, its WHJ joints ready for position commands.

#![allow(clippy::unwrap_used)] // tests: a failed unwrap is a failed test

use serde_json::json;

use crate::catalogue::{Request, run};
use crate::ops::Control;
use crate::robot::RobotConfig;
use crate::station::Station;

/// The built-in simulated station with the robot file `file` (its WHJ joints on
/// `sim-whj`), the WHJ joints `joints` (`"1-2"`) in position mode and enabled, and the
/// WHJ simulators' handle.
pub(super) fn enabled(file: &str, joints: &str) -> (Station, robobus_sim::whj::WhjSimHandle) {
    let (mut station, _wck, whj) = Station::simulated_with_handles().unwrap();
    station
        .set_robot(RobotConfig::from_toml_str(file).unwrap())
        .unwrap();
    for r in [
        json!({"op": "whj.mode", "joints": joints, "mode": "position"}),
        json!({"op": "whj.enable", "joints": joints}),
    ] {
        let r: Request = serde_json::from_value(r).unwrap();
        run(&station, &r, &mut Control::none()).unwrap();
    }
    (station, whj)
}
