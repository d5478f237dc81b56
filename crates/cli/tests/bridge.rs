//! `robobus bridge` as a process: its dry run (the keys, no socket), bad options (exit 2,
//! nothing opened), a start and a clean stop, the built-in simulators through a robot file
//! of one's own (`--simulated --robot`; a file not of the simulators refused with exit 2),
//! and a second bridge on a namespace in use (exit 4, the first serving on). Its peers (Python Zenoh, two network
//! namespaces, ROS 2) are tested by `scripts/bridge/test-peers`.

#![allow(clippy::unwrap_used, clippy::panic)] // test helpers: a failed unwrap is a failed test

use std::process::Command;
#[cfg(unix)]
use {
    std::io::{BufRead as _, BufReader},
    std::process::Stdio,
};

fn robobus(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_robobus"))
        .args(args)
        .output()
        .unwrap()
}

#[test]
fn a_dry_run_prints_the_keys_and_opens_no_socket() {
    // The port is taken: a real run could not listen there; the dry run never tries.
    let taken = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let endpoint = format!("tcp/{}", taken.local_addr().unwrap());
    let out = robobus(&[
        "--dry-run",
        "bridge",
        "--namespace",
        "/site/arm1",
        "--listen",
        &endpoint,
        "--rate",
        "100",
    ]);
    assert!(out.status.success(), "{out:?}");
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(
        text.starts_with(&format!(
            "bridge: would serve, opening no socket: listening on {endpoint}; the built-in \
             simulated robot; 23 joints (s0 s1"
        )),
        "{text}"
    );
    let rows: Vec<Vec<&str>> = text
        .lines()
        .skip(1)
        .map(|l| l.split_whitespace().collect())
        .collect();
    let keys: Vec<&str> = rows.iter().map(|r| r[0]).collect();
    assert_eq!(
        keys,
        [
            "site/arm1/joint_states",
            "site/arm1/joint_commands",
            "site/arm1/diagnostics",
            "site/arm1/robobus/run",
            "site/arm1/robobus/plan",
            "site/arm1/robobus/arm",
            "site/arm1/robobus/health",
            "site/arm1/robobus/bridge",
            "site/arm1/joint_trajectory",
            "site/arm1/controller_state",
            "site/arm1/joint_trajectory/result",
            "site/arm1/joint_commands/velocity",
            "site/arm1/joint_commands/effort",
            "site/arm1/robobus/interface",
            "site/arm1/robobus/sim",
        ]
    );
    assert_eq!(rows[0][1..], ["sensor_msgs/msg/JointState,", "100", "Hz"]);
    assert_eq!(rows[1][1..], ["std_msgs/msg/Float64MultiArray,", "rad"]);
    let real = robobus(&["bridge", "--listen", &endpoint]);
    assert_eq!(real.status.code(), Some(1), "{real:?}");
    assert!(String::from_utf8_lossy(&real.stderr).contains("Address already in use"));
    drop(taken);
}

#[test]
fn a_client_dry_run_names_its_routers() {
    let out = robobus(&[
        "--dry-run",
        "bridge",
        "--mode",
        "client",
        "--connect",
        "tcp/10.0.0.1:7447",
        "--connect",
        "tcp/10.0.0.2:7447",
    ]);
    assert!(out.status.success(), "{out:?}");
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(
        text.starts_with(
            "bridge: would serve, opening no socket: a client of tcp/10.0.0.1:7447, \
             tcp/10.0.0.2:7447; the built-in simulated robot; 23 joints"
        ),
        "{text}"
    );
}

#[test]
fn a_read_only_bridge_says_so_and_cannot_be_armed() {
    let out = robobus(&["--dry-run", "bridge", "--read-only"]);
    assert!(out.status.success(), "{out:?}");
    let text = String::from_utf8(out.stdout).unwrap();
    let first = text.lines().next().unwrap_or_default();
    assert!(first.ends_with("23 joints (s0 s1 s2 s3 s4 s5 s6 s7 s8 s9 s10 s11 s12 s13 s14 s15 j1 j2 j3 j4 j5 j6 j7); read-only"), "{first}");
}

#[test]
fn bad_options_exit_2_naming_the_option_and_open_nothing() {
    for (args, option) in [
        (&["bridge", "--read-only", "--armed"][..], "--armed"),
        (&["bridge", "--namespace", "a/*"][..], "--namespace"),
        (&["bridge", "--rate", "5000"][..], "--rate"),
        (&["bridge", "--connect", "127.0.0.1:7447"][..], "--connect"),
        (
            &["bridge", "--command-timeout", "5"][..],
            "--command-timeout",
        ),
        (
            &["bridge", "--zenoh-config", "/nonexistent/z.json5"][..],
            "--zenoh-config",
        ),
        (
            &["--dry-run", "bridge", "--namespace", "x y"][..],
            "--namespace",
        ),
        (&["bridge", "--mode", "client"][..], "--connect"),
        (
            &["--dry-run", "bridge", "--mode", "client"][..],
            "--connect",
        ),
        (
            &[
                "bridge",
                "--mode",
                "client",
                "--connect",
                "tcp/127.0.0.1:9",
                "--listen",
                "tcp/127.0.0.1:0",
            ][..],
            "--listen",
        ),
        (
            &["--dry-run", "bridge", "--connect", "10.0.0.1:7447"][..],
            "--connect",
        ),
        (&["bridge", "--mode", "router"][..], "--mode"),
    ] {
        let out = robobus(args);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
        assert!(err.contains(option), "{args:?}: {err}");
    }
}

/// The robot file of the built-in simulators with a wheel and WHJ joints on velocity and
/// effort (crates/robobus/examples).
const SIM_DRIVE: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../robobus/examples/sim_drive.toml"
);

#[test]
fn simulated_with_a_robot_file_serves_the_files_joints_on_the_simulators() {
    let out = robobus(&[
        "--dry-run",
        "bridge",
        "--simulated",
        "--robot",
        SIM_DRIVE,
        "--namespace",
        "bot",
    ]);
    assert!(out.status.success(), "{out:?}");
    let text = String::from_utf8(out.stdout).unwrap();
    let first = text.lines().next().unwrap_or_default();
    assert_eq!(
        first,
        format!(
            "bridge: would serve, opening no socket: listening on tcp/127.0.0.1:7447; the \
             built-in simulated robot through {SIM_DRIVE}; 3 joints (s0 j1 j2); not armed"
        )
    );
    for key in [
        "bot/joint_commands/velocity",
        "bot/joint_commands/effort",
        "bot/robobus/interface",
        "bot/robobus/sim",
    ] {
        assert!(
            text.lines().any(|l| l.trim_start().starts_with(key)),
            "{key}: {text}"
        );
    }
}

#[cfg(unix)] // stopped with kill -INT
#[test]
fn simulated_with_a_robot_file_starts_with_its_joints_and_stops_on_ctrl_c() {
    let (mut child, line) = started(&[
        "bridge",
        "--simulated",
        "--robot",
        SIM_DRIVE,
        "--listen",
        "tcp/127.0.0.1:0",
        "--armed",
    ]);
    assert!(
        line.starts_with("bridge: zenoh ")
            && line.ends_with(&format!(
                "the built-in simulated robot through {SIM_DRIVE}; 3 joints (s0 j1 j2); ARMED\n"
            )),
        "{line}"
    );
    nix_kill(child.id());
    assert_eq!(child.wait().unwrap().code(), Some(0));
}

/// `robobus ARGS`'s output once it ends by itself; one still running after 30 s (a
/// bridge that started serving) is killed and fails the test.
fn ended(args: &[&str]) -> std::process::Output {
    ended_or(args, || ())
}

/// [`ended`], and on its failure `also` (what stops the rest of the test's processes)
/// before the test fails.
fn ended_or(args: &[&str], also: impl FnOnce()) -> std::process::Output {
    let mut child = Command::new(env!("CARGO_BIN_EXE_robobus"))
        .args(args)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(30);
    while child.try_wait().unwrap().is_none() {
        if std::time::Instant::now() > deadline {
            let _ = child.kill();
            also();
            panic!("robobus {args:?} started instead of refusing");
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    child.wait_with_output().unwrap()
}

#[test]
fn simulated_refuses_a_robot_file_not_of_the_simulators_with_exit_2_before_starting() {
    let dir = std::env::temp_dir().join(format!("robobus-bridge-sim-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let joint = |bus: &str, id: u8| {
        format!(
            "[[joints]]\nname = \"a\"\nbus = \"{bus}\"\nid = {id}\nlimits = [-1.0, 1.0]\n\
             max_velocity = 1.0\nmax_acceleration = 5.0\n"
        )
    };
    let cases = [
        (
            format!(
                "[buses.arm]\nkind = \"whj-bus\"\nbus = \"udp\"\n{}",
                joint("arm", 1)
            ),
            "bus arm (kind = \"whj-bus\") is not a bus of the built-in simulated robot; \
             expected [buses.sim-wck] with kind = \"wck-external\" or [buses.sim-whj] with \
             kind = \"whj-external\"",
        ),
        (
            format!(
                "[buses.sim-whj]\nkind = \"wck-external\"\n{}",
                joint("sim-whj", 1)
            ),
            "bus sim-whj (kind = \"wck-external\") is not a bus of the built-in simulated robot",
        ),
        (
            format!(
                "[buses.sim-wck]\nkind = \"wck-external\"\n{}",
                joint("sim-wck", 16)
            ),
            "joint a: id = 16 is not on the simulated bus sim-wck; expected 0..=15",
        ),
        (
            format!(
                "[buses.sim-whj]\nkind = \"whj-external\"\n{}",
                joint("sim-whj", 8)
            ),
            "joint a: id = 8 is not on the simulated bus sim-whj; expected 1..=7",
        ),
        ("[buses.sim-whj\n".to_owned(), "line 1"),
    ];
    let endpoint = free_endpoint();
    for (i, (text, expected)) in cases.iter().enumerate() {
        let path = dir.join(format!("robot{i}.toml"));
        std::fs::write(&path, text).unwrap();
        let path = path.to_str().unwrap();
        for dry in [false, true] {
            let mut args = vec![
                "bridge",
                "--simulated",
                "--robot",
                path,
                "--listen",
                &endpoint,
            ];
            if dry {
                args.insert(0, "--dry-run");
            }
            let out = ended(&args);
            let err = String::from_utf8_lossy(&out.stderr);
            assert_eq!(out.status.code(), Some(2), "{text}: {err}");
            assert!(
                err.contains(&format!("--robot {path} with --simulated: "))
                    && err.contains(expected),
                "{text}: {err}"
            );
            // Nothing started: no first line.
            assert!(out.stdout.is_empty(), "{text}: {out:?}");
        }
    }
    let missing = dir.join("missing.toml");
    let out = robobus(&[
        "bridge",
        "--simulated",
        "--robot",
        missing.to_str().unwrap(),
    ]);
    assert_eq!(out.status.code(), Some(2), "{out:?}");
    assert!(String::from_utf8_lossy(&out.stderr).contains("missing.toml"));
    for bus in [&["--whj-bus", "udp"][..], &["--wck-port", "/dev/null"][..]] {
        let out = robobus(&[&["bridge", "--simulated"][..], bus].concat());
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{err}");
        assert!(err.contains("'--simulated' cannot be used with"), "{err}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[cfg(unix)] // stopped with kill -INT
#[test]
fn it_starts_serves_and_stops_cleanly_on_ctrl_c() {
    let (mut child, line) = started(&["bridge", "--listen", "tcp/127.0.0.1:0", "--namespace", "t"]);
    assert!(line.starts_with("bridge: zenoh "), "{line}");
    assert!(
        line.contains("23 joints") && line.contains("not armed"),
        "{line}"
    );
    nix_kill(child.id());
    let status = child.wait().unwrap();
    // A server stopped by its operator ends normally (as `robobus studio` does).
    assert_eq!(status.code(), Some(0), "{status:?}");
}

#[cfg(unix)] // stopped with kill -INT
#[test]
fn a_second_bridge_on_a_namespace_in_use_exits_4_and_the_first_serves_on() {
    let endpoint = free_endpoint();
    let (mut first, line) = started(&["bridge", "--listen", &endpoint, "--namespace", "bot1"]);
    assert!(line.starts_with("bridge: zenoh "), "{line}");
    // It must end by itself (a bridge that started would serve until stopped).
    let second = ended_or(
        &[
            "bridge",
            "--no-listen",
            "--connect",
            &endpoint,
            "--namespace",
            "/bot1/",
        ],
        || {
            let _ = first.kill();
        },
    );
    let err = String::from_utf8_lossy(&second.stderr);
    assert_eq!(second.status.code(), Some(4), "{err}");
    assert!(
        err.contains("namespace \"bot1\" is in use: another bridge (Zenoh ID ")
            && err.contains("give this bridge another --namespace"),
        "{err}"
    );
    assert!(second.stdout.is_empty(), "{second:?}");
    assert!(
        first.try_wait().unwrap().is_none(),
        "the first bridge stopped"
    );
    nix_kill(first.id());
    assert_eq!(first.wait().unwrap().code(), Some(0));
}

/// `robobus ARGS` started (its standard error discarded), and the first line it printed
/// (a bridge's says it serves).
#[cfg(unix)]
fn started(args: &[&str]) -> (std::process::Child, String) {
    let mut child = Command::new(env!("CARGO_BIN_EXE_robobus"))
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let mut line = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    (child, line)
}

/// A TCP endpoint on the loopback whose port was free a moment ago.
fn free_endpoint() -> String {
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    format!("tcp/127.0.0.1:{port}")
}

#[cfg(unix)]
fn nix_kill(pid: u32) {
    let status = Command::new("kill")
        .args(["-INT", &pid.to_string()])
        .status()
        .unwrap();
    assert!(status.success());
}
