use ratatui::Terminal;
use ratatui::backend::TestBackend;

use robobus::record::{RecordFormat, Recorder, SampleTable};

use std::io::Cursor;

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
    let mut t = SampleTable::whj(&[1, 2]);
    let j1 = &mut t.rows[0];
    j1.position_deg = Some(12.345);
    j1.speed = Some(1.5);
    j1.effort = Some(250.0);
    j1.enabled = Some(true);
    "no error".clone_into(&mut j1.error);
    j1.got();
    let j2 = &mut t.rows[1];
    "timeout".clone_into(&mut j2.error);
    j2.failures = 3;
    t.samples = 40;
    let mut d = Dashboard {
        recording: Some("run.csv".into()),
        ..Dashboard::new("WHJ bus udp".into(), "current mA", t)
    };
    for k in 0..20 {
        d.table.t_s = f64::from(k) * 0.1;
        d.table.rows[0].position_deg = Some(f64::from(k));
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
    assert_eq!(d.history[0].len(), 20);
}

#[test]
fn a_recording_reads_back_as_robobus_plot_reads_it() {
    let mut t = SampleTable::wck(&[0, 1]);
    t.rows[0].position_deg = Some(1.0);
    t.rows[0].speed = Some(2.0);
    t.rows[0].effort = Some(3.0);
    t.rows[0].got();
    t.t_s = 0.5;
    let mut r = Recorder::new(
        Cursor::new(Vec::new()),
        RecordFormat::Csv,
        "wCK port sim",
        &t,
    )
    .unwrap();
    r.record(&t).unwrap();
    let text = String::from_utf8(r.finish().unwrap().into_inner()).unwrap();
    let rec = crate::plot::Recording::parse(&text).unwrap();
    assert_eq!(rec.signals.len(), 6);
    assert_eq!(rec.signals[0].1, vec![Some(1.0)]);
    assert_eq!(rec.signals[3].1, vec![None]);
}

#[test]
fn a_silent_device_is_marked_stale_and_exits_3() {
    let mut t = SampleTable::whj(&[2]);
    // One good sample, then the joint goes away.
    let j = &mut t.rows[0];
    j.position_deg = Some(12.0);
    j.speed = Some(1.0);
    j.effort = Some(300.0);
    j.enabled = Some(true);
    j.got();
    j.missed("timeout");
    t.t_s = 2.0;
    t.samples = 2;
    let d = Dashboard::new(String::new(), "current mA", t);
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
    assert!(e.to_string().contains("j2 (1 of 2 samples missing)"), "{e}");
}

#[test]
fn id_lists_are_checked() {
    assert_eq!(parse_ids_1_30("1-3,5").unwrap().0, [1, 2, 3, 5]);
    assert!(parse_ids_1_30("0").unwrap_err().contains("1..=30"));
    assert!(parse_ids_0_30("3-1").is_err());
    assert_eq!(ids_text(&[1, 2, 3]), "1-3");
    assert_eq!(ids_text(&[1, 3]), "1,3");
}
