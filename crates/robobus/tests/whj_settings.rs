//! `robobus::ops::whj::settings` against the simulator on its virtual clock: a backup
//! restored onto a fresh joint gives an equal backup (but for the bus identity, which a
//! restore never writes); a restore writes only what differs and refuses, before anything
//! is sent, another model or firmware, an enabled joint and an unconfirmed confirm-class
//! register; the file format is checked when it is read.

#![allow(clippy::unwrap_used, clippy::panic, clippy::result_large_err)] // tests

use crate::whj_common;

use robobus::ops::ErrorKind;
use robobus::ops::whj::settings::{self, Settings};
use robobus::whj::JointBus;
use robobus_whj::JointId;
use whj_common::{chain, sim_link, virtual_config as config};

fn id(n: u8) -> JointId {
    JointId::new(n).unwrap()
}

/// Two fresh WHJ30 joints (1, 2) on the virtual clock, disabled.
fn bus() -> (JointBus, robobus_sim::whj::WhjSimHandle) {
    let (link, handle) = sim_link(chain(2));
    let bus = JointBus::open_with(link, config()).unwrap();
    for j in [1, 2] {
        bus.joint(id(j)).unwrap().disable().unwrap();
    }
    (bus, handle)
}

fn raw(s: &Settings, register: &str) -> i64 {
    s.get(register)
        .unwrap_or_else(|| panic!("no {register}"))
        .raw
}

/// Joint 1 tuned away from its factory settings.
fn tune(bus: &JointBus) {
    let j = bus.joint(id(1)).unwrap();
    j.write_register("LIT_MAX_SPEED", 20.0).unwrap();
    j.write_register("SEV_POSITION_P", 1234.0).unwrap();
    j.write_register("LIT_MIN_POSITION", -90.0).unwrap();
    j.write_register("LIT_MAX_POSITION", 90.0).unwrap();
    j.save_to_flash().unwrap();
}

#[test]
fn a_backup_restored_onto_a_fresh_joint_gives_an_equal_backup() {
    let (bus, _sim) = bus();
    tune(&bus);
    let one = settings::backup(&bus, id(1)).unwrap();
    assert_eq!(one.format, settings::SETTINGS_FORMAT);
    assert_eq!((one.joint, one.model.as_str()), (1, "WHJ30"));
    assert_eq!(raw(&one, "SYS_ID"), 1);
    assert_eq!(raw(&one, "SEV_POSITION_P"), 1234);
    let limit = one.get("LIT_MIN_POSITION").unwrap();
    assert_eq!((limit.raw, limit.value), (-900_000, Some(-90.0)));
    // The file round-trips.
    let text = serde_json::to_string_pretty(&one).unwrap();
    assert_eq!(Settings::parse(&text).unwrap(), one);

    let fresh = settings::backup(&bus, id(2)).unwrap();
    let before: Vec<String> = settings::diff(&fresh, &one)
        .into_iter()
        .map(|d| d.register)
        .collect();
    assert_eq!(
        before,
        [
            "SYS_ID",
            "LIT_MAX_SPEED",
            "LIT_MIN_POSITION",
            "LIT_MAX_POSITION",
            "SEV_POSITION_P"
        ]
    );
    let report = settings::restore(&bus, id(2), &one, false).unwrap();
    assert_eq!(report.written, 4);
    assert!(report.saved);
    let skipped = &report.steps[0];
    assert_eq!(skipped.register, "SYS_ID");
    assert!(skipped.action.starts_with("skipped"), "{skipped:?}");
    assert_eq!(report.differ_after, ["SYS_ID"]);
    // Joint 2 now has joint 1's settings, but its own ID.
    let two = settings::backup(&bus, id(2)).unwrap();
    let after: Vec<String> = settings::diff(&two, &one)
        .into_iter()
        .map(|d| d.register)
        .collect();
    assert_eq!(after, ["SYS_ID"]);
    assert_eq!(raw(&two, "SYS_ID"), 2);
    // Restoring again writes nothing.
    let again = settings::restore(&bus, id(2), &one, false).unwrap();
    assert_eq!((again.written, again.saved), (0, false));
}

#[test]
fn a_restore_refuses_before_writing_anything() {
    let (bus, _sim) = bus();
    tune(&bus);
    let one = settings::backup(&bus, id(1)).unwrap();
    let untouched = settings::backup(&bus, id(2)).unwrap();
    let unchanged = || assert_eq!(settings::backup(&bus, id(2)).unwrap(), untouched);

    // Another model or firmware.
    for other in [
        Settings {
            model: "WHJ60".into(),
            ..one.clone()
        },
        Settings {
            firmware: "0001".into(),
            ..one.clone()
        },
    ] {
        let e = settings::restore(&bus, id(2), &other, true).unwrap_err();
        assert_eq!(e.kind(), ErrorKind::Refused, "{e}");
        assert!(e.to_string().contains("nothing was written"), "{e}");
        unchanged();
    }
    // An enabled joint.
    bus.joint(id(2)).unwrap().enable().unwrap();
    let e = settings::restore(&bus, id(2), &one, true).unwrap_err();
    assert!(e.to_string().contains("disable it"), "{e}");
    bus.joint(id(2)).unwrap().disable().unwrap();
    unchanged();
    // A confirm-class register that differs, unconfirmed: nothing at all is written,
    // not even the plain registers before it.
    let mut on_power = one.clone();
    let s = on_power
        .settings
        .iter_mut()
        .find(|s| s.register == "SYS_ENABLE_ON_POWER")
        .unwrap();
    s.raw = 1 - s.raw;
    assert!(
        settings::confirm_needed(&on_power)
            .iter()
            .any(|(r, _)| *r == "SYS_ENABLE_ON_POWER")
    );
    let e = settings::restore(&bus, id(2), &on_power, false).unwrap_err();
    assert_eq!(e.kind(), ErrorKind::Refused, "{e}");
    assert!(e.to_string().contains("SYS_ENABLE_ON_POWER"), "{e}");
    unchanged();
    // Confirmed, it is written.
    let r = settings::restore(&bus, id(2), &on_power, true).unwrap();
    assert!(
        r.steps
            .iter()
            .any(|s| s.register == "SYS_ENABLE_ON_POWER" && s.action.contains("confirmed")),
        "{r:?}"
    );
}

#[test]
fn limits_are_written_in_the_order_that_never_inverts_them() {
    let (bus, _sim) = bus();
    // Joint 1 limited to 100..=120 degrees, joint 2 at its factory limits: restoring joint
    // 1's limits onto joint 2 must raise the maximum... and restoring a low window onto a
    // high one must lower the minimum first.
    let j = bus.joint(id(1)).unwrap();
    j.write_register("LIT_MAX_POSITION", 120.0).unwrap();
    j.write_register("LIT_MIN_POSITION", 100.0).unwrap();
    let high = settings::backup(&bus, id(1)).unwrap();
    j.write_register("LIT_MIN_POSITION", -120.0).unwrap();
    j.write_register("LIT_MAX_POSITION", -100.0).unwrap();
    let low = settings::backup(&bus, id(1)).unwrap();
    settings::restore(&bus, id(2), &high, false).unwrap();
    settings::restore(&bus, id(2), &low, false).unwrap();
    let two = settings::backup(&bus, id(2)).unwrap();
    assert_eq!(raw(&two, "LIT_MIN_POSITION"), -1_200_000);
    assert_eq!(raw(&two, "LIT_MAX_POSITION"), -1_000_000);
    settings::restore(&bus, id(2), &high, false).unwrap();
    let two = settings::backup(&bus, id(2)).unwrap();
    assert_eq!(raw(&two, "LIT_MIN_POSITION"), 1_000_000);
}

#[test]
fn a_settings_file_is_checked_when_it_is_read() {
    let (bus, _sim) = bus();
    let one = settings::backup(&bus, id(1)).unwrap();
    let text = serde_json::to_string(&one).unwrap();
    for (bad, want) in [
        ("not json".to_owned(), "not a settings file"),
        (
            text.replace("robobus-whj-settings", "something-else"),
            "expected format",
        ),
        (
            text.replace("\"SEV_POSITION_P\"", "\"TAG_POSITION\""),
            "not a setting",
        ),
    ] {
        let e = Settings::parse(&bad).unwrap_err();
        assert_eq!(e.kind(), ErrorKind::BadInput, "{e}");
        assert!(e.to_string().contains(want), "{e} (wanted {want})");
    }
}

use crate::station_support;

/// Runs one catalogue request on `s`.
fn run(
    s: &robobus::station::Station,
    json: &str,
) -> Result<robobus::catalogue::Report, robobus::ops::OpError> {
    let r = robobus::catalogue::Request::parse_many(json)
        .unwrap()
        .remove(0);
    robobus::catalogue::run(s, &r, &mut robobus::ops::Control::none())
}

#[test]
fn the_catalogue_backs_up_diffs_and_restores_with_confirmation() {
    let (s, _w, j) = station_support::station("wck", "whj");
    for id in [1, 2] {
        j.bus().joint(self::id(id)).unwrap().disable().unwrap();
    }
    j.bus()
        .joint(id(1))
        .unwrap()
        .write_register("SEV_SPEED_P", 777.0)
        .unwrap();
    let backup = run(&s, r#"{"op": "whj.backup", "joint": 1}"#).unwrap();
    assert_eq!(backup.results[0]["model"], "WHJ30");
    let file = backup.summary.unwrap().to_string();
    let doc = Settings::parse(&file).unwrap();
    assert_eq!(raw(&doc, "SEV_SPEED_P"), 777);
    // Joint 2 against the file and against joint 1: SYS_ID and the gain.
    let with_file = serde_json::json!({"op": "whj.diff", "joint": 2, "settings": file}).to_string();
    for json in [
        with_file.as_str(),
        r#"{"op": "whj.diff", "joint": 2, "other": 1}"#,
    ] {
        let d = run(&s, json).unwrap();
        let regs: Vec<&str> = d
            .results
            .iter()
            .map(|r| r["register"].as_str().unwrap())
            .collect();
        assert_eq!(regs, ["SYS_ID", "SEV_SPEED_P"], "{json}");
        assert_eq!(d.summary.as_ref().unwrap()["differ"], 2);
    }
    let e = run(&s, r#"{"op": "whj.diff", "joint": 2}"#).unwrap_err();
    assert_eq!(e.kind(), ErrorKind::BadInput);
    // A restore writes flash: refused without confirmation, nothing written.
    let restore = serde_json::json!({"op": "whj.restore", "joint": 2, "settings": file});
    let e = run(&s, &restore.to_string()).unwrap_err();
    assert_eq!(e.kind(), ErrorKind::Refused, "{e}");
    assert_ne!(
        raw(&settings::backup(j.bus(), id(2)).unwrap(), "SEV_SPEED_P"),
        777
    );
    // Its dry run is the plan: the reads, and what the run then does.
    let plan = robobus::catalogue::plan(
        &robobus::catalogue::Request::parse_many(&restore.to_string()).unwrap()[0],
    )
    .unwrap();
    assert!(plan.steps.len() > 20, "{plan:?}");
    assert!(
        plan.notes.iter().any(|n| n.contains("never SYS_ID")),
        "{plan:?}"
    );
    let mut confirmed = restore.clone();
    confirmed["confirm"] = true.into();
    let r = run(&s, &confirmed.to_string()).unwrap();
    assert_eq!(r.summary.as_ref().unwrap()["written"], 1);
    assert_eq!(
        r.summary.as_ref().unwrap()["differ_after"],
        serde_json::json!(["SYS_ID"])
    );
    assert_eq!(
        raw(&settings::backup(j.bus(), id(2)).unwrap(), "SEV_SPEED_P"),
        777
    );
}

#[test]
fn the_documented_defaults_restore_what_the_vendor_documents_and_keep_the_rest() {
    let (bus, _sim) = bus();
    tune(&bus);
    let defaults = settings::defaults(&bus, id(1)).unwrap();
    assert_eq!((defaults.joint, defaults.model.as_str()), (1, "WHJ30"));
    let names: Vec<&str> = defaults
        .settings
        .iter()
        .map(|s| s.register.as_str())
        .collect();
    // Documented values only: no ID or bit rates, no factory-tuned gains or limits.
    assert!(names.contains(&"LIT_MAX_SPEED") && names.contains(&"TAG_WORK_MODE"));
    for absent in [
        "SYS_ID",
        "SYS_BPS_CANFD_DATA",
        "SEV_POSITION_P",
        "LIT_MIN_POSITION",
    ] {
        assert!(!names.contains(&absent), "{absent} in {names:?}");
    }
    assert_eq!(raw(&defaults, "LIT_MAX_SPEED"), 3000);
    // The file reads back as a settings file, and restores where the joint differs.
    let text = serde_json::to_string(&defaults).unwrap();
    let parsed = Settings::parse(&text).unwrap();
    let report = settings::restore(&bus, id(1), &parsed, true).unwrap();
    assert!(report.saved, "{report:?}");
    let after = settings::backup(&bus, id(1)).unwrap();
    assert!(
        settings::diff(&after, &defaults)
            .iter()
            .all(|d| d.b.is_none()),
        "{:?}",
        settings::diff(&after, &defaults)
    );
    assert_eq!(raw(&after, "LIT_MAX_SPEED"), 3000);
    // What the vendor tunes per joint stays as it was.
    assert_eq!(raw(&after, "SEV_POSITION_P"), 1234);
    assert_eq!(raw(&after, "LIT_MIN_POSITION"), -900_000);
}

#[test]
fn a_defaults_file_differs_only_in_the_registers_it_holds() {
    let (s, _w, j) = station_support::station("wck", "whj");
    j.bus().joint(id(1)).unwrap().disable().unwrap();
    tune(j.bus());
    let defaults = run(&s, r#"{"op": "whj.defaults", "joint": 1}"#).unwrap();
    let file = defaults.summary.unwrap().to_string();
    let held = Settings::parse(&file).unwrap().settings.len();
    let diff = serde_json::json!({"op": "whj.diff", "joint": 1, "settings": file}).to_string();
    let regs = |r: &robobus::catalogue::Report| -> Vec<String> {
        r.results
            .iter()
            .map(|x| x["register"].as_str().unwrap().to_owned())
            .collect()
    };
    // Tuned: the one documented value changed; the gains, limits and ID the file leaves
    // out are counted, not listed.
    let before = run(&s, &diff).unwrap();
    assert_eq!(regs(&before), ["LIT_MAX_SPEED"]);
    let summary = before.summary.as_ref().unwrap();
    assert_eq!(summary["differ"], 1);
    let all = settings::backup(j.bus(), id(1)).unwrap().settings.len();
    assert_eq!(summary["left_out"], all - held);
    assert!(all > held, "{all} {held}");
    // Restored: no difference at all.
    let restore =
        serde_json::json!({"op": "whj.restore", "joint": 1, "settings": file, "confirm": true});
    run(&s, &restore.to_string()).unwrap();
    let after = run(&s, &diff).unwrap();
    assert_eq!(regs(&after), Vec::<String>::new());
    assert_eq!(after.summary.as_ref().unwrap()["differ"], 0);
    assert_eq!(after.failed_kind(), None, "{after:?}");
}
