//! The benchmark suite in smoke mode: every benchmark runs briefly (the numbers mean
//! nothing) and the report is written with every section and its plots. The Python peers
//! run too (pyserial on the pty; python-can on the UDP bus inside a private network
//! namespace, `unshare -n`, as the link and CLI interop tests do).

#![allow(clippy::unwrap_used, clippy::panic)]

use std::path::PathBuf;

use robobus_testkit::Guest;

fn python() -> PathBuf {
    PathBuf::from(robobus_testkit::provision("py/ensure-pyserial"))
}

#[test]
fn smoke_run_writes_the_report_with_every_section() {
    let py = python();
    let dir = tempfile::tempdir().unwrap();
    Guest::new(env!("CARGO_BIN_EXE_robobus-bench"))
        .args(["--smoke", "--udp", "--python"])
        .arg(&py)
        .arg("--out")
        .arg(dir.path())
        .timeout_s(600)
        .in_private_netns()
        .expect_success();
    let report = std::fs::read_to_string(dir.path().join("report.md")).unwrap();
    for section in [
        "# robobus benchmark report",
        "**Smoke mode**",
        "## Summary",
        "## Machine",
        "## Codec",
        "## wCK polling",
        "## wCK synchronized-move streaming",
        "## WHJ free-running",
        "## WHJ fixed rate",
        "## Peers",
        "## Transports",
        "## System calls per transaction",
        "## Telemetry",
        "## Studio",
        "## Simulator",
    ] {
        assert!(report.contains(section), "no {section:?} in:\n{report}");
    }
    // Both peers ran against the simulators and answered.
    assert!(
        report.contains("| wCK polling 1 servos, 921600 bit/s, wait sleep, guard default |"),
        "{report}"
    );
    assert!(
        report.contains("| WHJ servo cycle 1 joints, wait sleep, collision window on, UDP"),
        "{report}"
    );
    assert!(!report.contains("FAILED"), "{report}");
    // Both wait modes ran, the spin mode over the pty and over the memory link, the wCK
    // cases with the client's default guard and with it off, and the simulators reported
    // their release lateness in each row.
    for row in [
        "| 1 | 921600 | zero | sleep | pty | default |",
        "| 1 | 921600 | zero | sleep | pty | off |",
        "| 1 | 921600 | zero | spin | pty | default |",
        "| 1 | 921600 | zero | spin | memory | off |",
        "| 1 | memory | spin | off |",
        "| 1 | memory, pipelined | sleep | on |",
        "| 1 | point-to-point | spin | 1000 |",
    ] {
        assert!(report.contains(row), "no row {row:?} in:\n{report}");
    }
    // Every plot the report links exists and is an SVG.
    let links: Vec<&str> = report
        .lines()
        .filter_map(|l| l.strip_prefix("![").and_then(|l| l.split_once("](")))
        .map(|(_, rest)| rest.trim_end_matches(')'))
        .collect();
    assert!(links.len() >= 4, "{links:?}");
    for l in links {
        let svg = std::fs::read_to_string(dir.path().join(l)).unwrap();
        assert!(svg.starts_with("<svg") && svg.contains("</svg>"), "{l}");
    }
}
