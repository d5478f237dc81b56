//! `robobus monitor` without a terminal: plain lines, a CSV recording `robobus plot`
//! reads, `--duration`, and bad options. (The ratatui screen itself is tested with
//! ratatui's `TestBackend` in the module's unit tests.)

#![allow(clippy::unwrap_used, clippy::panic)] // Test code.

mod common;

#[test]
fn monitor_records_the_simulated_arm_to_csv_and_stops_by_itself() {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("arm.csv");
    let started = std::time::Instant::now();
    let r = common::robobus(&[
        "monitor",
        "--sim",
        "--joints",
        "1-3",
        "--rate-hz",
        "40",
        "--duration",
        "2",
        "--record",
        csv.to_str().unwrap(),
    ]);
    assert_eq!(r.code, Some(0), "{}", r.stderr);
    assert!(started.elapsed().as_secs_f64() < 20.0);
    // One plain line per second, naming the joints.
    assert!(r.stdout.lines().count() >= 2, "{}", r.stdout);
    assert!(
        r.stdout.contains("J1") && r.stdout.contains("J3"),
        "{}",
        r.stdout
    );
    assert!(r.stderr.contains("samples recorded"), "{}", r.stderr);

    let text = std::fs::read_to_string(&csv).unwrap();
    let mut lines = text.lines().filter(|l| !l.starts_with('#'));
    let header = lines.next().unwrap();
    assert_eq!(
        header,
        "t_s,j1_deg,j1_rpm,j1_mA,j2_deg,j2_rpm,j2_mA,j3_deg,j3_rpm,j3_mA"
    );
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    assert!((40..=90).contains(&rows.len()), "{} rows", rows.len());
    assert!(rows.iter().all(|r| r.len() == 10));
    // The arm moves: joint 1's position changes by degrees over the run.
    let j1: Vec<f64> = rows.iter().filter_map(|r| r[1].parse().ok()).collect();
    let (lo, hi) = j1
        .iter()
        .fold((f64::MAX, f64::MIN), |(a, b), &v| (a.min(v), b.max(v)));
    assert!(hi - lo > 2.0, "joint 1 stayed within {lo}..{hi}");

    // `robobus plot` reads the recording.
    let png = dir.path().join("arm.png");
    let p = common::robobus(&["plot", csv.to_str().unwrap(), "-o", png.to_str().unwrap()]);
    assert_eq!(p.code, Some(0), "{}", p.stderr);
    assert!(p.stdout.contains("9 signals"), "{}", p.stdout);
}

#[test]
fn monitor_refuses_bad_options() {
    let r = common::robobus(&["monitor", "--duration", "1"]);
    assert_eq!(r.code, Some(2));
    assert!(
        r.stderr.contains("--bus") && r.stderr.contains("--sim"),
        "{}",
        r.stderr
    );
    let r = common::robobus(&["monitor", "--sim", "--record", "out.txt"]);
    assert_eq!(r.code, Some(2));
    assert!(r.stderr.contains(".csv"), "{}", r.stderr);
    let r = common::robobus(&["monitor", "--sim", "--joints", "0-3"]);
    assert_eq!(r.code, Some(2));
    assert!(r.stderr.contains("1..=30"), "{}", r.stderr);
    let r = common::robobus(&["monitor", "--sim", "--rate-hz", "500"]);
    assert_eq!(r.code, Some(2));
    assert!(r.stderr.contains("1..=200"), "{}", r.stderr);
    let r = common::robobus(&["monitor", "--bus", "udp", "--sim"]);
    assert_eq!(r.code, Some(2));
}

/// A dashboard whose terminal goes away (a killed tmux, a dropped SSH session) ends
/// promptly instead of spinning on end of file until killed.
#[test]
fn monitor_ends_when_its_terminal_hangs_up() {
    use std::process::{Command, Stdio};
    use std::time::{Duration, Instant};

    use robobus_link::{PtyOptions, PtyPair};

    let pair = PtyPair::open(&PtyOptions::default()).unwrap();
    let tty = std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .open(&pair.slave_path)
        .unwrap();
    let mut child = Command::new(env!("CARGO_BIN_EXE_robobus"))
        .args(["monitor", "--sim", "--joints", "1-2", "--duration", "60"])
        .stdin(tty.try_clone().unwrap())
        .stdout(tty.try_clone().unwrap())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    drop(tty);
    // Drain what it draws so it never blocks on a full pty, then hang up.
    std::thread::sleep(Duration::from_millis(1500));
    assert!(child.try_wait().unwrap().is_none(), "monitor ended early");
    drop(pair);
    let hung_up = Instant::now();
    loop {
        if child.try_wait().unwrap().is_some() {
            break;
        }
        if hung_up.elapsed() > Duration::from_secs(10) {
            let _ = child.kill();
            panic!("monitor kept running 10 s after its terminal hung up");
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// A capture file on a full disk ends the monitor naming the cause ("No space left on
/// device"), exit 1, instead of marking every sample a bad reply. The full disk is a
/// 16 KiB tmpfs in a private mount namespace (`unshare -m`, as root).
#[test]
fn a_capture_on_a_full_disk_ends_the_monitor_naming_the_cause() {
    let sim = common::WckSim::start("0-1", &[]);
    let dir = tempfile::tempdir().unwrap();
    let mnt = dir.path().join("full");
    std::fs::create_dir(&mnt).unwrap();
    let script = format!(
        "mount -t tmpfs -o size=16k robobus-full {mnt} && exec {bin} monitor --port {port} \
         --servos 0-1 --rate-hz 200 --duration 20 --json --capture {mnt}/c.log",
        mnt = mnt.display(),
        bin = env!("CARGO_BIN_EXE_robobus"),
        port = sim.port(),
    );
    let out = std::process::Command::new("unshare")
        .args(["-m", "sh", "-c", &script])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("No space left on device"), "{err}");
    assert!(err.contains("capture"), "{err}");
}
