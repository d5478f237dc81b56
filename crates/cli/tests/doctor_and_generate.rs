//! `robobus doctor` (checks that need no device), `robobus completions` and `robobus man`.

#![allow(clippy::unwrap_used, clippy::panic)] // test helpers: a failed unwrap is a failed test

use crate::common;

use common::{ok, robobus};

#[test]
fn doctor_reports_a_missing_port_with_a_fix_and_exit_code_5() {
    let r = robobus(&["doctor", "--port", "/nonexistent/ttyUSB9"]);
    assert_eq!(r.code, Some(5), "{r:#?}");
    assert!(
        r.stdout.contains("FAIL  /nonexistent/ttyUSB9"),
        "{}",
        r.stdout
    );
    assert!(r.stdout.contains("fix: check the cable"), "{}", r.stdout);
    assert!(r.stdout.contains("udp bus"), "{}", r.stdout);
    assert!(r.stderr.contains("1 check(s) failed"), "{}", r.stderr);
}

#[test]
fn doctor_json_lists_every_finding() {
    let dir = tempfile::tempdir().unwrap();
    let fake = dir.path().join("not-a-tty");
    std::fs::write(&fake, "").unwrap();
    let r = robobus(&[
        "doctor",
        "--json",
        "--port",
        fake.to_str().unwrap(),
        "--can",
        "vcan99",
    ]);
    let v: serde_json::Value = serde_json::from_str(&r.stdout).unwrap();
    let findings = v["findings"].as_array().unwrap();
    let get = |subject: &str, check: &str| {
        findings
            .iter()
            .find(|f| f["subject"] == subject && f["check"] == check)
            .unwrap_or_else(|| panic!("no {subject}/{check} in {findings:#?}"))
    };
    let port = fake.to_str().unwrap();
    assert_eq!(get(port, "exists")["status"], "warn");
    assert_eq!(get(port, "latency timer")["status"], "skip");
    let vcan = get("vcan99", "exists");
    assert_eq!(vcan["status"], "fail");
    assert!(vcan["fix"].as_str().unwrap().contains("type vcan"));
    assert!(
        ["ok", "warn", "skip", "fail"]
            .contains(&get("udp bus", "loopback")["status"].as_str().unwrap())
    );
    assert_eq!(v["ok"], false);
    assert_eq!(r.code, Some(5));
}

#[test]
fn completions_cover_the_subcommands() {
    for shell in ["bash", "zsh", "fish"] {
        let out = ok(&["completions", shell]);
        for word in [
            "wck",
            "whj",
            "sync-move",
            "release-iap",
            "doctor",
            "--dry-run",
        ] {
            assert!(out.contains(word), "{shell} completion lacks {word}");
        }
    }
    let r = robobus(&["completions", "tcsh"]);
    assert_eq!(r.code, Some(2));
}

#[test]
fn man_pages_are_written_for_every_subcommand() {
    let page = ok(&["man"]);
    assert!(
        page.starts_with(".ie") || page.contains(".TH robobus"),
        "{}",
        &page[..200]
    );
    let dir = tempfile::tempdir().unwrap();
    let r = robobus(&["man", "-o", dir.path().to_str().unwrap()]);
    assert_eq!(r.code, Some(0), "{r:#?}");
    for name in [
        "robobus.1",
        "robobus-wck.1",
        "robobus-wck-move.1",
        "robobus-whj-wave.1",
        "robobus-sim-wck.1",
    ] {
        let text = std::fs::read_to_string(dir.path().join(name))
            .unwrap_or_else(|e| panic!("{name}: {e}"));
        assert!(text.contains(".TH"), "{name} is not a man page");
    }
    let move_page = std::fs::read_to_string(dir.path().join("robobus-wck-move.1")).unwrap();
    assert!(move_page.contains("torque"), "{move_page}");
}

#[test]
fn doctor_refuses_overlong_names_without_panicking() {
    let long = "a".repeat(65_536);
    let long_path = format!("/dev/{long}");
    for (option, value, limit) in [
        ("--can", long.as_str(), "1..=15 bytes"),
        ("--port", long_path.as_str(), "1..=4095 bytes"),
        ("--wck-port", long_path.as_str(), "1..=4095 bytes"),
        ("--whj-bus", long.as_str(), "1..=15 bytes"),
        ("--can", "can0/../x", "no `/`"),
    ] {
        let r = robobus(&["doctor", option, value]);
        assert_eq!(r.code, Some(2), "{option}: {r:#?}");
        assert!(
            r.stderr.contains(option) && r.stderr.contains(limit),
            "{option}: {}",
            r.stderr
        );
        assert!(!r.stderr.contains("panicked"), "{}", r.stderr);
        assert!(
            r.stderr.len() < 300,
            "the value is not echoed in full: {}",
            r.stderr
        );
        assert!(r.stdout.is_empty(), "nothing checked: {}", r.stdout);
    }
    // The longest valid interface name is checked (and missing), not refused.
    let r = robobus(&["doctor", "--can", "abcdefghijklmno"]);
    assert_eq!(r.code, Some(5), "{r:#?}");
    assert!(
        r.stdout
            .contains("sample-point 0.8 dbitrate 5000000 dsample-point 0.75")
    );
}
