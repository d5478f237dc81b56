//! `robobus demo`: the built-in simulated robot, run by the built binary.

#![allow(clippy::unwrap_used, clippy::panic, clippy::cast_precision_loss)] // Test code.

use crate::common;

use serde_json::Value;

/// The demo runs two simulators on the wall clock: never two demos at once.
static SERIAL: std::sync::Mutex<()> = std::sync::Mutex::new(());

fn num(v: &Value) -> f64 {
    v.as_f64().unwrap_or_else(|| panic!("not a number: {v}"))
}

#[test]
fn demo_json_summary_reports_the_whole_robot_tracking_well() {
    let _serial = SERIAL
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    let dir = tempfile::tempdir().unwrap();
    let plot = dir.path().join("demo.svg");
    let r = common::robobus(&[
        "demo",
        "--seconds",
        "2",
        "--json",
        "--plot",
        plot.to_str().unwrap(),
    ]);
    assert_eq!(r.code, Some(0), "{}", r.stderr);
    let doc: Value =
        serde_json::from_str(&r.stdout).unwrap_or_else(|e| panic!("not JSON ({e}): {}", r.stdout));

    // wCK: all 16 servos found, every keyframe reached within a step, no lost replies.
    let wck = &doc["wck"];
    assert_eq!(wck["servos_found"], 16, "{wck}");
    let poses = wck["poses"].as_array().unwrap();
    assert_eq!(poses.len(), 3);
    for p in poses {
        assert!(p["settled_ms"].is_number(), "{p}");
        // A step is 1.06°; the manual's control error is ±0.8°.
        assert!(num(&p["worst_error_steps"]) <= 2.0, "{p}");
    }
    // A late reply on a loaded machine is retried; every one must have been recovered.
    assert!(num(&wck["timeouts"]) <= num(&wck["retries"]), "{wck}");
    let busy = num(&wck["wire_utilisation"]);
    assert!(busy > 0.0 && busy < 1.0, "{wck}");

    // WHJ: 7 joints identified, the 500 Hz loop ran about 2 s and tracked closely.
    let whj = &doc["whj"];
    assert_eq!(whj["joints"], 7, "{whj}");
    assert!(
        whj["identities"]
            .as_array()
            .unwrap()
            .iter()
            .all(|i| i["model"] == "WHJ30")
    );
    let cycles = num(&whj["cycles"]);
    // 1000 cycles in 2 s; a loaded machine running a debug build skips some (overruns).
    assert!((200.0..=1100.0).contains(&cycles), "{whj}");
    // Complete cycles: every joint's feedback before the next tick. A loaded machine
    // running a debug build starts some cycles too late for that (late replies are counted
    // as late, not taken for the next cycle's); the tracking below is what must hold.
    assert!(num(&whj["complete"]) > 0.0, "{whj}");
    assert!(
        (num(&whj["complete"]) + num(&whj["deadline_misses"]) - cycles).abs() < 0.5,
        "{whj}"
    );
    assert!(num(&whj["tracking_rms_deg"]) < 2.0, "{whj}");
    assert!(num(&whj["tracking_max_deg"]) < 6.0, "{whj}");
    for t in whj["tracking"].as_array().unwrap() {
        assert!(num(&t["samples"]) > 100.0, "{t}");
        assert_eq!(t["error_free"], true, "{t}");
    }
    // The modelled wire budget: 14 frames take well under the 2 ms period.
    let util = num(&whj["wire_utilisation"]);
    assert!(util > 0.1 && util < 0.9, "{whj}");
    assert!(num(&whj["wire_limit_hz"]) > 500.0, "{whj}");
    assert!(num(&whj["round_trip_us"]["p50"]) > 0.0, "{whj}");

    assert_eq!(doc["errors"].as_array().unwrap().len(), 0, "{doc}");
    // The plot: a panel per family, each with its signals and their (dashed) targets.
    let svg = std::fs::read_to_string(&plot).unwrap();
    assert!(svg.starts_with("<svg"), "not an SVG");
    let labels: Vec<&str> = svg
        .split("</text>")
        .filter_map(|t| t.rsplit_once('>').map(|(_, label)| label.trim()))
        .filter(|l| !l.is_empty() && l.parse::<f64>().is_err())
        .collect();
    assert_eq!(
        labels,
        [
            "wCK servo angle (deg)",
            "wck0_deg",
            "wck2_deg",
            "wck4_deg",
            "wck6_deg",
            "target",
            "WHJ joint angle (deg)",
            "whj1_deg",
            "whj2_deg",
            "whj3_deg",
            "whj4_deg",
            "whj5_deg",
            "whj6_deg",
            "whj7_deg",
            "target",
            "time (s)",
            "robobus demo: simulated robot",
        ]
    );
}

#[test]
fn demo_text_summary_and_bad_options() {
    let _serial = SERIAL
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    let r = common::robobus(&["demo", "--seconds", "0.5"]);
    assert_eq!(r.code, Some(0), "{}", r.stderr);
    for needle in [
        "found 16 servos",
        "7 x WHJ30",
        "tracking error rms",
        "deadline misses",
        "wire allows",
    ] {
        assert!(
            r.stdout.contains(needle),
            "missing {needle:?}:\n{}",
            r.stdout
        );
    }
    let r = common::robobus(&["demo", "--seconds", "600"]);
    assert_eq!(r.code, Some(2));
    assert!(r.stderr.contains("0.5..=60"), "{}", r.stderr);
    let r = common::robobus(&["demo", "--plot", "out.gif"]);
    assert_eq!(r.code, Some(2));
    assert!(r.stderr.contains(".png or .svg"), "{}", r.stderr);
}
