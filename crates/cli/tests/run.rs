//! `robobus run`: a JSON request is planned as the subcommand with the same arguments
//! plans it (the same `--dry-run` lines, for every subcommand), and run against the wCK
//! simulator it reports what the subcommand reports. Requests that are bad input or lack
//! a confirmation are refused with their exit code before anything is sent.

#![allow(clippy::unwrap_used, clippy::panic)]

use crate::common;

use common::{WckSim, robobus};
use serde_json::Value;

/// Each subcommand's arguments and the request with the same arguments.
const PAIRS: &[(&str, &str)] = &[
    (
        "robot calibrate --robot robot.toml --seconds 2 --rate-hz 10 --zero keep",
        r#"{"op":"robot.calibrate","seconds":2,"rate_hz":10,"zero":"keep"}"#,
    ),
    (
        "robot teach --robot robot.toml --seconds 2 --joints s0,j1 --hold-ma 50 -o taught.csv",
        r#"{"op":"robot.teach","seconds":2,"joints":["s0","j1"],"hold_ma":50}"#,
    ),
    (
        "robot teleop --robot robot.toml --map s0:s1 --map s0:s2:-1:10 --limit s2:-20:20 --seconds 2 --rate-hz 10 --no-passive",
        r#"{"op":"robot.teleop","map":[{"leader":"s0","follower":"s1"},{"leader":"s0","follower":"s2","scale":-1,"offset_deg":10,"limits_deg":[-20,20]}],"seconds":2,"rate_hz":10,"passive_leader":false}"#,
    ),
    ("wck scan", r#"{"op":"wck.scan"}"#),
    ("wck scan --ids 0-3", r#"{"op":"wck.scan","ids":"0-3"}"#),
    ("wck status 0-2", r#"{"op":"wck.status","ids":"0-2"}"#),
    (
        "wck move 3 127 --torque 2",
        r#"{"op":"wck.move","id":3,"position":127,"torque":2}"#,
    ),
    (
        "wck move10 3 500",
        r#"{"op":"wck.move10","id":3,"position":500}"#,
    ),
    ("wck read10 3", r#"{"op":"wck.read10","id":3}"#),
    (
        "wck sync-move 10 20 30",
        r#"{"op":"wck.sync-move","positions":[10,20,30]}"#,
    ),
    ("wck passive 0-1", r#"{"op":"wck.passive","ids":"0-1"}"#),
    (
        "wck wheel 2 cw 5",
        r#"{"op":"wck.wheel","id":2,"direction":"cw","speed":5}"#,
    ),
    ("wck brake", r#"{"op":"wck.brake"}"#),
    (
        "wck get gains 3",
        r#"{"op":"wck.get","param":"gains","id":3}"#,
    ),
    (
        "wck get bounds 3",
        r#"{"op":"wck.get","param":"bounds","id":3}"#,
    ),
    (
        "wck set gains 3 10 5 --yes",
        r#"{"op":"wck.set","param":"gains","id":3,"p":10,"d":5,"confirm":true}"#,
    ),
    (
        "wck set-id 3 5 --yes",
        r#"{"op":"wck.set-id","id":3,"new_id":5,"confirm":true}"#,
    ),
    (
        "wck set-baud 3 57600 --yes",
        r#"{"op":"wck.set-baud","id":3,"rate":57600,"confirm":true}"#,
    ),
    (
        "whj scan --joints 1-3",
        r#"{"op":"whj.scan","joints":"1-3"}"#,
    ),
    ("whj info 1", r#"{"op":"whj.info","joint":1}"#),
    (
        "whj set-rates 1-2 --bitrate 500000 --dbitrate 2000000 --yes",
        r#"{"op":"whj.set-rates","joints":"1-2","bitrate":500000,"dbitrate":2000000,"confirm":true}"#,
    ),
    (
        "whj end-board power --volts 24 --yes",
        r#"{"op":"whj.end-board","action":"power","volts":24,"confirm":true}"#,
    ),
    (
        "whj end-board io --channel 2 --mode output --yes",
        r#"{"op":"whj.end-board","action":"io","channel":2,"mode":"output","confirm":true}"#,
    ),
    (
        "whj defaults 2 -o defaults.json",
        r#"{"op":"whj.defaults","joint":2}"#,
    ),
    ("whj status 1-3", r#"{"op":"whj.status","joints":"1-3"}"#),
    (
        "whj status --broadcast 1-3",
        r#"{"op":"whj.status","joints":"1-3","broadcast":true}"#,
    ),
    ("whj enable 1,2", r#"{"op":"whj.enable","joints":"1,2"}"#),
    ("whj disable 1", r#"{"op":"whj.disable","joints":"1"}"#),
    (
        "whj mode 1 speed",
        r#"{"op":"whj.mode","joints":"1","mode":"speed"}"#,
    ),
    (
        "whj move 1 30 --max-speed 20",
        r#"{"op":"whj.move","joint":1,"degrees":30,"max_speed":20}"#,
    ),
    (
        "whj move 1 30 --from 10",
        r#"{"op":"whj.move","joint":1,"degrees":30,"from":10}"#,
    ),
    (
        "whj speed 1 5 --duration 0.1",
        r#"{"op":"whj.speed","joint":1,"rpm":5,"duration":0.1}"#,
    ),
    (
        "whj current 1 500 --model whj30",
        r#"{"op":"whj.current","joint":1,"milliamps":500,"model":"whj30"}"#,
    ),
    ("whj zero 1", r#"{"op":"whj.zero","joint":1}"#),
    ("whj clear 1", r#"{"op":"whj.clear","joints":"1"}"#),
    (
        "whj save 1 --yes",
        r#"{"op":"whj.save","joints":"1","confirm":true}"#,
    ),
    (
        "whj read 1 SYS_ID",
        r#"{"op":"whj.read","joints":"1","register":"SYS_ID"}"#,
    ),
    (
        "whj write 1 SYS_ID 2 --yes",
        r#"{"op":"whj.write","joints":"1","register":"SYS_ID","value":2,"confirm":true}"#,
    ),
    (
        "whj set-id 1 2 --yes",
        r#"{"op":"whj.set-id","joint":1,"new_id":2,"confirm":true}"#,
    ),
    (
        "whj wave 1 --amplitude 5 --duration 0.1",
        r#"{"op":"whj.wave","joint":1,"amplitude":5,"duration":0.1}"#,
    ),
    (
        "whj release-iap 1",
        r#"{"op":"whj.release-iap","joints":"1"}"#,
    ),
    (
        "wck get i-gain 3",
        r#"{"op":"wck.get","param":"i-gain","id":3}"#,
    ),
    (
        "wck get speed 3",
        r#"{"op":"wck.get","param":"speed","id":3}"#,
    ),
    (
        "wck get overload 3",
        r#"{"op":"wck.get","param":"overload","id":3}"#,
    ),
    ("wck get io 3", r#"{"op":"wck.get","param":"io","id":3}"#),
    (
        "wck set i-gain 3 4 --runtime",
        r#"{"op":"wck.set","param":"i-gain","id":3,"i":4,"runtime":true}"#,
    ),
    (
        "wck set speed 3 20 30 --yes",
        r#"{"op":"wck.set","param":"speed","id":3,"speed":20,"accel":30,"confirm":true}"#,
    ),
    (
        "wck set overload 3 800 --yes",
        r#"{"op":"wck.set","param":"overload","id":3,"milliamps":800,"confirm":true}"#,
    ),
    (
        "wck set bounds 3 10 240 --yes",
        r#"{"op":"wck.set","param":"bounds","id":3,"lower":10,"upper":240,"confirm":true}"#,
    ),
    (
        "wck set io 3 2",
        r#"{"op":"wck.set","param":"io","id":3,"outputs":2}"#,
    ),
    (
        "wck program download 0",
        r#"{"op":"wck.program.download","id":0}"#,
    ),
    (
        "wck teach 0-2 --rate-hz 10 --duration 0.3",
        r#"{"op":"wck.teach","ids":"0-2","rate_hz":10,"duration":0.3}"#,
    ),
    (
        "whj status --broadcast --end-board 1-3",
        r#"{"op":"whj.status","joints":"1-3","broadcast":true,"end_board":true}"#,
    ),
    (
        "whj read --broadcast 1-3 SYS_ID",
        r#"{"op":"whj.read","joints":"1-3","register":"SYS_ID","broadcast":true}"#,
    ),
    (
        "whj write --broadcast 1-3 SYS_ID 2 --yes",
        r#"{"op":"whj.write","joints":"1-3","register":"SYS_ID","value":2,"broadcast":true,"confirm":true}"#,
    ),
    (
        "whj wave --broadcast 1 --amplitude 5 --duration 0.05",
        r#"{"op":"whj.wave","joint":1,"amplitude":5,"duration":0.05,"broadcast":true}"#,
    ),
];

/// The subcommands that read a file, and the requests that carry its text.
const PROGRAM: &str = "move 82 torque 0\ndelay 266ms\nmove 172 torque 0\ndelay 266ms\n";
const MOTION: &str = "torque 1\npose 500 100 200\npose 100 120 180\nhold 40\npose 0 0 0\n";
const FILE_PAIRS: &[(&str, &str)] = &[
    (
        "wck program upload 0 PROGRAM --yes",
        r#"{"op":"wck.program.upload","id":0,"program":PROGRAM,"confirm":true}"#,
    ),
    (
        "wck program check PROGRAM",
        r#"{"op":"wck.program.check","program":PROGRAM}"#,
    ),
    ("wck play MOTION", r#"{"op":"wck.play","motion":MOTION}"#),
    (
        "wck play MOTION --rate-hz 25",
        r#"{"op":"wck.play","motion":MOTION,"rate_hz":25}"#,
    ),
];

fn request_file(dir: &tempfile::TempDir, json: &str) -> String {
    let path = dir.path().join("request.json");
    std::fs::write(&path, json).unwrap();
    path.to_str().unwrap().to_owned()
}

#[test]
fn every_request_plans_what_its_subcommand_dry_run_prints() {
    let dir = tempfile::tempdir().unwrap();
    for (args, json) in PAIRS {
        let mut words: Vec<&str> = args.split(' ').collect();
        words.insert(1, "--dry-run");
        let cli = robobus(&words);
        assert_eq!(cli.code, Some(0), "{args}: {}", cli.stderr);
        assert!(!cli.stdout.is_empty(), "{args}");
        let file = request_file(&dir, json);
        let run = robobus(&["run", "--dry-run", &file]);
        assert_eq!(run.code, Some(0), "{json}: {}", run.stderr);
        assert_eq!(run.stdout, cli.stdout, "{args} against {json}");
    }
}

#[test]
fn requests_carrying_a_file_plan_what_the_subcommand_reading_it_prints() {
    let dir = tempfile::tempdir().unwrap();
    let program = dir.path().join("swing.wck");
    let motion = dir.path().join("wave.motion");
    std::fs::write(&program, PROGRAM).unwrap();
    std::fs::write(&motion, MOTION).unwrap();
    let text = |s: &str| serde_json::to_string(s).unwrap();
    for (args, json) in FILE_PAIRS {
        let args = args
            .replace("PROGRAM", program.to_str().unwrap())
            .replace("MOTION", motion.to_str().unwrap());
        let json = json
            .replace("PROGRAM", &text(PROGRAM))
            .replace("MOTION", &text(MOTION));
        let mut words: Vec<&str> = args.split(' ').collect();
        // `program check` needs no port and has no dry run: it prints its plan.
        if !args.contains(" check ") {
            words.insert(1, "--dry-run");
        }
        let cli = robobus(&words);
        assert_eq!(cli.code, Some(0), "{args}: {}", cli.stderr);
        let file = request_file(&dir, &json);
        let run = robobus(&["run", "--dry-run", &file]);
        assert_eq!(run.code, Some(0), "{json}: {}", run.stderr);
        assert!(run.stdout.contains("FF "), "{json}: {}", run.stdout);
        if args.contains(" check ") {
            // The check's output is the plan's packet plus its listing.
            let packet = run.stdout.lines().find(|l| l.starts_with("FF ")).unwrap();
            assert!(cli.stdout.lines().any(|l| l == packet), "{}", cli.stdout);
        } else {
            assert_eq!(run.stdout, cli.stdout, "{args} against {json}");
        }
    }
}

#[test]
fn requests_refused_before_anything_is_sent_exit_as_the_subcommand_does() {
    let dir = tempfile::tempdir().unwrap();
    for (json, code, says) in [
        (r#"{"op":"wck.move","id":3,"position":255}"#, 2, "254"),
        (r#"{"op":"whj.move","joint":1,"degrees":400}"#, 2, "360"),
        (
            r#"{"op":"wck.status","ids":"0","colour":"red"}"#,
            2,
            "colour",
        ),
        (r#"{"op":"wck.set-id","id":3,"new_id":5}"#, 2, "confirm"),
        (r#"{"op":"whj.save","joints":"1"}"#, 2, "confirm"),
        // In a list, a bad request anywhere sends nothing: the first is not run either.
        (
            r#"[{"op":"wck.brake"},{"op":"whj.move","joint":1,"degrees":400}]"#,
            2,
            "request 2",
        ),
    ] {
        let file = request_file(&dir, json);
        // On the built-in simulated robot: refused before it is touched.
        let r = robobus(&["run", &file]);
        assert_eq!(r.code, Some(code), "{json}: {r:?}");
        assert!(r.stderr.contains(says), "{json}: {}", r.stderr);
        assert!(r.stdout.is_empty(), "{json}: {}", r.stdout);
    }
}

/// The rows without the failure message (its timing differs from run to run).
fn rows(doc: &Value) -> Vec<Value> {
    doc["results"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| {
            let mut r = r.clone();
            r.as_object_mut().unwrap().remove("error");
            r
        })
        .collect()
}

#[test]
fn run_reports_what_the_subcommand_reports_on_the_wck_simulator() {
    let sim = WckSim::start("0-2", &[]);
    let dir = tempfile::tempdir().unwrap();
    for (args, json, code) in [
        ("status 0-3", r#"{"op":"wck.status","ids":"0-3"}"#, 3),
        (
            "get gains 1",
            r#"{"op":"wck.get","param":"gains","id":1}"#,
            0,
        ),
        ("read10 2", r#"{"op":"wck.read10","id":2}"#, 0),
        // To where it stands: a move that changes nothing reports the same twice.
        (
            "move 1 127 --torque 1",
            r#"{"op":"wck.move","id":1,"position":127,"torque":1}"#,
            0,
        ),
        ("passive 0-2", r#"{"op":"wck.passive","ids":"0-2"}"#, 0),
    ] {
        let mut words = vec!["wck", "--port", sim.port(), "--json"];
        words.extend(args.split(' '));
        let cli = robobus(&words);
        assert_eq!(cli.code, Some(code), "{args}: {}", cli.stderr);
        let file = request_file(&dir, json);
        let run = robobus(&["run", "--wck-port", sim.port(), &file]);
        assert_eq!(run.code, Some(code), "{json}: {}", run.stderr);
        let (cli, run): (Value, Value) = (
            serde_json::from_str(&cli.stdout).unwrap(),
            serde_json::from_str(&run.stdout).unwrap(),
        );
        assert_eq!(run["bus"], sim.port());
        assert_eq!(rows(&run), rows(&cli), "{args} against {json}");
    }
}

#[test]
fn a_current_target_runs_without_a_model_which_only_its_plan_needs() {
    // A plan converts mA to counts with the model it is given; a run reads the joint's.
    let dir = tempfile::tempdir().unwrap();
    let file = request_file(
        &dir,
        r#"[{"op":"whj.mode","joints":"1","mode":"current"},
            {"op":"whj.current","joint":1,"milliamps":100,"duration":0.05}]"#,
    );
    let r = robobus(&["run", &file]);
    assert_eq!(r.code, Some(0), "{r:?}");
    let reports: Value = serde_json::from_str(&r.stdout).unwrap();
    assert_eq!(reports.as_array().unwrap().len(), 2, "{reports}");
    assert_eq!(reports[1]["op"], "whj.current");
    let plan = robobus(&["run", "--dry-run", &file]);
    assert_eq!(plan.code, Some(2), "{plan:?}");
    assert!(plan.stderr.contains("model"), "{}", plan.stderr);
}
