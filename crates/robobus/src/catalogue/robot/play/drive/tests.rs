#![allow(clippy::unwrap_used)]

use serde_json::{Value, json};

use crate::catalogue::{Request, run};
use crate::ops::{Control, ErrorKind};
use crate::robot::RobotConfig;
use crate::robot::simulated::{DRIVE_ROBOT, sim_1108_wheel_speeds};
use crate::station::Station;

/// The built-in simulated station with its robot file of a wheel `s0`, a WHJ joint `j1`
/// with velocity and effort, and `j2` with position alone ([`DRIVE_ROBOT`]); its WHJ
/// joints enabled.
fn station() -> (
    Station,
    robobus_sim::wck::SimHandle,
    robobus_sim::whj::WhjSimHandle,
) {
    let (mut station, wck, whj) = Station::simulated_with_handles().unwrap();
    station
        .set_robot(RobotConfig::from_toml_str(DRIVE_ROBOT).unwrap())
        .unwrap();
    for r in [
        json!({"op": "whj.mode", "joints": "1-2", "mode": "position"}),
        json!({"op": "whj.enable", "joints": "1-2"}),
    ] {
        run(&station, &req(r), &mut Control::none()).unwrap();
    }
    (station, wck, whj)
}

fn req(v: Value) -> Request {
    serde_json::from_value(v).unwrap()
}

fn play(station: &Station, csv: &str) -> Result<Value, crate::ops::OpError> {
    let request = req(json!({"op": "robot.play", "trajectory": csv, "rate_hz": 50}));
    run(station, &request, &mut Control::none()).map(|r| serde_json::to_value(r).unwrap())
}

fn wheel_angle(wck: &robobus_sim::wck::SimHandle) -> f64 {
    wck.with_bus(|b| {
        let s = b.servo(0).unwrap();
        #[allow(clippy::cast_precision_loss)] // a few rotations
        let turns = s.rotations() as f64;
        turns * 360.0 + s.angle()
    })
}

#[test]
fn a_csv_of_velocities_turns_a_wheel_and_a_whj_joint_at_its_speeds() {
    let (station, wck, whj) = station();
    let level_7 = sim_1108_wheel_speeds()[6].to_degrees();
    let a0 = wheel_angle(&wck);
    let v = play(
        &station,
        &format!("time_s,s0_deg_s,j1_deg_s\n0,{level_7},30\n1,{level_7},30\n"),
    )
    .unwrap();
    assert_eq!(v["failed"], Value::Null, "{v:#}");
    assert_eq!(v["summary"]["ticks"], 51, "{v:#}");
    let rows = v["results"].as_array().unwrap();
    // The wheel: its level-7 speed, sent as that level.
    let s0 = rows[0]["sent_deg_s"].as_f64().unwrap();
    assert!((s0 - level_7).abs() < 1e-9, "{v:#}");
    // Up to speed within 31 ms at 100 rad/s², then 1 s: about 1 s of level 7.
    let turned = wheel_angle(&wck) - a0;
    assert!(
        (turned - level_7).abs() < 0.04 * level_7,
        "{turned}° for {level_7}°/s"
    );
    // The WHJ joint: 30°/s (0.002 RPM counts), 1 s less the ramp (26 ms at 20 rad/s²).
    let j1 = rows[1]["sent_deg_s"].as_f64().unwrap();
    assert!((j1 - 30.0).abs() < 0.012, "{v:#}");
    let at = rows[1]["position_deg"].as_f64().unwrap();
    assert!((at - 29.6).abs() < 1.0, "{v:#}");
    assert_eq!(rows[1]["tracking_max_deg"], 0.0);
    assert!(rows[0].get("sent_nm").is_none(), "{v:#}");
    // Left in the safe state: the WHJ joint back in position mode, holding.
    let s = whj.with_bus(|b| b.joint(1).unwrap().state());
    // (still turning at 30°/s when the play ended: its position loop brakes it to
    // the angle where the mode changed)
    assert_eq!((s.mode, s.enabled, s.target_speed), (3, true, 0), "{s:?}");
    assert!(
        (f64::from(s.target_position) * 1e-4 - at).abs() < 1.0,
        "{s:?}"
    );
    assert_eq!(
        wck.with_bus(|b| b.servo(0).unwrap().mode()),
        robobus_sim::wck::Mode::Passive
    );
}

#[test]
fn a_csv_of_efforts_drives_a_whj_joint_in_current_mode() {
    let (station, _wck, whj) = station();
    let v = play(&station, "time_s,j1_nm\n0,1\n0.2,1\n").unwrap();
    assert_eq!(v["failed"], Value::Null, "{v:#}");
    let row = &v["results"][0];
    // 1 N·m is 260 mA on the WHJ30 (3.846 N·m/A), sent in 1 mA counts.
    let nm = row["sent_nm"].as_f64().unwrap();
    assert!((nm - 0.26 * 30.0 / 7.8).abs() < 1e-9, "{v:#}");
    assert!(
        row["position_deg"].as_f64().unwrap() > 0.5,
        "it turned: {v:#}"
    );
    let s = whj.with_bus(|b| b.joint(1).unwrap().state());
    assert_eq!((s.mode, s.target_current), (3, 0), "{s:?}");
}

/// The play's summary and its first column's row.
fn stopped(v: &Value) -> (&Value, &Value) {
    (&v["summary"], &v["results"][0])
}

/// [`stopped`], and the one protection event the summary must have.
fn stopped_once(v: &Value) -> (&Value, &Value, &Value) {
    let (s, row) = stopped(v);
    let events = s["protection"].as_array().unwrap();
    assert_eq!(events.len(), 1, "{s:#}");
    (s, row, &events[0])
}

#[test]
fn an_obstacle_stops_a_velocity_play_within_the_stall_time_and_names_the_joint() {
    let (station, _wck, whj) = station();
    // A stop 5° above where j1 stands, and j1 told to turn up at 30°/s for 2 s: it
    // reaches the stop at about 0.17 s.
    whj.with_bus(|b| {
        let j = b.joint_mut(1).unwrap();
        let at = j.state().physical_deg + 5.0;
        j.set_obstacle(Some(robobus_sim::whj::Obstacle::above(at)));
    });
    let v = play(&station, "time_s,j1_deg_s\n0,30\n2,30\n").unwrap();
    let (s, row, stop) = stopped_once(&v);
    assert_eq!(
        (
            &stop["joint"],
            &stop["check"],
            &stop["quantity"],
            &stop["action"]
        ),
        (
            &json!("j1"),
            &json!("stall"),
            &json!("current_a"),
            &json!("stop")
        ),
        "{stop}"
    );
    // The WHJ30's rated current, from the models table.
    assert_eq!(stop["limit"], 7.8, "{stop}");
    let at = stop["at_s"].as_f64().unwrap();
    assert!((at - STALL_AT_S).abs() < 0.001, "{stop}");
    // The current reaches the stall current about 0.3 s into the play (the joint
    // reached the stop at about 0.17 s), and the stall time (0.3 s) later the play
    // stops: at the feedback of the tick at 0.6 s, not at 2 s.
    assert_eq!(s["ticks"], json!(STALL_TICKS), "{s}");
    assert_eq!(row["id"], "j1");
    let error = row["error"].as_str().unwrap();
    assert!(
        error.starts_with("j1: stall protection: current ")
            && error.contains("reached the limit 7.8 A at ")
            && error.contains(
                "stopped in the safe state (the joint did not move as commanded meanwhile); \
                 its drive disabled"
            ),
        "{error}"
    );
    // j1 (a WHJ30: a pin brake) is disabled, no longer pushing into the stop.
    let j1 = whj.with_bus(|b| b.joint(1).unwrap().state());
    assert!(!j1.enabled && j1.brake_locked, "{j1:?}");
}

/// A wheel held still while told to turn at its level 2 (267 mA held on the
/// simulated 1108, under its 400 mA over-load, so nothing else would stop it): read
/// at the first tick at or past every 0.25 s (0, 0.26, 0.52, 0.78 s at 50 Hz), the
/// stall seen at 0.26 s and held for two periods (0.5 s), the play stops at the read
/// at 0.78 s, not at 2 s, naming the wheel, which is left passive.
#[test]
fn a_wheel_held_still_under_velocity_is_stopped_naming_it() {
    let (station, wck, _whj) = station();
    wck.with_bus(|b| b.servo_mut(0).unwrap().hold(true));
    let level_2 = sim_1108_wheel_speeds()[1].to_degrees();
    let v = play(
        &station,
        &format!("time_s,s0_deg_s\n0,{level_2}\n2,{level_2}\n"),
    )
    .unwrap();
    let (s, row, stop) = stopped_once(&v);
    assert_eq!(
        (
            &stop["joint"],
            &stop["check"],
            &stop["quantity"],
            &stop["limit"]
        ),
        (
            &json!("s0"),
            &json!("stall"),
            &json!("current_a"),
            &json!(0.2)
        ),
        "{stop}"
    );
    let at = stop["at_s"].as_f64().unwrap();
    assert!((0.78..0.79).contains(&at), "{stop}");
    assert_eq!(s["ticks"], json!(40), "{s}");
    let error = row["error"].as_str().unwrap();
    assert!(
        error.starts_with("s0: stall protection: current 0.27 A reached the limit 0.2 A"),
        "{error}"
    );
    assert_eq!(
        wck.with_bus(|b| b.servo(0).unwrap().mode()),
        robobus_sim::wck::Mode::Passive
    );
}

/// A play of positions (through the same protection as velocities: the monitor
/// `robot.play` feeds) into a hand that grips the wCK servo `s0` 1 s in: each tick's
/// position move answers with the servo's load, read as a current: 800 mA held
/// (torque level 3, the servo's own over-load raised to 1800 mA so only the host can
/// stop it). Its target runs away at 20°/s, so the error passes the stall's 3° at
/// 1.12 s, and the stall time (0.4 s) later, at 1.52 s, the play stops naming the
/// servo, which is left passive.
#[test]
fn a_play_of_positions_into_a_gripped_wck_servo_is_stopped_naming_it() {
    let (station, wck, _whj) = station();
    wck.with_bus(|b| {
        let s = b.servo_mut(0).unwrap();
        let e = robobus_sim::wck::Eeprom {
            overload: robobus_wck::Overload::new(199).unwrap(),
            ..*s.eeprom()
        };
        s.set_eeprom(e);
    });
    let mut on_progress = |p: &crate::ops::Progress| {
        if p.done == 50 {
            wck.with_bus(|b| b.servo_mut(0).unwrap().hold(true));
        }
    };
    let mut control = Control::none().with_progress(&mut on_progress);
    let request = req(json!({
        "op": "robot.play",
        "trajectory": "time_s,s0\n0,0\n3,60\n",
        "rate_hz": 50,
        "torque": 3,
    }));
    let v = serde_json::to_value(run(&station, &request, &mut control).unwrap()).unwrap();
    drop(control);
    let (s, row, stop) = stopped_once(&v);
    assert_eq!(
        (&stop["joint"], &stop["check"], &stop["action"]),
        (&json!("s0"), &json!("stall"), &json!("stop")),
        "{stop}"
    );
    let at = stop["at_s"].as_f64().unwrap();
    assert!((1.52..1.53).contains(&at), "{stop}");
    assert_eq!(s["ticks"], json!(77), "{s}");
    assert_eq!(row["id"], "s0");
    let error = row["error"].as_str().unwrap();
    assert!(
        error.starts_with("s0: stall protection: current 0.80 A reached the limit 0.2 A"),
        "{error}"
    );
    assert_eq!(
        wck.with_bus(|b| b.servo(0).unwrap().mode()),
        robobus_sim::wck::Mode::Passive
    );
}

/// When the obstacle test's stall stops the play, s, and its ticks by then (at 50 Hz).
const STALL_AT_S: f64 = 0.6005;
const STALL_TICKS: u64 = 31;

#[test]
fn a_hot_joint_under_velocity_is_derated_then_stopped() {
    let (station, _wck, whj) = station();
    // j1 starts at 81 °C (over the WHJ30's 80 °C derating), and is heated to 86 °C (over
    // the 85 °C stop) at the tick at 0.4 s; the temperature is read every 13 ticks.
    let heat = |celsius: f64| {
        whj.with_bus(|b| b.joint_mut(1).unwrap().set_winding_temperature(celsius));
    };
    heat(81.0);
    let mut on_progress = |p: &crate::ops::Progress| {
        if p.done == 21 {
            heat(86.0);
        }
    };
    let mut control = Control::none().with_progress(&mut on_progress);
    let request = req(json!({
        "op": "robot.play",
        "trajectory": "time_s,j1_deg_s\n0,100\n2,100\n",
        "rate_hz": 50,
    }));
    let v = serde_json::to_value(run(&station, &request, &mut control).unwrap()).unwrap();
    let (s, row) = stopped(&v);
    let events: Vec<(String, String, f64, f64)> = s["protection"]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| {
            (
                e["check"].as_str().unwrap().to_owned(),
                e["action"].as_str().unwrap().to_owned(),
                e["limit"].as_f64().unwrap(),
                e["at_s"].as_f64().unwrap(),
            )
        })
        .collect();
    assert_eq!(events.len(), 2, "{s:#}");
    assert_eq!(
        (events[0].0.as_str(), events[0].1.as_str()),
        ("thermal", "derate")
    );
    assert!(
        (events[0].2 - 80.0).abs() < 1e-9 && events[0].3 < 0.001,
        "{events:?}"
    );
    assert_eq!(
        (events[1].0.as_str(), events[1].1.as_str()),
        ("thermal", "stop")
    );
    assert!((events[1].2 - 85.0).abs() < 1e-9, "{events:?}");
    assert!((events[1].3 - 0.521).abs() < 0.001, "{events:?}");
    // Derated: held to half its max_velocity (2 rad/s), not the 100°/s asked for.
    let sent = row.get("sent_deg_s").and_then(Value::as_f64);
    assert!(sent.is_none(), "a failed row: {row}");
    let error = row["error"].as_str().unwrap();
    assert!(
        error.starts_with("j1: thermal protection: temperature 86.")
            && error.contains("reached the limit 85 °C at 0.52"),
        "{error}"
    );
    let at = whj.with_bus(|b| b.joint(1).unwrap().state().position_deg);
    // 0.52 s at most at 57.3°/s is under 30°; at 100°/s it would be about 50°.
    assert!(at > 20.0 && at < 30.0, "{at}");
}

#[test]
fn an_effort_that_runs_a_joint_past_its_max_velocity_stops_the_play() {
    let (station, _wck, whj) = station();
    // 4 N·m on a free j1 for 2 s: its current is the command (no stall, no collision),
    // and it speeds up past its max_velocity (2 rad/s, 114.6°/s).
    let v = play(&station, "time_s,j1_nm\n0,4\n2,4\n").unwrap();
    let (_, row, stop) = stopped_once(&v);
    assert_eq!(
        (&stop["check"], &stop["quantity"], &stop["action"]),
        (&json!("speed"), &json!("speed_deg_s"), &json!("stop")),
        "{stop}"
    );
    let limit = stop["limit"].as_f64().unwrap();
    assert!((limit - 2f64.to_degrees()).abs() < 1e-9, "{stop}");
    let at = stop["at_s"].as_f64().unwrap();
    // At 0.16 s (134.6°/s at that feedback), not at 2 s.
    assert!((at - 0.1605).abs() < 0.001, "{stop}");
    assert!(
        row["error"]
            .as_str()
            .unwrap()
            .starts_with("j1: speed protection: speed "),
        "{row}"
    );
    // Its current is back to zero, in position mode.
    let j1 = whj.with_bus(|b| b.joint(1).unwrap().state());
    assert_eq!((j1.mode, j1.target_current), (3, 0), "{j1:?}");
}

#[test]
fn a_joint_without_the_interface_or_a_value_past_its_limit_refuses_the_play() {
    let (station, _wck, whj) = station();
    let frames = || {
        whj.with_bus(|b| {
            b.joint(2).unwrap().frames_handled() + b.joint(1).unwrap().frames_handled()
        })
    };
    let before = frames();
    let err = play(&station, "time_s,j2_deg_s\n0,10\n1,10\n").unwrap_err();
    assert_eq!(err.kind(), ErrorKind::BadInput);
    assert!(
        err.to_string()
            .contains("j2 has no velocity interface in the robot file (its interfaces: position)"),
        "{err}"
    );
    let err = play(&station, "time_s,j1_deg_s\n0,10\n1,130\n").unwrap_err();
    assert!(
        err.to_string().contains(
            "trajectory line 3: j1 130 deg/s is outside -114.592..=114.592 deg/s (its max_velocity)"
        ),
        "{err}"
    );
    let err = play(&station, "time_s,j1_nm,s0_deg_s\n0,1,0\n").unwrap_err();
    assert!(
        err.to_string().contains("one interface for every column"),
        "{err}"
    );
    let err = play(&station, "time_s,j1_nm\n0,6\n").unwrap_err();
    assert!(
        err.to_string().contains("-5..=5 N·m (its max_effort)"),
        "{err}"
    );
    assert_eq!(frames(), before, "nothing sent");
}
