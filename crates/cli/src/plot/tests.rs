//! Unit tests: the CSV parser, the panels and titles, ticks, the font's metrics and the
//! bitmap text's spacing.

use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::HPos;

use super::draw::{default_height, span, ticks};
use super::panels::{Panel, Series, panels, target_of, time_title};
use super::recording::{MAX_LINE_BYTES, Recording};
use super::text::{FAMILY, FontMetrics, Label, Pen, px, register_font};

#[test]
fn parses_header_rows_and_gaps() {
    let r = Recording::parse("# c\nt_s,a,b\n0,1,\n0.5,2,3\n").unwrap();
    assert_eq!(r.time_name, "t_s");
    assert_eq!(r.time, [0.0, 0.5]);
    assert_eq!(r.signals[0], ("a".into(), vec![Some(1.0), Some(2.0)]));
    assert_eq!(r.signals[1], ("b".into(), vec![None, Some(3.0)]));
}

#[test]
fn values_and_lines_are_bounded() {
    let e = Recording::parse("t,a\n0,1\n1,-1e308\n").unwrap_err();
    assert_eq!(e.line, 3);
    assert!(e.message.contains("-1e12..=1e12"), "{}", e.message);
    assert!(Recording::parse("t,a\n0,1e12\n1,-1e12\n").is_ok());
    let long = format!("t,a\n0,{}\n", "1".repeat(MAX_LINE_BYTES));
    let e = Recording::parse(&long).unwrap_err();
    assert_eq!(e.line, 2);
    assert!(e.message.contains("64 KiB"), "{}", e.message);
    // Spans are widened to something f64 can subdivide.
    let (lo, hi) = span(1e12, 1e12);
    assert!(hi - lo >= 1e3 && lo < 1e12 && hi > 1e12);
    assert_eq!(span(f64::NEG_INFINITY, 1.0), (0.0, 1.0));
}

#[test]
fn errors_name_the_line() {
    let e = Recording::parse("t,a\n0,1\n1,x\n").unwrap_err();
    assert_eq!(e.line, 3);
    assert!(e.message.contains("`x`"), "{}", e.message);
    assert_eq!(Recording::parse("t,a\n0,1,2\n").unwrap_err().line, 2);
    assert_eq!(Recording::parse("t,a\n1,1\n0,1\n").unwrap_err().line, 3);
    assert_eq!(Recording::parse("t\n").unwrap_err().line, 1);
    assert!(Recording::parse("t,a\n").is_err());
    assert!(Recording::parse("").is_err());
}

fn series(signal: usize, target: Option<usize>) -> Series {
    Series { signal, target }
}

fn panel(title: &str, series: &[Series]) -> Panel {
    Panel {
        title: title.into(),
        series: series.to_vec(),
    }
}

#[test]
fn the_demo_trace_is_one_panel_per_family_with_targets() {
    let names = robobus::demo::Trace::names();
    assert_eq!(
        panels(&names),
        [
            panel(
                "wCK servo angle (deg)",
                &[
                    series(0, Some(11)),
                    series(1, Some(12)),
                    series(2, Some(13)),
                    series(3, Some(14)),
                ]
            ),
            panel(
                "WHJ joint angle (deg)",
                &(4..11).map(|i| series(i, Some(i + 11))).collect::<Vec<_>>()
            ),
        ]
    );
}

#[test]
fn monitor_recordings_are_one_panel_per_unit() {
    // `robobus monitor` on a WHJ bus, a wCK port, a robot file.
    let whj = ["j1_deg", "j1_rpm", "j1_mA", "j2_deg", "j2_rpm", "j2_mA"];
    assert_eq!(
        panels(&whj),
        [
            panel("WHJ joint angle (deg)", &[series(0, None), series(3, None)]),
            panel("WHJ joint speed (rpm)", &[series(1, None), series(4, None)]),
            panel(
                "WHJ joint current (mA)",
                &[series(2, None), series(5, None)]
            ),
        ]
    );
    let wck = [
        "s0_deg",
        "s0_deg_per_s",
        "s0_load",
        "s1_deg",
        "s1_deg_per_s",
        "s1_load",
    ];
    assert_eq!(
        panels(&wck),
        [
            panel("wCK servo angle (deg)", &[series(0, None), series(3, None)]),
            panel(
                "wCK servo speed (deg/s)",
                &[series(1, None), series(4, None)]
            ),
            panel("wCK servo load", &[series(2, None), series(5, None)]),
        ]
    );
    let robot = [
        "left_knee_deg",
        "left_knee_deg_per_s",
        "left_knee_load",
        "shoulder_1_deg",
        "shoulder_1_deg_per_s",
        "shoulder_1_mA",
    ];
    assert_eq!(
        panels(&robot),
        [
            panel("angle (deg)", &[series(0, None), series(3, None)]),
            panel("speed (deg/s)", &[series(1, None), series(4, None)]),
            panel("load", &[series(2, None)]),
            panel("current (mA)", &[series(5, None)]),
        ]
    );
    // Other spellings of the families and units; names without a unit.
    let other = [
        "servo3_deg",
        "wck_hip_rad",
        "joint2_rad_s",
        "WHJ4_DEG_S",
        "a",
        "b",
    ];
    assert_eq!(
        panels(&other),
        [
            panel("wCK servo angle (deg)", &[series(0, None)]),
            panel("wCK servo angle (rad)", &[series(1, None)]),
            panel("WHJ joint speed (rad/s)", &[series(2, None)]),
            panel("WHJ joint speed (deg/s)", &[series(3, None)]),
            panel("value", &[series(4, None), series(5, None)]),
        ]
    );
}

#[test]
fn targets_pair_with_their_signals() {
    let names = [
        "j1_deg",
        "j1_target_deg", // j1_deg's target
        "j2_deg_target", // j2_deg's target, before it
        "j2_deg",
        "j9_target_deg", // no j9_deg: a line of its own, in j9_deg's panel
        "a",
        "a_target",      // a's target
        "a_targets",     // not a target's name
        "j1_deg_target", // a second target of j1_deg: a line of its own
        "J1_TARGET_DEG", // names are compared exactly: no `J1_DEG`
    ];
    assert_eq!(target_of("j1_target_deg").as_deref(), Some("j1_deg"));
    assert_eq!(target_of("j2_deg_target").as_deref(), Some("j2_deg"));
    assert_eq!(target_of("a_targets"), None);
    assert_eq!(target_of("_target"), None);
    assert_eq!(
        panels(&names),
        [
            panel(
                "WHJ joint angle (deg)",
                &[
                    series(0, Some(1)),
                    series(3, Some(2)),
                    series(4, None),
                    series(8, None),
                    series(9, None),
                ]
            ),
            panel("value", &[series(5, Some(6)), series(7, None)]),
        ]
    );
}

#[test]
fn the_time_axis_is_titled_with_its_unit() {
    for (name, title) in [
        ("t_s", "time (s)"),
        ("T_S", "time (s)"),
        ("time_ms", "time (ms)"),
        ("t_us", "time (µs)"),
        ("elapsed_min", "elapsed (min)"),
        ("t", "time"),
        ("stamp", "stamp"),
        ("_s", "_s"),
    ] {
        assert_eq!(time_title(name), title, "{name}");
    }
    assert_eq!(default_height(1), 600);
    assert_eq!(default_height(2), 600);
    assert_eq!(default_height(3), 840);
    assert_eq!(default_height(1000), 8000);
}

#[test]
fn ticks_step_by_one_two_five() {
    let labels = |lo, hi, most| -> Vec<String> {
        ticks(lo, hi, most).0.into_iter().map(|(_, l)| l).collect()
    };
    assert_eq!(labels(0.0, 10.0, 5), ["0", "2", "4", "6", "8", "10"]);
    assert_eq!(
        labels(-0.35, 1.05, 7),
        ["-0.2", "0.0", "0.2", "0.4", "0.6", "0.8", "1.0"]
    );
    assert_eq!(labels(-52.0, 83.0, 3), ["-50", "0", "50"]);
    assert_eq!(
        labels(0.0, 2e12, 4),
        ["0.0e0", "5.0e11", "1.0e12", "1.5e12", "2.0e12"]
    );
    assert!((ticks(0.0, 1.0, 4).1 - 0.5).abs() < 1e-12);
    assert!(ticks(1.0, 1.0, 4).0.is_empty());
}

#[test]
fn font_metrics_are_the_fonts_and_match_plotters_widths() {
    let f = FontMetrics::embedded().unwrap();
    // DejaVu Sans: advance and left side bearing, font units.
    for (c, metrics) in [
        ('1', (1303.0, 225.0)),
        ('j', (569.0, -37.0)),
        ('_', (1024.0, -20.0)),
        ('h', (1298.0, 186.0)),
    ] {
        assert_eq!(f.h_metrics(f.glyph(c)), metrics, "{c:?}");
    }
    assert_eq!(f.glyph('\u{10000}'), 0);
    // Widths with kerning (`AV`, `To`) as plotters (ab_glyph) measures them.
    register_font().unwrap();
    for text in ["whj1_deg", "WHJ joint angle (deg)", "AVATAR To -40.5 µs °"] {
        for size in [14, 16, 20] {
            let font = FontDesc::new(FontFamily::Name(FAMILY), f64::from(size), FontStyle::Normal);
            let ((x0, _), (x1, _)) = font.layout_box(text).unwrap();
            assert_eq!(
                px(f.layout(text).1 * f.scale(size)),
                x1 - x0,
                "{text:?} at {size}"
            );
        }
    }
    assert!(f.kerning(f.glyph('A'), f.glyph('V')) < 0.0);
}

/// The ink of `label` drawn on a white bitmap: per column, whether any pixel is not
/// white.
fn ink_columns(draw: impl FnOnce(&DrawingArea<BitMapBackend<'_>, Shift>)) -> Vec<bool> {
    let (w, h) = (300u32, 40u32);
    let mut buf = vec![0u8; 3 * 300 * 40];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        root.fill(&WHITE).unwrap();
        draw(&root);
        root.present().unwrap();
    }
    (0..300)
        .map(|x| (0..40).any(|y| buf[3 * (y * 300 + x)..][..3] != [255, 255, 255]))
        .collect()
}

/// The first and last inked column, and the blank ones between.
fn blanks(ink: &[bool]) -> (usize, usize, Vec<usize>) {
    let first = ink.iter().position(|&i| i).unwrap();
    let last = ink.iter().rposition(|&i| i).unwrap();
    let blank = (first..=last).filter(|&x| !ink[x]).collect();
    (first, last, blank)
}

#[test]
fn bitmap_labels_keep_the_fonts_spacing() {
    register_font().unwrap();
    let font = FontMetrics::embedded().unwrap();
    let pen = |text: &'static str| {
        move |root: &DrawingArea<BitMapBackend<'_>, Shift>| {
            let label = Label {
                text,
                at: (10, 20),
                size: 14,
                color: BLACK,
                align: HPos::Left,
                upwards: false,
            };
            Pen {
                area: root,
                font,
                bitmap: true,
            }
            .draw(&label)
            .unwrap();
        }
    };
    let plotters = |text: &'static str| {
        move |root: &DrawingArea<BitMapBackend<'_>, Shift>| {
            let style = (FAMILY, 14).into_font().color(&BLACK);
            root.draw_text(text, &style, (10, 20)).unwrap();
        }
    };
    // A glyph's ink starts at its left side bearing from the pen: 225 units (1.3 px at
    // 14 px) for `1`, -37 (-0.2 px) for `j`. plotters' own bitmap text starts it at the
    // pen. (When plotters places glyphs right, `Pen` can draw its text directly.)
    assert_eq!(blanks(&ink_columns(pen("1"))).0, 11);
    assert_eq!(blanks(&ink_columns(pen("j"))).0, 9);
    assert_eq!(blanks(&ink_columns(plotters("1"))).0, 10);
    // `whj1_deg` at 14 px: each glyph's box (DejaVu Sans: xMin..xMax w 86..1589,
    // h 186..1124, j -37..377, 1 225..1114, _ -20..1044, d 113..1114, e 113..1151,
    // g 113..1114) from its pen position (the advances: 1675, 1298, 569, 1303, 1024,
    // 1300, 1260) ink columns 10..=19, 21..=26, 26..=29, 32..=37, 37..=44, 44..=50,
    // 52..=58, 59..=65: blank are 20, 30, 31 and 51.
    assert_eq!(
        blanks(&ink_columns(pen("whj1_deg"))),
        (10, 65, vec![20, 30, 31, 51])
    );
    // plotters: `wh j1 _deg`.
    assert_ne!(
        blanks(&ink_columns(plotters("whj1_deg"))).2,
        vec![20, 30, 31, 51]
    );
}
