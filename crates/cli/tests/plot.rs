//! `robobus plot`: PNG and SVG from a sample recording, and clear errors for bad CSV.

#![allow(clippy::unwrap_used, clippy::panic)] // test helpers: a failed unwrap is a failed test

mod common;

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
        assert!(r.stdout.contains("100 rows, 3 signals"), "{}", r.stdout);
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
    for name in ["j1_deg", "j2_deg", "j1_mA", "t_s", "rec.csv"] {
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
    let r = robobus(&["plot", "/nonexistent/rec.csv", "-o", "x.png"]);
    assert_eq!(r.code, Some(1));
    assert!(
        r.stderr.contains("cannot read /nonexistent/rec.csv"),
        "{}",
        r.stderr
    );
}
