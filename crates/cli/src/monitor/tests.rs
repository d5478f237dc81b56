use ratatui::Terminal;
use ratatui::backend::TestBackend;

use super::*;

fn screen(dash: &Dashboard, width: u16, height: u16) -> String {
    let mut term = Terminal::new(TestBackend::new(width, height)).unwrap();
    term.draw(|f| render(f, dash)).unwrap();
    let buf = term.backend().buffer().clone();
    let mut text = String::new();
    for y in 0..height {
        for x in 0..width {
            text.push_str(buf[(x, y)].symbol());
        }
        text.push('\n');
    }
    text
}

#[test]
fn the_dashboard_shows_values_errors_and_the_plot() {
    let mut d = Dashboard {
        title: "WHJ bus udp".into(),
        speed_unit: "RPM",
        effort_name: "current mA",
        channels: vec![
            Channel {
                name: "J1".into(),
                position: Some(12.345),
                speed: Some(1.5),
                effort: Some(250.0),
                enabled: Some(true),
                error: "no error".into(),
                ..Channel::default()
            },
            Channel {
                name: "J2".into(),
                error: "timeout".into(),
                failures: 3,
                ..Channel::default()
            },
        ],
        t: 2.0,
        samples: 40,
        recording: Some("run.csv".into()),
        named_joints: false,
        ..Dashboard::default()
    };
    for k in 0..20 {
        d.t = f64::from(k) * 0.1;
        d.channels[0].position = Some(f64::from(k));
        d.push_history();
    }
    let s = screen(&d, 100, 30);
    assert!(s.contains("robobus monitor WHJ bus udp"), "{s}");
    assert!(s.contains("19.000"), "{s}");
    assert!(
        s.contains("1.50") && s.contains("250") && s.contains(" on "),
        "{s}"
    );
    assert!(s.contains("timeout"), "{s}");
    assert!(s.contains("position, degrees"), "{s}");
    assert!(s.contains("recording to run.csv"), "{s}");
    // The plot draws braille dots for J1's history.
    assert!(
        s.chars().any(|c| ('\u{2801}'..='\u{28FF}').contains(&c)),
        "{s}"
    );
    assert_eq!(d.channels[0].history.len(), 20);
}

#[test]
fn csv_rows_match_the_header_and_gaps_stay_empty() {
    let d = Dashboard {
        speed_unit: "deg/s",
        effort_name: "load",
        channels: vec![
            Channel {
                name: "S0".into(),
                position: Some(1.0),
                speed: Some(2.0),
                effort: Some(3.0),
                effort_unit: "load",
                fresh: true,
                ..Channel::default()
            },
            Channel {
                name: "S1".into(),
                effort_unit: "load",
                ..Channel::default()
            },
        ],
        t: 0.5,
        ..Dashboard::default()
    };
    assert_eq!(
        d.csv_header(),
        "t_s,s0_deg,s0_deg_per_s,s0_load,s1_deg,s1_deg_per_s,s1_load"
    );
    assert_eq!(d.csv_row(), "0.5000,1.0000,2.0000,3.0000,,,");
    let text = format!("{}\n{}\n", d.csv_header(), d.csv_row());
    let rec = crate::plot::Recording::parse(&text).unwrap();
    assert_eq!(rec.signals.len(), 6);
    assert_eq!(rec.signals[3].1, vec![None]);
}

#[test]
fn robot_joint_names_become_csv_columns_and_json_keys_carry_units() {
    let d = Dashboard {
        speed_unit: "deg/s",
        effort_name: "mA / load",
        channels: vec![
            Channel {
                name: "Left Knee".into(),
                position: Some(-12.5),
                effort: Some(40.0),
                effort_unit: "load",
                error: "ok".into(),
                fresh: true,
                ..Channel::default()
            },
            Channel {
                name: "shoulder-1".into(),
                position: Some(3.25),
                speed: Some(-6.0),
                effort: Some(812.0),
                effort_unit: "mA",
                enabled: Some(true),
                error: "no error".into(),
                failures: 2,
                fresh: true,
                ..Channel::default()
            },
        ],
        t: 1.23456,
        samples: 7,
        ..Dashboard::default()
    };
    assert_eq!(
        d.csv_header(),
        "t_s,left_knee_deg,left_knee_deg_per_s,left_knee_load,\
         shoulder_1_deg,shoulder_1_deg_per_s,shoulder_1_mA"
    );
    let v: serde_json::Value = serde_json::from_str(&d.json_line()).unwrap();
    assert_eq!(v["t_s"], 1.2346);
    assert_eq!(v["sample"], 7);
    let knee = &v["channels"][0];
    assert_eq!(knee["name"], "Left Knee");
    assert_eq!(knee["position_deg"], -12.5);
    assert!(knee["speed_deg_per_s"].is_null());
    assert_eq!(knee["load"], 40.0);
    assert!(knee.get("current_ma").is_none());
    let sh = &v["channels"][1];
    assert_eq!(sh["current_ma"], 812.0);
    assert_eq!(sh["speed_deg_per_s"], -6.0);
    assert_eq!(sh["enabled"], true);
    assert_eq!(sh["failures"], 2);
}

#[test]
#[allow(clippy::many_single_char_names)]
fn a_silent_device_is_marked_stale_everywhere_and_exits_3() {
    let mut c = Channel {
        name: "J2".into(),
        effort_unit: "mA",
        ..Channel::default()
    };
    // One good sample, then the joint goes away.
    c.position = Some(12.0);
    c.speed = Some(1.0);
    c.effort = Some(300.0);
    c.enabled = Some(true);
    c.got();
    c.missed("timeout");
    let d = Dashboard {
        speed_unit: "RPM",
        effort_name: "current mA",
        channels: vec![c],
        t: 2.0,
        samples: 2,
        ..Dashboard::default()
    };
    // CSV: an empty cell, never the last good value.
    assert_eq!(d.csv_row(), "2.0000,,,");
    // JSON: null values, marked stale.
    let v: serde_json::Value = serde_json::from_str(&d.json_line()).unwrap();
    let j = &v["channels"][0];
    assert!(
        j["position_deg"].is_null() && j["current_ma"].is_null(),
        "{j}"
    );
    assert_eq!(j["stale"], true);
    assert_eq!(j["error"], "timeout");
    // Plain lines show the error instead of a value.
    assert!(d.plain_line().contains("timeout"), "{}", d.plain_line());
    // The dashboard shows the loss and marks the values stale.
    let screen = screen(&d, 100, 20);
    assert!(
        screen.contains("stale") && screen.contains("1 (50%)"),
        "{screen}"
    );
    // Exit code 3 at the end.
    let e = silent(&d).unwrap_err();
    assert_eq!(crate::exit::Exit::of(&e), crate::exit::Exit::Timeout);
    assert!(e.to_string().contains("J2 (1 of 2 samples missing)"), "{e}");
}

#[test]
fn id_lists_are_checked() {
    assert_eq!(parse_ids_1_30("1-3,5").unwrap().0, [1, 2, 3, 5]);
    assert!(parse_ids_1_30("0").unwrap_err().contains("1..=30"));
    assert!(parse_ids_0_30("3-1").is_err());
    assert_eq!(ids_text(&[1, 2, 3]), "1-3");
    assert_eq!(ids_text(&[1, 3]), "1,3");
}
