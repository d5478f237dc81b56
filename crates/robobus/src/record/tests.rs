use std::io::Cursor;

use super::*;

fn row(name: &str, effort: Effort) -> SampleRow {
    SampleRow::new(name, name.into(), effort)
}

#[test]
fn csv_rows_match_the_header_and_gaps_stay_empty() {
    let mut t = SampleTable::wck(&[0, 1]);
    t.rows[0].position_deg = Some(1.0);
    t.rows[0].speed = Some(2.0);
    t.rows[0].effort = Some(3.0);
    t.rows[0].got();
    t.t_s = 0.5;
    assert_eq!(
        t.csv_header(),
        "t_s,s0_deg,s0_deg_per_s,s0_load,s1_deg,s1_deg_per_s,s1_load"
    );
    assert_eq!(t.csv_row(), "0.5000,1.0000,2.0000,3.0000,,,");
}

#[test]
fn robot_joint_names_become_csv_columns_and_json_keys_carry_units() {
    let mut t = SampleTable::robot([("Left Knee", true), ("shoulder-1", false)]);
    let knee = &mut t.rows[0];
    knee.position_deg = Some(-12.5);
    knee.effort = Some(40.0);
    "ok".clone_into(&mut knee.error);
    knee.got();
    let sh = &mut t.rows[1];
    sh.position_deg = Some(3.25);
    sh.speed = Some(-6.0);
    sh.effort = Some(812.0);
    sh.enabled = Some(true);
    "no error".clone_into(&mut sh.error);
    sh.failures = 2;
    sh.got();
    t.t_s = 1.23456;
    t.samples = 7;
    assert_eq!(
        t.csv_header(),
        "t_s,left_knee_deg,left_knee_deg_per_s,left_knee_load,\
         shoulder_1_deg,shoulder_1_deg_per_s,shoulder_1_mA"
    );
    let v: serde_json::Value = serde_json::from_str(&t.json_line()).unwrap();
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
fn a_silent_device_is_stale_in_every_output_and_named_by_silent() {
    let mut t = SampleTable::whj(&[2]);
    assert_eq!(t.speed_unit.as_str(), "RPM");
    // One good sample, then the joint goes away.
    let j = &mut t.rows[0];
    j.position_deg = Some(12.0);
    j.speed = Some(1.0);
    j.effort = Some(300.0);
    j.enabled = Some(true);
    j.got();
    t.take_cycle(None, 1.0);
    t.rows[0].missed("timeout");
    t.t_s = 2.0;
    t.samples = 2;
    // CSV: empty cells, never the last good value.
    assert_eq!(t.csv_row(), "2.0000,,,");
    // JSON: null values, marked stale, the error kept.
    let v: serde_json::Value = serde_json::from_str(&t.json_line()).unwrap();
    let j = &v["channels"][0];
    assert!(
        j["position_deg"].is_null()
            && j["speed_rpm"].is_null()
            && j["current_ma"].is_null()
            && j["enabled"].is_null(),
        "{j}"
    );
    assert_eq!(j["stale"], true);
    assert_eq!(j["error"], "timeout");
    // The row keeps its values for a front end that shows them dimmed.
    assert_eq!(t.rows[0].position_deg, Some(12.0));
    assert_eq!(t.silent(), ["j2 (1 of 2 samples missing)"]);
    // A device that answered every sample is not silent; before any sample nobody is.
    t.rows[0].got();
    assert!(t.silent().is_empty());
    assert!(SampleTable::whj(&[1]).silent().is_empty());
}

#[test]
fn a_device_that_never_answered_is_silent() {
    let mut t = SampleTable::wck(&[3]);
    t.take_cycle(None, 0.1);
    assert_eq!(t.samples, 1);
    assert_eq!(t.silent(), ["s3 (0 of 1 samples missing)"]);
}

#[test]
fn recordings_write_the_head_then_a_line_per_sample_in_either_format() {
    let mut t = SampleTable::wck(&[0]);
    t.rows[0].position_deg = Some(10.0);
    t.rows[0].got();
    t.t_s = 0.25;
    t.samples = 1;
    let mut csv = Recorder::new(
        Cursor::new(Vec::new()),
        RecordFormat::Csv,
        "wCK port sim",
        &t,
    )
    .unwrap();
    csv.record(&t).unwrap();
    assert_eq!(csv.written(), 1);
    let text = String::from_utf8(csv.finish().unwrap().into_inner()).unwrap();
    assert_eq!(
        text,
        "# robobus monitor: wCK port sim\nt_s,s0_deg,s0_deg_per_s,s0_load\n0.2500,10.0000,,\n"
    );
    let mut jl = Recorder::new(Cursor::new(Vec::new()), RecordFormat::JsonLines, "x", &t).unwrap();
    jl.record(&t).unwrap();
    t.rows[0].missed("no reply");
    t.samples = 2;
    jl.record(&t).unwrap();
    let text = String::from_utf8(jl.finish().unwrap().into_inner()).unwrap();
    let lines: Vec<serde_json::Value> = text
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(lines.len(), 2);
    assert_eq!(lines[0]["channels"][0]["position_deg"], 10.0);
    assert!(lines[1]["channels"][0]["position_deg"].is_null());
    assert_eq!(lines[1]["channels"][0]["stale"], true);
}

#[test]
fn a_recordings_format_comes_from_its_name() {
    assert_eq!(
        RecordFormat::of_path(Path::new("a/run.csv")),
        Some(RecordFormat::Csv)
    );
    assert_eq!(
        RecordFormat::of_path(Path::new("run.jsonl")),
        Some(RecordFormat::JsonLines)
    );
    assert_eq!(
        RecordFormat::of_path(Path::new("run.ndjson")),
        Some(RecordFormat::JsonLines)
    );
    assert_eq!(RecordFormat::of_path(Path::new("run.txt")), None);
    let dir = std::env::temp_dir().join(format!("robobus-record-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let t = SampleTable::whj(&[1]);
    let e = Recorder::create(&dir.join("run.txt"), "x", &t).unwrap_err();
    assert_eq!(e.kind(), ErrorKind::BadInput);
    assert!(e.to_string().contains("run.txt") && e.to_string().contains(".jsonl"));
    assert!(!dir.join("run.txt").exists(), "nothing created");
    let e = Recorder::create(&dir.join("no/such/run.csv"), "x", &t).unwrap_err();
    assert_eq!(e.kind(), ErrorKind::Link);
    let path = dir.join("run.csv");
    let r = Recorder::create(&path, "WHJ bus udp", &t).unwrap();
    r.finish().unwrap();
    assert_eq!(
        std::fs::read_to_string(&path).unwrap(),
        "# robobus monitor: WHJ bus udp\nt_s,j1_deg,j1_rpm,j1_mA\n"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn rows_start_empty_and_stale() {
    let r = row("j1", Effort::Milliamps);
    assert!(!r.fresh && r.answered == 0 && r.failures == 0);
    assert_eq!(r.now(Some(1.0)), None);
    assert_eq!(r.error, "-");
}

#[test]
fn an_mcap_recording_holds_every_sample_and_the_joint_states_of_those_that_answered() {
    let mut t = SampleTable::whj(&[1, 2]);
    let mut rec = Recorder::new(
        Cursor::new(Vec::new()),
        RecordFormat::Mcap,
        "WHJ bus udp",
        &t,
    )
    .unwrap();
    // Sample 1: both answer; sample 2: J2 is silent; sample 3: neither answers.
    for (k, answered) in [[true, true], [true, false], [false, false]]
        .iter()
        .enumerate()
    {
        for (row, &ok) in t.rows.iter_mut().zip(answered) {
            if ok {
                row.position_deg = Some(90.0);
                row.speed = Some(60.0);
                row.effort = Some(120.0);
                row.got();
            } else {
                row.missed("timeout");
            }
        }
        t.t_s = 0.5 * f64::from(u8::try_from(k).unwrap());
        t.samples += 1;
        rec.record(&t).unwrap();
    }
    let bytes = rec.finish().unwrap().into_inner();
    let mut samples = Vec::new();
    let mut states = Vec::new();
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        let schema = m.channel.schema.as_ref().unwrap();
        match m.channel.topic.as_str() {
            SAMPLES_TOPIC => {
                assert_eq!(
                    (
                        m.channel.message_encoding.as_str(),
                        schema.encoding.as_str()
                    ),
                    ("json", "jsonschema")
                );
                let v: serde_json::Value = serde_json::from_slice(&m.data).unwrap();
                samples.push((m.log_time, v));
            }
            JOINT_STATES_TOPIC => {
                assert_eq!(m.channel.message_encoding, "cdr");
                assert_eq!(
                    (schema.name.as_str(), schema.encoding.as_str()),
                    ("sensor_msgs/msg/JointState", "ros2msg")
                );
                let s = crate::cdr::JointState::decode(&m.data).unwrap();
                states.push((m.log_time, s));
            }
            other => panic!("unexpected topic {other}"),
        }
    }
    // Every sample; a joint state only for the samples a device answered.
    assert_eq!(samples.len(), 3);
    assert_eq!(states.len(), 2);
    // One time base: the sample's time on both channels, 0.5 s apart.
    assert_eq!(states[0].0, samples[0].0);
    assert_eq!(states[1].0, samples[1].0);
    assert_eq!(samples[1].0 - samples[0].0, 500_000_000);
    let stamp = &states[1].1.stamp;
    assert_eq!(
        u64::try_from(stamp.sec).unwrap() * 1_000_000_000 + u64::from(stamp.nanosec),
        states[1].0
    );
    let (first, second) = (&states[0].1, &states[1].1);
    assert_eq!(first.name, ["j1", "j2"]);
    assert!((first.position[0] - core::f64::consts::FRAC_PI_2).abs() < 1e-12);
    // 60 RPM is 2π rad/s; without a torque constant the effort (a current, not a torque)
    // is unknown.
    assert!((first.velocity[0] - core::f64::consts::TAU).abs() < 1e-12);
    assert!(first.effort.iter().all(|e| e.is_nan()));
    // The silent joint is left out, never given its last value.
    assert_eq!(second.name, ["j1"]);
    assert_eq!(samples[1].1["channels"][1]["stale"], true);
    assert!(samples[1].1["channels"][1]["position_deg"].is_null());
    assert_eq!(samples[2].1["sample"], 3);
    // The summary counts them, and the metadata names the source.
    let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
    assert_eq!(summary.stats.as_ref().unwrap().message_count, 5);
    let meta = mcap::read::metadata(&bytes, &summary.metadata_indexes[0]).unwrap();
    assert_eq!(meta.name, "robobus");
    assert_eq!(meta.metadata["source"], "WHJ bus udp");
    assert_eq!(meta.metadata["speed_unit"], "RPM");
    // Read back as the CSV form's columns, stale values missing.
    let cols = read_columns(&bytes).unwrap();
    assert_eq!(cols.time, [0.0, 0.5, 1.0]);
    let names: Vec<&str> = cols.signals.iter().map(|(n, _)| n.as_str()).collect();
    let header = t.csv_header();
    assert_eq!(names, header.split(',').skip(1).collect::<Vec<_>>());
    assert_eq!(cols.signals[0].1, [Some(90.0), Some(90.0), None]);
    assert_eq!(cols.signals[3].1, [Some(90.0), None, None]);
    assert!(
        read_columns(b"not an mcap file")
            .unwrap_err()
            .contains("not MCAP")
    );
}

#[test]
fn devices_by_id_are_named_as_the_built_in_robot_names_them() {
    let whj = SampleTable::whj(&[1, 7]);
    let wck = SampleTable::wck(&[0, 15]);
    let names: Vec<&str> = whj
        .rows
        .iter()
        .chain(&wck.rows)
        .map(|r| r.name.as_str())
        .collect();
    assert_eq!(names, ["j1", "j7", "s0", "s15"]);
    // The CSV columns are the names, as before.
    assert_eq!(
        whj.csv_header(),
        "t_s,j1_deg,j1_rpm,j1_mA,j7_deg,j7_rpm,j7_mA"
    );
}

/// The joint states of an MCAP recording of `t`'s latest sample.
fn recorded_states(t: &SampleTable) -> Vec<crate::cdr::JointState> {
    let mut rec = Recorder::new(Cursor::new(Vec::new()), RecordFormat::Mcap, "x", t).unwrap();
    rec.record(t).unwrap();
    let bytes = rec.finish().unwrap().into_inner();
    mcap::MessageStream::new(&bytes)
        .unwrap()
        .map(Result::unwrap)
        .filter(|m| m.channel.topic == JOINT_STATES_TOPIC)
        .map(|m| crate::cdr::JointState::decode(&m.data).unwrap())
        .collect()
}

#[test]
#[allow(clippy::float_cmp)] // exact: the value written is the value read back
fn an_mcap_joint_states_effort_is_the_torque_estimated_from_the_current() {
    // Joint 1 with a torque constant of 2.5 N·m/A, joint 2 without one (model unknown).
    let mut t = SampleTable::whj(&[1, 2]).with_torque_constants(&[Some(2.5)]);
    assert_eq!((t.rows[0].nm_per_a, t.rows[1].nm_per_a), (Some(2.5), None));
    let feedback = |ma| {
        Some(crate::whj::Feedback {
            position: robobus_whj::units::Position::from_degrees(10.0).unwrap(),
            speed: robobus_whj::units::ActualSpeed::from_rpm(0.0).unwrap(),
            current: robobus_whj::units::Current::from_milliamps(ma, CurrentScale::OneMilliamp)
                .unwrap(),
            enabled: true,
            error: robobus_whj::ErrorCode::default(),
        })
    };
    let report = CycleReport {
        cycle: 0,
        scheduled: std::time::Instant::now(),
        start_lateness: std::time::Duration::ZERO,
        round_trip: None,
        commanded: vec![0, 0],
        feedback: vec![feedback(-400.0), feedback(300.0)],
        missed: false,
    };
    t.take_cycle(Some(&report), 0.1);
    // -400 mA at 2.5 N·m/A: -1 N·m, the bridge's estimate (sampler::effort_nm).
    assert_eq!(t.rows[0].effort_nm, Some(-1.0));
    assert_eq!(
        t.rows[0].effort_nm,
        Some(crate::station::sampler::effort_nm(-400, 2.5, false))
    );
    assert_eq!(t.rows[1].effort_nm, None);
    let states = recorded_states(&t);
    assert_eq!(states.len(), 1);
    assert_eq!(states[0].name, ["j1", "j2"]);
    assert_eq!(states[0].effort[0], -1.0);
    assert!(states[0].effort[1].is_nan(), "{:?}", states[0].effort);
}

#[test]
#[allow(clippy::float_cmp)] // exact: the value written is the value read back
fn a_robot_samples_effort_nm_is_the_recorded_effort() {
    // As the bridge publishes it: a robot sample's `effort_nm`, whatever its current.
    let mut t = SampleTable::robot([("elbow", false), ("s0", true)]);
    t.rows[0].position_deg = Some(1.0);
    t.rows[0].effort_nm = Some(0.75);
    t.rows[0].got();
    t.rows[1].position_deg = Some(2.0);
    t.rows[1].got();
    let states = recorded_states(&t);
    assert_eq!(states[0].name, ["elbow", "s0"]);
    assert_eq!(states[0].effort[0], 0.75);
    assert!(states[0].effort[1].is_nan());
}
