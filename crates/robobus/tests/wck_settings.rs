//! `robobus::ops::wck::settings` and the catalogue's `wck.backup` / `wck.diff` /
//! `wck.restore` against the wCK simulator on its virtual clock: a backup restored onto
//! a fresh servo gives an equal backup, only the groups that differ are written, the
//! factory settings are the manual's A-5, and a file is checked when it is read.

#![allow(clippy::unwrap_used, clippy::result_large_err)] // tests

use crate::station_support;

use robobus::catalogue::{self, Report, Request};
use robobus::ops::wck::settings::{self, WckSettings};
use robobus::ops::{Control, ErrorKind, OpError};
use robobus::station::Station;
use robobus::wck::Gains;
use robobus_wck::{Boundaries, DGain, PGain, Position, ServoId};

fn id(n: u8) -> ServoId {
    ServoId::new(n).unwrap()
}

fn run(s: &Station, json: &str) -> Result<Report, OpError> {
    let r = Request::parse_many(json).unwrap().remove(0);
    catalogue::run(s, &r, &mut Control::none())
}

#[test]
fn a_backup_restored_onto_a_fresh_servo_gives_an_equal_backup() {
    let (_s, w, _j) = station_support::station("wck", "whj");
    let mut bus = w.lock();
    let fresh = settings::backup(&mut bus, id(1)).unwrap();
    // A fresh servo has the factory settings (A-5).
    assert_eq!(
        WckSettings {
            servo: None,
            ..fresh
        },
        WckSettings::factory()
    );
    {
        let mut s = bus.servo(id(0));
        s.set_gains(Gains {
            p: PGain::new(40).unwrap(),
            d: DGain::new(12).unwrap(),
        })
        .unwrap();
        s.set_boundaries(
            Boundaries::new(Position::new(30).unwrap(), Position::new(200).unwrap()).unwrap(),
        )
        .unwrap();
    }
    let zero = settings::backup(&mut bus, id(0)).unwrap();
    assert_eq!(
        (zero.p_gain, zero.d_gain, zero.lower, zero.upper),
        (40, 12, 30, 200)
    );
    let text = serde_json::to_string(&zero).unwrap();
    assert!(
        text.contains("\"format\":\"robobus-wck-settings\""),
        "{text}"
    );
    assert_eq!(WckSettings::parse(&text).unwrap(), zero);
    let differ: Vec<&str> = settings::diff(&fresh, &zero)
        .iter()
        .map(|d| d.setting)
        .collect();
    assert_eq!(differ, ["gains", "bounds"]);

    let r = settings::restore(&mut bus, id(1), &zero).unwrap();
    assert_eq!(r.written, 2);
    assert_eq!(r.steps[0].to, "p_gain=40 d_gain=12");
    let one = settings::backup(&mut bus, id(1)).unwrap();
    assert_eq!(
        WckSettings {
            servo: Some(0),
            ..one
        },
        zero
    );
    // Restoring again sends only the reads: the settings before and after, five
    // packets each.
    let before = bus.stats().attempts;
    assert_eq!(
        settings::restore(&mut bus, id(1), &zero).unwrap().written,
        0
    );
    assert_eq!(bus.stats().attempts - before, 10);
    // Back to the factory settings.
    settings::restore(&mut bus, id(1), &WckSettings::factory()).unwrap();
    assert_eq!(
        WckSettings {
            servo: None,
            ..settings::backup(&mut bus, id(1)).unwrap()
        },
        WckSettings::factory()
    );
}

#[test]
fn a_settings_file_is_checked_when_it_is_read() {
    let good = serde_json::to_string(&WckSettings::factory()).unwrap();
    for (bad, want) in [
        ("{}".to_owned(), "not a wCK settings file"),
        (
            good.replace("robobus-wck-settings", "x"),
            "expected robobus-wck-settings",
        ),
        (good.replace("\"p_gain\":20", "\"p_gain\":0"), "1..=254"),
        (good.replace("\"accel\":60", "\"accel\":5"), "20..=100"),
        (
            good.replace("\"version\":1", "\"version\":2"),
            "expected version 1",
        ),
    ] {
        let e = WckSettings::parse(&bad).unwrap_err();
        assert_eq!(e.kind(), ErrorKind::BadInput, "{e}");
        assert!(e.to_string().contains(want), "{e} (wanted {want})");
    }
}

#[test]
fn the_catalogue_backs_up_diffs_and_restores_with_confirmation() {
    let (s, w, _j) = station_support::station("wck", "whj");
    run(&s, r#"{"op": "wck.set", "param": "speed", "id": 2, "speed": 10, "accel": 40, "confirm": true}"#)
        .unwrap();
    let backup = run(&s, r#"{"op": "wck.backup", "id": 2}"#).unwrap();
    assert_eq!(backup.results[0]["speed"], 10);
    let file = backup.summary.unwrap().to_string();
    for json in [
        serde_json::json!({"op": "wck.diff", "id": 0, "settings": file}).to_string(),
        r#"{"op": "wck.diff", "id": 0, "other": 2}"#.to_owned(),
        r#"{"op": "wck.diff", "id": 2, "factory": true}"#.to_owned(),
    ] {
        let d = run(&s, &json).unwrap();
        assert_eq!(d.results.len(), 1, "{json}: {:?}", d.results);
        assert_eq!(d.results[0]["setting"], "speed");
    }
    for bad in [
        r#"{"op": "wck.diff", "id": 0}"#,
        r#"{"op": "wck.restore", "id": 0}"#,
        r#"{"op": "wck.diff", "id": 0, "factory": true, "other": 1}"#,
    ] {
        assert_eq!(
            run(&s, bad).unwrap_err().kind(),
            ErrorKind::BadInput,
            "{bad}"
        );
    }
    // EEPROM writes: refused without confirmation, nothing sent.
    let restore = serde_json::json!({"op": "wck.restore", "id": 0, "settings": file});
    let sent = w.lock().stats().attempts;
    let e = run(&s, &restore.to_string()).unwrap_err();
    assert_eq!(e.kind(), ErrorKind::Refused, "{e}");
    assert_eq!(w.lock().stats().attempts, sent);
    let mut confirmed = restore.clone();
    confirmed["confirm"] = true.into();
    let r = run(&s, &confirmed.to_string()).unwrap();
    assert_eq!(r.summary.unwrap()["written"], 1);
    assert!(
        run(&s, r#"{"op": "wck.diff", "id": 0, "other": 2}"#)
            .unwrap()
            .results
            .is_empty()
    );
}
