//! `robobus plot`: PNG and SVG from a sample recording, and clear errors for bad CSV.

#![allow(clippy::unwrap_used, clippy::panic)] // test helpers: a failed unwrap is a failed test

use crate::common;

use std::fmt::Write as _;

use common::robobus;

fn sample_csv() -> String {
    let mut s = String::from("# sample recording\nt_s,j1_deg,j2_deg,j1_mA\n");
    for i in 0..100 {
        let t = f64::from(i) * 0.02;
        let gap = if (40..45).contains(&i) {
            String::new()
        } else {
            format!("{:.1}", 5.0 * t)
        };
        writeln!(
            s,
            "{t:.3},{:.3},{:.3},{gap}",
            30.0 * (t * 3.0).sin(),
            20.0 * (t * 5.0).cos()
        )
        .unwrap();
    }
    s
}

#[test]
fn plots_png_and_svg() {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("rec.csv");
    std::fs::write(&csv, sample_csv()).unwrap();
    let png = dir.path().join("rec.png");
    let svg = dir.path().join("rec.svg");
    for (out, extra) in [
        (&png, &["--width", "640", "--height", "480"][..]),
        (&svg, &[][..]),
    ] {
        let mut args = vec!["plot", csv.to_str().unwrap(), "-o", out.to_str().unwrap()];
        args.extend_from_slice(extra);
        let r = robobus(&args);
        assert_eq!(r.code, Some(0), "{r:#?}");
        assert!(
            r.stdout.contains("100 rows, 3 signals in 2 panels"),
            "{}",
            r.stdout
        );
    }
    // PNG: signature, IHDR with the requested size, and more than a blank canvas.
    let bytes = std::fs::read(&png).unwrap();
    assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n");
    assert_eq!(&bytes[12..16], b"IHDR");
    let w = u32::from_be_bytes(bytes[16..20].try_into().unwrap());
    let h = u32::from_be_bytes(bytes[20..24].try_into().unwrap());
    assert_eq!((w, h), (640, 480));
    assert!(
        bytes.len() > 10_000,
        "PNG suspiciously small: {} bytes",
        bytes.len()
    );
    // SVG: an svg element of the default size, one polyline per line piece, the legend.
    let text = std::fs::read_to_string(&svg).unwrap();
    assert!(text.starts_with("<svg"), "{}", &text[..80]);
    assert!(text.contains(r#"width="1200" height="600""#));
    assert!(text.trim_end().ends_with("</svg>"));
    for name in [
        "j1_deg",
        "j2_deg",
        "j1_mA",
        "rec.csv",
        "time (s)",
        "WHJ joint angle (deg)",
        "WHJ joint current (mA)",
    ] {
        assert!(text.contains(name), "SVG lacks {name}");
    }
    // j1_mA has a gap, so it is drawn in two pieces: 2 + 1 + 1 polylines for data.
    assert!(text.matches("<polyline").count() >= 4);
}

#[test]
fn signals_can_be_selected() {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("rec.csv");
    std::fs::write(&csv, sample_csv()).unwrap();
    let svg = dir.path().join("one.svg");
    let r = robobus(&[
        "plot",
        csv.to_str().unwrap(),
        "-o",
        svg.to_str().unwrap(),
        "--signals",
        "j2_deg",
    ]);
    assert_eq!(r.code, Some(0), "{r:#?}");
    let text = std::fs::read_to_string(&svg).unwrap();
    assert!(text.contains("j2_deg") && !text.contains("j1_deg"));
    let r = robobus(&[
        "plot",
        csv.to_str().unwrap(),
        "-o",
        svg.to_str().unwrap(),
        "--signals",
        "nope",
    ]);
    assert_eq!(r.code, Some(2));
    assert!(
        r.stderr.contains("`nope`") && r.stderr.contains("j1_deg"),
        "{}",
        r.stderr
    );
}

#[test]
fn bad_csv_names_the_line() {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("bad.csv");
    std::fs::write(&csv, "t_s,a,b\n0,1,2\n0.1,1,oops\n").unwrap();
    let out = dir.path().join("bad.png");
    let r = robobus(&["plot", csv.to_str().unwrap(), "-o", out.to_str().unwrap()]);
    assert_eq!(r.code, Some(2), "{r:#?}");
    assert!(r.stderr.contains("bad.csv:3:"), "{}", r.stderr);
    assert!(r.stderr.contains("`oops` is not a number"), "{}", r.stderr);
    assert!(!out.exists());
    std::fs::write(&csv, "t_s,a\n0,1\n1\n").unwrap();
    let r = robobus(&["plot", csv.to_str().unwrap(), "-o", out.to_str().unwrap()]);
    assert_eq!(r.code, Some(2));
    assert!(
        r.stderr.contains("bad.csv:3:") && r.stderr.contains("1 cells"),
        "{}",
        r.stderr
    );
    let r = robobus(&["plot", csv.to_str().unwrap(), "-o", "x.jpg"]);
    assert_eq!(r.code, Some(2));
    assert!(r.stderr.contains(".png or .svg"), "{}", r.stderr);
    // A missing recording is bad input (exit 2), as every other bad argument is.
    let r = robobus(&["plot", "/nonexistent/rec.csv", "-o", "x.png"]);
    assert_eq!(r.code, Some(2));
    assert!(
        r.stderr.contains("/nonexistent/rec.csv: no such file"),
        "{}",
        r.stderr
    );
}

/// A recording of both families with targets: a wCK servo's angle and its target, a WHJ
/// joint's angle and its target (named the other way round), and the joint's current.
fn two_family_csv() -> String {
    let mut s = String::from("t_s,wck0_deg,wck0_target_deg,whj1_deg,whj1_deg_target,whj1_mA\n");
    for i in 0..200 {
        let t = f64::from(i) * 0.01;
        let step = if t < 0.5 { 0.0 } else { 60.0 };
        let sine = 20.0 * (t * 3.0).sin();
        writeln!(
            s,
            "{t:.3},{:.2},{step:.1},{:.3},{sine:.3},{:.1}",
            step * (1.0 - (-(t - 0.5).max(0.0) * 8.0).exp()),
            20.0 * (t * 3.0 - 0.1).sin(),
            800.0 * (t * 3.0).cos()
        )
        .unwrap();
    }
    s
}

#[test]
fn one_panel_per_family_and_unit_with_targets_dashed() {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("two.csv");
    std::fs::write(&csv, two_family_csv()).unwrap();
    let expected: serde_json::Value = serde_json::json!([
        {"title": "wCK servo angle (deg)", "series": [
            {"signal": "wck0_deg", "target": "wck0_target_deg"}]},
        {"title": "WHJ joint angle (deg)", "series": [
            {"signal": "whj1_deg", "target": "whj1_deg_target"}]},
        {"title": "WHJ joint current (mA)", "series": [
            {"signal": "whj1_mA", "target": null}]},
    ]);
    for ext in ["png", "svg"] {
        let out = dir.path().join(format!("two.{ext}"));
        let r = robobus(&[
            "--json",
            "plot",
            csv.to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
        ]);
        assert_eq!(r.code, Some(0), "{r:#?}");
        let doc: serde_json::Value = serde_json::from_str(&r.stdout).unwrap();
        assert_eq!(doc["panels"], expected, "{doc:#}");
        assert_eq!(doc["x_title"], "time (s)");
        assert_eq!(doc["rows"], 200);
        assert_eq!(doc["signals"].as_array().unwrap().len(), 5);
    }
    // PNG: three panels make it 840 pixels high (240 each and 120), 1200 wide.
    let bytes = std::fs::read(dir.path().join("two.png")).unwrap();
    assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n");
    let w = u32::from_be_bytes(bytes[16..20].try_into().unwrap());
    let h = u32::from_be_bytes(bytes[20..24].try_into().unwrap());
    assert_eq!((w, h), (1200, 840));
    // SVG: the axis titles, one legend entry per signal and one for the dashed targets
    // in each panel with targets; a target is drawn in its signal's colour (the first
    // of the palette, #1F77B4, in every panel): one polyline for the signal, one or more
    // per dash of the target, one for its legend sample.
    let text = std::fs::read_to_string(dir.path().join("two.svg")).unwrap();
    assert!(text.contains(r#"width="1200" height="840""#));
    let labels: Vec<&str> = text
        .split("</text>")
        .filter_map(|t| t.rsplit_once('>').map(|(_, label)| label.trim()))
        .filter(|l| !l.is_empty() && l.parse::<f64>().is_err())
        .collect();
    assert_eq!(
        labels,
        [
            "wCK servo angle (deg)",
            "wck0_deg",
            "target",
            "WHJ joint angle (deg)",
            "whj1_deg",
            "target",
            "WHJ joint current (mA)",
            "whj1_mA",
            "time (s)",
            "two.csv",
        ]
    );
    let blue = text.matches(r##"stroke="#1F77B4""##).count();
    assert!(blue > 3 * 2 + 10, "{blue} blue lines: targets not dashed?");
}

#[test]
fn selected_signals_bring_their_targets() {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("two.csv");
    std::fs::write(&csv, two_family_csv()).unwrap();
    let out = dir.path().join("one.svg");
    let r = robobus(&[
        "--json",
        "plot",
        csv.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--signals",
        "whj1_deg,wck0_target_deg",
    ]);
    assert_eq!(r.code, Some(0), "{r:#?}");
    let doc: serde_json::Value = serde_json::from_str(&r.stdout).unwrap();
    assert_eq!(
        doc["signals"],
        serde_json::json!(["wck0_target_deg", "whj1_deg", "whj1_deg_target"])
    );
    // A target without its signal is a line of its own, in its signal's panel.
    assert_eq!(
        doc["panels"],
        serde_json::json!([
            {"title": "wCK servo angle (deg)", "series": [
                {"signal": "wck0_target_deg", "target": null}]},
            {"title": "WHJ joint angle (deg)", "series": [
                {"signal": "whj1_deg", "target": "whj1_deg_target"}]},
        ])
    );
    let text = std::fs::read_to_string(&out).unwrap();
    assert!(text.contains(r#"width="1200" height="600""#));
}

/// Runs `robobus ARGS`, killing it (and failing) if it is not done within 30 s: a plot
/// that loops forever must fail the test, not hang it.
fn robobus_bounded(args: &[&str]) -> common::Run {
    use std::process::{Command, Stdio};
    use std::time::{Duration, Instant};
    let mut child = Command::new(env!("CARGO_BIN_EXE_robobus"))
        .args(args)
        .env_remove("RUST_LOG")
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let start = Instant::now();
    while child.try_wait().unwrap().is_none() {
        if start.elapsed() > Duration::from_secs(30) {
            child.kill().unwrap();
            panic!("robobus {args:?} still running after 30 s");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    child.wait_with_output().unwrap().into()
}

#[test]
fn absurd_ranges_are_refused_and_extreme_ones_still_plot() {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("r.csv");
    let out = dir.path().join("r.svg");
    let run = |text: &str| {
        std::fs::write(&csv, text).unwrap();
        robobus_bounded(&["plot", csv.to_str().unwrap(), "-o", out.to_str().unwrap()])
    };
    for (text, needle) in [
        (
            "t,a\n-1e308,1\n1e308,2\n",
            "r.csv:2: column 1 (`t`): -1e308",
        ),
        (
            "t,a\n0,-1e308\n1,1e308\n",
            "r.csv:2: column 2 (`a`): -1e308",
        ),
        ("t,a\n0,1\n1,1e13\n", "r.csv:3: column 2 (`a`): 1e13"),
        ("t,a\n0,inf\n", "`inf` is not a number"),
        ("t,a\n0,NaN\n", "`NaN` is not a number"),
    ] {
        let r = run(text);
        assert_eq!(r.code, Some(2), "{text:?}: {r:#?}");
        assert!(
            r.stderr.contains(needle),
            "{needle:?} missing: {}",
            r.stderr
        );
        if needle.contains("1e") {
            assert!(r.stderr.contains("-1e12..=1e12"), "{}", r.stderr);
        }
        assert!(!out.exists());
    }
    // At the limits: the widest span, a tiny span at a huge magnitude, a single time.
    for text in [
        "t,a\n0,-1e12\n1,1e12\n",
        "t,a\n-1e12,0\n1e12,1e-300\n",
        "t,a\n1e12,5\n1e12,5.000001\n",
        "t,a\n999999999999.9999,1e12\n1e12,1e12\n",
        "t,a\n7,7\n",
    ] {
        let r = run(text);
        assert_eq!(r.code, Some(0), "{text:?}: {r:#?}");
        assert!(std::fs::read_to_string(&out).unwrap().ends_with("</svg>\n"));
        std::fs::remove_file(&out).unwrap();
    }
}

#[test]
fn oversized_files_and_lines_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("r.png");
    // A line over 64 KiB.
    let csv = dir.path().join("long.csv");
    let mut text = String::from("t,a\n0,1\n1,");
    text.push_str(&"1".repeat(70_000));
    text.push('\n');
    std::fs::write(&csv, &text).unwrap();
    let r = robobus_bounded(&["plot", csv.to_str().unwrap(), "-o", out.to_str().unwrap()]);
    assert_eq!(r.code, Some(2), "{r:#?}");
    assert!(
        r.stderr.contains("long.csv:3:") && r.stderr.contains("64 KiB"),
        "{}",
        r.stderr
    );
    // A file over 64 MiB (sparse), and an endless device.
    let big = dir.path().join("big.csv");
    let f = std::fs::File::create(&big).unwrap();
    f.set_len((64 << 20) + 1).unwrap();
    for path in [big.to_str().unwrap(), "/dev/zero"] {
        let r = robobus_bounded(&["plot", path, "-o", out.to_str().unwrap()]);
        assert_eq!(r.code, Some(2), "{path}: {r:#?}");
        assert!(
            r.stderr.contains(path) && r.stderr.contains("64 MiB"),
            "{}",
            r.stderr
        );
    }
    assert!(!out.exists());
}
