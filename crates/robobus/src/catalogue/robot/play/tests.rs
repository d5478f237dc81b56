#![allow(clippy::unwrap_used)]

use std::time::Duration;

use serde_json::{Value, json};

use super::PlayTick;
use crate::catalogue::{Interaction, Request, run, run_with};
use crate::ops::{Control, ErrorKind, OpError};
use crate::station::Station;

const WAVE: &str = "# two wCK servos and two WHJ joints\n\
        time_s,s0,s1,j1,j2\n\
        0,0,0,0,0\n\
        1,20,-20,10,-10\n\
        2,0,0,0,0\n";

/// Every tick kept: its time, targets and positions.
#[derive(Default)]
struct Ticks(Vec<(f64, Vec<f64>, Vec<Option<f64>>)>);

impl Interaction for Ticks {
    fn play_tick(&mut self, t: &PlayTick<'_>) -> Result<(), OpError> {
        self.0
            .push((t.t_s, t.targets.to_vec(), t.positions.to_vec()));
        Ok(())
    }
}

fn req(v: Value) -> Request {
    serde_json::from_value(v).unwrap()
}

fn ready_whj(station: &Station) {
    for r in [
        json!({"op": "whj.mode", "joints": "1-2", "mode": "position"}),
        json!({"op": "whj.enable", "joints": "1-2"}),
    ] {
        run(station, &req(r), &mut Control::none()).unwrap();
    }
}

#[test]
fn a_trajectory_across_both_buses_is_played_in_step_and_tracked() {
    let (station, _wck, _whj) = Station::simulated_with_handles().unwrap();
    ready_whj(&station);
    let request = req(json!({"op": "robot.play", "trajectory": WAVE, "rate_hz": 50}));
    let mut ticks = Ticks::default();
    let report = run_with(&station, &request, &mut Control::none(), &mut ticks).unwrap();
    let v = serde_json::to_value(&report).unwrap();
    assert_eq!(v["failed"], Value::Null, "{v:#}");
    let s = &v["summary"];
    // The joints start at their zero: no lead-in; 2 s at 50 Hz, both ends included.
    assert_eq!(s["lead_in_s"], 0.0, "{s}");
    assert_eq!(s["ticks"], 101, "{s}");
    assert_eq!(s["overruns"], 0, "{s}");
    assert_eq!(s["buses"], json!(["sim-wck", "sim-whj"]), "{s}");
    // Time-aligned: on the simulators' clocks both buses send at each tick's instant.
    assert_eq!(s["skew_ms"]["max"], 0.0, "{s}");
    assert_eq!(s["late_ms"]["max"], 0.0, "{s}");
    // A free motion with the default protection: no event.
    assert_eq!(s["protection"], json!([]), "{s}");
    for row in v["results"].as_array().unwrap() {
        assert_eq!(row["commands"], 101, "{row}");
        assert_eq!(row["failed"], 0, "{row}");
        // A wCK step is 1.055°; the servos and joints follow within a few degrees.
        let rms = row["tracking_rms_deg"].as_f64().unwrap();
        assert!(rms < 2.0, "{row}");
        assert!(row["position_deg"].as_f64().unwrap().abs() < 2.0, "{row}");
    }
    // Mid-way the targets are the second point, and the joints are near it.
    let (t, targets, positions) = &ticks.0[50];
    assert!((t - 1.0).abs() < 1e-9, "{t}");
    assert_eq!(targets, &[20.0, -20.0, 10.0, -10.0]);
    let (_, _, next) = &ticks.0[51];
    for ((want, at), name) in targets.iter().zip(next).zip(["s0", "s1", "j1", "j2"]) {
        let at = at.unwrap();
        assert!(
            (want - at).abs() < 2.5,
            "{name}: {at} for {want}: {positions:?}"
        );
    }
}

#[test]
fn the_lead_in_goes_from_where_the_joints_are_and_refusals_send_nothing() {
    let (station, wck, _) = Station::simulated_with_handles().unwrap();
    ready_whj(&station);
    // s3 starts at +10° (turned by hand while passive): 10° at 2 rad/s is 87 ms.
    let centre = 127.0 * robobus_sim::wck::mechanics::DEG_PER_STEP8;
    wck.with_bus(|b| b.servo_mut(3).unwrap().set_angle(centre + 10.0));
    let request = req(json!({
        "op": "robot.play",
        "trajectory": "time_s,s3\n0,0\n0.5,5\n",
        "rate_hz": 100,
    }));
    let v = serde_json::to_value(run(&station, &request, &mut Control::none()).unwrap()).unwrap();
    let lead = v["summary"]["lead_in_s"].as_f64().unwrap();
    let step = robobus_sim::wck::mechanics::DEG_PER_STEP8;
    let start = v["results"][0]["start_deg"].as_f64().unwrap();
    assert!((start - 10.0).abs() <= step, "{v:#}");
    let expected = super::lead_in_s(start, 2f64.to_degrees(), 20f64.to_degrees());
    assert!((lead - expected).abs() < 1e-9, "{v:#}");
    assert!((v["results"][0]["target_deg"].as_f64().unwrap() - 5.0).abs() < 1e-9);
    // Refused before anything is sent: a joint not in the file, outside its limits,
    // too fast, silent.
    wck.with_bus(|b| b.servo_mut(6).unwrap().power_off(Duration::ZERO));
    run(
        &station,
        &req(json!({"op": "whj.disable", "joints": "3"})),
        &mut Control::none(),
    )
    .unwrap();
    for (text, kind, says) in [
        (
            "time_s,knee\n0,0\n",
            ErrorKind::BadInput,
            "joint knee is not in the robot file",
        ),
        (
            "time_s,s4\n0,0\n1,200\n",
            ErrorKind::BadInput,
            "outside its soft limits",
        ),
        (
            "time_s,s4\n0,0\n0.1,100\n",
            ErrorKind::BadInput,
            "faster than its max_velocity",
        ),
        ("time_s,s6\n0,0\n", ErrorKind::Refused, "s6 did not answer"),
        // The wCK servo would move without the disabled WHJ joint: neither does.
        (
            "time_s,s4,j3\n0,10,0\n",
            ErrorKind::Refused,
            "j3: joint 3 is disabled",
        ),
    ] {
        let request = req(json!({"op": "robot.play", "trajectory": text}));
        let before = wck.with_bus(|b| b.servo(4).unwrap().position());
        let e = run(&station, &request, &mut Control::none()).unwrap_err();
        assert_eq!(e.kind(), kind, "{text:?}: {e}");
        assert!(e.to_string().contains(says), "{text:?}: {e}");
        assert_eq!(wck.with_bus(|b| b.servo(4).unwrap().position()), before);
    }
}

/// A WHJ trajectory of j1 and j2 at 50 Hz: j1 0 -> 40° over 2 s, j2 0 -> 20°.
const REACH: &str = "time_s,j1,j2\n0,0,0\n2,40,20\n";

#[test]
fn an_obstacle_stops_play_within_the_stall_time_and_names_the_joint() {
    let (station, _wck, whj) = Station::simulated_with_handles().unwrap();
    ready_whj(&station);
    // A stop at 5° in j1's way: j1 reaches it at 0.25 s (20°/s).
    whj.with_bus(|b| {
        b.joint_mut(1)
            .unwrap()
            .set_obstacle(Some(robobus_sim::whj::Obstacle::above(5.0)));
    });
    let request = req(json!({"op": "robot.play", "trajectory": REACH, "rate_hz": 50}));
    let mut ticks = Ticks::default();
    let report = run_with(&station, &request, &mut Control::none(), &mut ticks).unwrap();
    let v = serde_json::to_value(&report).unwrap();
    let s = &v["summary"];
    let events = s["protection"].as_array().unwrap();
    assert_eq!(events.len(), 1, "{s:#}");
    let stop = &events[0];
    assert_eq!(stop["joint"], "j1", "{stop}");
    assert_eq!(stop["action"], "stop", "{stop}");
    assert_eq!(stop["check"], "stall", "{stop}");
    assert_eq!(stop["quantity"], "current_a", "{stop}");
    // The WHJ30's rated current, from the models table.
    assert_eq!(stop["limit"], 7.8, "{stop}");
    let at = stop["at_s"].as_f64().unwrap();
    // The current reaches the stall current 0.21 s after the contact at 0.25 s (the
    // target 4.2° into the stop), and the stall time (0.3 s) later the run stops: at
    // the feedback of the tick at 0.76 s.
    assert!((at - 0.76).abs() < 0.001, "{stop}");
    assert_eq!(s["ticks"], ticks.0.len(), "{s}");
    let last = ticks.0.last().unwrap().0;
    assert!(
        (last - 0.76).abs() < 1e-9,
        "the run ended at the stop's tick: {last}"
    );
    // The row names the joint, the quantity, the limit and the time; j2 is fine.
    let rows = v["results"].as_array().unwrap();
    assert_eq!(rows[0]["id"], "j1");
    assert_eq!(rows[0]["kind"], "device", "{}", rows[0]);
    let error = rows[0]["error"].as_str().unwrap();
    assert!(
        error.starts_with("j1: stall protection: current ")
            && error.contains("reached the limit 7.8 A at ")
            && error.contains("stopped in the safe state"),
        "{error}"
    );
    assert_eq!(rows[1]["id"], "j2");
    assert_eq!(rows[1]["failed"], 0, "{}", rows[1]);
    assert_eq!(s["safe_state"][0]["safe_state"], "hold", "{s}");
    // j1 (a WHJ30: a pin brake) is disabled, no longer pushing into the stop; j2
    // holds where it is.
    assert!(
        error.ends_with(
            "its drive disabled (its brake holds it: holding would keep it pushing or heating)"
        ),
        "{error}"
    );
    let j1 = whj.with_bus(|b| b.joint(1).unwrap().state());
    assert!(!j1.enabled && j1.brake_locked, "{j1:?}");
    assert!(j1.current_a.abs() < 1e-9, "{j1:?}");
    let j2 = whj.with_bus(|b| b.joint(2).unwrap().state());
    assert!(j2.enabled, "{j2:?}");
}

/// Heats joint 1 at given ticks of a run.
struct Heat {
    whj: robobus_sim::whj::WhjSimHandle,
    at: Vec<(f64, f64)>,
    ticks: Ticks,
}

impl Interaction for Heat {
    fn play_tick(&mut self, t: &PlayTick<'_>) -> Result<(), OpError> {
        for &(when, celsius) in &self.at {
            if (t.t_s - when).abs() < 1e-9 {
                self.whj.with_bus(|b| {
                    b.joint_mut(1).unwrap().set_winding_temperature(celsius);
                });
            }
        }
        self.ticks.play_tick(t)
    }
}

#[test]
fn a_hot_joint_is_derated_then_stopped() {
    let (station, _wck, whj) = Station::simulated_with_handles().unwrap();
    ready_whj(&station);
    // j1 at 60°/s; the temperature is read every 0.25 s.
    let request = req(json!({
        "op": "robot.play",
        "trajectory": "time_s,j1,j2\n0,0,0\n1.5,90,0\n",
        "rate_hz": 50,
    }));
    let mut heat = Heat {
        whj,
        at: vec![(0.4, 81.0), (1.2, 86.0)],
        ticks: Ticks::default(),
    };
    let report = run_with(&station, &request, &mut Control::none(), &mut heat).unwrap();
    let v = serde_json::to_value(&report).unwrap();
    let events = v["summary"]["protection"].as_array().unwrap().clone();
    let seen: Vec<(&str, &str, f64, f64)> = events
        .iter()
        .map(|e| {
            (
                e["joint"].as_str().unwrap(),
                e["action"].as_str().unwrap(),
                e["limit"].as_f64().unwrap(),
                e["at_s"].as_f64().unwrap(),
            )
        })
        .collect();
    // The temperature is read every 13 ticks (0.26 s): at 0.52 s (derate, 80 °C) and
    // at 1.30 s (stop, 85 °C).
    assert_eq!(seen.len(), 2, "{events:?}");
    assert_eq!(seen[0].0, "j1");
    assert_eq!((seen[0].1, seen[0].2), ("derate", 80.0));
    assert_eq!((seen[1].1, seen[1].2), ("stop", 85.0));
    assert!((seen[0].3 - 0.52).abs() < 0.001, "{events:?}");
    assert!((seen[1].3 - 1.30).abs() < 0.001, "{events:?}");
    assert_eq!(v["results"][0]["kind"], "device", "{v:#}");
    assert!(
        v["results"][0]["error"]
            .as_str()
            .unwrap()
            .starts_with("j1: thermal protection: temperature 86.00 °C reached the limit 85 °C")
    );
    // Before the derating j1 was sent 1.2° a tick (60°/s); after it, at most half its
    // max_velocity (the built-in file's, 1.33 rad/s): 0.5 × 75.96°/s × 0.02 s = 0.76°.
    let steps: Vec<(f64, f64)> = heat
        .ticks
        .0
        .windows(2)
        .map(|w| (w[1].0, w[1].1[0] - w[0].1[0]))
        .collect();
    let most = 0.5 * crate::robot::simulated::whj_follows().0.to_degrees() * 0.02;
    for &(t, step) in &steps {
        if t <= 0.52 {
            assert!((step - 1.2).abs() < 1e-9, "{t}: {step}");
        } else if t > 0.54 {
            assert!(step <= most + 1e-9 && step > most - 1e-9, "{t}: {step}");
        }
    }
    assert!((heat.ticks.0.last().unwrap().0 - 1.30).abs() < 1e-9);
}

/// Blends a newer trajectory (j1 to 0° at 1 s, velocity and acceleration 0) into the run
/// at its tick `at` (15 ticks ahead, from the state commanded there), as a front end does.
struct Blending<'s> {
    station: &'s Station,
    blend: std::sync::Arc<super::Blend>,
    at: usize,
    /// The tick the blend starts at and whether the offer was taken up.
    offered: Option<(u64, bool)>,
    ticks: Ticks,
}

impl Interaction for Blending<'_> {
    fn play_tick(&mut self, t: &PlayTick<'_>) -> Result<(), OpError> {
        self.ticks.play_tick(t)?;
        if self.ticks.0.len() == self.at + 1 {
            use crate::cdr::{Duration as Since, JointTrajectory, JointTrajectoryPoint};
            use crate::robot::trajectory::ros;
            let at = self.blend.commanded(15).unwrap();
            let msg = JointTrajectory {
                joint_names: vec!["j1".into()],
                points: vec![JointTrajectoryPoint {
                    positions: vec![0.0],
                    velocities: vec![0.0],
                    accelerations: vec![0.0],
                    time_from_start: Since::from_secs_f64(1.0),
                    ..JointTrajectoryPoint::default()
                }],
                ..JointTrajectory::default()
            };
            let config = self.station.robot().cloned().unwrap();
            let checked = ros::check(&msg, &config).unwrap();
            let start = at.start_of(&checked.joints).unwrap();
            let planned = ros::plan_from(&checked, &config, &start, at.ahead_s).unwrap();
            let blended = super::Blend::blended(&at, &planned.trajectory).unwrap();
            let r: super::Play =
                serde_json::from_value(json!({"trajectory": planned.csv})).unwrap();
            let taken = self
                .blend
                .offer(self.station, &r, &at, &blended, &Control::none())
                .unwrap();
            self.offered = Some((at.tick, taken));
        }
        Ok(())
    }

    fn play_blend(&self) -> Option<std::sync::Arc<super::Blend>> {
        Some(std::sync::Arc::clone(&self.blend))
    }
}

/// A trajectory blended into a play between two of its ticks (as the bridge's newer
/// trajectory): the same run goes on from the position, velocity and acceleration it
/// commanded at the swap tick, with no stop and no jump, the joint the newer one does not
/// name holds its commanded position, and the run ends when the newer one does.
#[test]
fn a_blended_trajectory_goes_on_from_the_commanded_state_in_the_same_run() {
    let (station, _wck, _whj) = Station::simulated_with_handles().unwrap();
    ready_whj(&station);
    // j1 at 20°/s, j2 at -10°/s; the newer one is offered at the tick at 0.5 s.
    let request = req(json!({
        "op": "robot.play",
        "trajectory": "time_s,j1,j2\n0,0,0\n2,40,-20\n",
        "rate_hz": 50,
    }));
    let mut b = Blending {
        station: &station,
        blend: std::sync::Arc::new(super::Blend::new()),
        at: 25,
        offered: None,
        ticks: Ticks::default(),
    };
    let report = run_with(&station, &request, &mut Control::none(), &mut b).unwrap();
    let v = serde_json::to_value(&report).unwrap();
    assert_eq!(v["failed"], Value::Null, "{v:#}");
    // Taken at tick 41 (0.82 s): 15 after the one after 0.5 s.
    assert_eq!(b.offered, Some((41, true)));
    assert_eq!(b.blend.taken().count, 1);
    assert!((b.blend.taken().t_s - 0.82).abs() < 1e-9);
    let ticks = &b.ticks.0;
    let j1 = |k: usize| ticks[k].1[0];
    // At the swap tick exactly where the first trajectory had it (16.4°), its step per
    // tick (0.4° at 20°/s) going on: the change in a step is the quintic's start's.
    assert!((j1(41) - 16.4).abs() < 1e-9, "{}", j1(41));
    for k in 38..=41 {
        assert!((j1(k) - j1(k - 1) - 0.4).abs() < 1e-9, "tick {k}");
    }
    assert!((j1(42) - j1(41) - 0.4).abs() < 0.01, "{}", j1(42) - j1(41));
    // Then as smooth as the quintic to 0° (down to -54°/s and back to rest in 0.68 s,
    // its acceleration at most 320°/s²: a step changes by at most 0.128° a tick).
    for k in 43..76 {
        let (a, b) = (j1(k - 1) - j1(k - 2), j1(k) - j1(k - 1));
        assert!((a - b).abs() < 0.13, "tick {k}: {a} then {b}");
    }
    // j2 holds its commanded -8.2° from the swap.
    for (t, targets, _) in &ticks[41..] {
        assert!((targets[1] + 8.2).abs() < 1e-9, "{t}: {targets:?}");
    }
    // The newer one's point was due 1 s after the tick it came at (0.5 s): the run ends
    // there, at 1.5 s (76 ticks, not the first's 101), j1 at 0°.
    assert_eq!(v["summary"]["ticks"], 76, "{v:#}");
    let (t, targets, _) = ticks.last().unwrap();
    assert!((t - 1.5).abs() < 1e-9, "{t}");
    assert!(targets[0].abs() < 1e-9, "{targets:?}");
}
