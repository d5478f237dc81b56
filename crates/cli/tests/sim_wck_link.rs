//! `robobus sim wck`: the link appears only when the servos listen, and `--link` never
//! clobbers or deletes what is not its own.
//!
//! - A client that opens the link the moment it appears (polling the file system, not
//!   waiting for the printed path) gets an answer to its first command, 20 runs in a row.
//!   Before, the link appeared while the modules were still deaf after power-up (65 ms).
//! - `--power-up-on-open` models that deafness on purpose: the first command is lost.
//! - A regular file at `--link` is refused (exit 2) and left as it was; so is a second
//!   simulator on a live simulator's link; a file the user put at the path after the
//!   simulator started is not deleted on exit.

#![allow(clippy::unwrap_used, clippy::panic)] // test code
#![cfg(target_os = "linux")]

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use robobus_link::{ByteLink, LinkError, SerialLink};

/// Status of servo 0 (manual A-1: `FF A0 00 20`), answered by `00 <position>`.
const STATUS_0: [u8; 4] = [0xFF, 0xA0, 0x00, 0x20];

fn spawn_sim(link: &Path, extra: &[&str]) -> Child {
    Command::new(env!("CARGO_BIN_EXE_robobus"))
        .args(["sim", "wck", "--servos", "0"])
        .args(extra)
        .arg("--link")
        .arg(link)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

/// Stops the simulator with SIGTERM and returns its exit code.
fn stop(mut child: Child) -> Option<i32> {
    let _ = Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status();
    let deadline = Instant::now() + Duration::from_secs(10);
    loop {
        if let Some(st) = child.try_wait().unwrap() {
            return st.code();
        }
        if Instant::now() > deadline {
            let _ = child.kill();
            panic!("simulator did not stop on SIGTERM");
        }
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// Waits (polling every 200 µs) until `path` exists as a symlink; returns at once then.
fn wait_for_link(path: &Path, child: &mut Child) {
    let deadline = Instant::now() + Duration::from_secs(20);
    while std::fs::symlink_metadata(path).is_err() {
        assert!(
            child.try_wait().unwrap().is_none(),
            "simulator exited early"
        );
        assert!(Instant::now() < deadline, "the link never appeared");
        std::thread::sleep(Duration::from_micros(200));
    }
}

/// Opens the link and sends one status command; returns the reply bytes that arrived
/// within `wait`.
fn first_command(path: &Path, wait: Duration) -> Vec<u8> {
    let mut port = SerialLink::open(path, 115_200).unwrap();
    let t0 = Instant::now();
    port.write_all(&STATUS_0).unwrap();
    let mut reply = [0u8; 2];
    match port.read_exact(&mut reply, t0 + wait) {
        Ok(()) => reply.to_vec(),
        Err(LinkError::Timeout { received, .. }) => reply[..received].to_vec(),
        Err(e) => panic!("{e}"),
    }
}

fn link_in(dir: &tempfile::TempDir) -> PathBuf {
    dir.path().join("wck0")
}

#[test]
fn a_client_that_opens_the_link_the_moment_it_appears_gets_its_first_answer_20_times() {
    for run in 0..20 {
        let dir = tempfile::tempdir().unwrap();
        let link = link_in(&dir);
        let mut sim = spawn_sim(&link, &[]);
        wait_for_link(&link, &mut sim);
        // Generous for a stalled machine; the reply itself takes 1.5 ms of wire time.
        let reply = first_command(&link, Duration::from_secs(2));
        assert_eq!(reply.len(), 2, "run {run}: first command unanswered");
        assert_eq!(reply[0], 0x00, "run {run}: {reply:02X?}");
        assert_eq!(stop(sim), Some(0), "run {run}");
        assert!(
            std::fs::symlink_metadata(&link).is_err(),
            "run {run}: link left behind"
        );
    }
}

#[test]
fn power_up_on_open_loses_a_command_sent_in_the_first_65_ms() {
    let dir = tempfile::tempdir().unwrap();
    let link = link_in(&dir);
    let mut sim = spawn_sim(&link, &["--power-up-on-open"]);
    wait_for_link(&link, &mut sim);
    let reply = first_command(&link, Duration::from_millis(30));
    // Only if the machine stalled us past the 65 ms can the servo have heard it.
    let late = reply.len() == 2;
    // Later on it answers.
    std::thread::sleep(Duration::from_millis(100));
    assert_eq!(first_command(&link, Duration::from_secs(2)).len(), 2);
    assert_eq!(stop(sim), Some(0));
    assert!(!late, "a deaf servo answered: {reply:02X?}");
}

#[test]
fn a_regular_file_at_the_link_path_is_refused_and_left_alone() {
    let dir = tempfile::tempdir().unwrap();
    let link = link_in(&dir);
    std::fs::write(&link, "my notes\n").unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_robobus"))
        .args(["sim", "wck", "--link"])
        .arg(&link)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("--link") && stderr.contains("regular file") && stderr.contains("wck0"),
        "{stderr}"
    );
    assert!(out.stdout.is_empty());
    assert_eq!(std::fs::read_to_string(&link).unwrap(), "my notes\n");
}

#[test]
fn a_second_simulator_does_not_take_over_a_live_link() {
    let dir = tempfile::tempdir().unwrap();
    let link = link_in(&dir);
    let mut first = spawn_sim(&link, &[]);
    wait_for_link(&link, &mut first);
    let target = std::fs::read_link(&link).unwrap();

    let out = Command::new(env!("CARGO_BIN_EXE_robobus"))
        .args(["sim", "wck", "--servos", "0", "--link"])
        .arg(&link)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("another simulator") && stderr.contains(&first.id().to_string()),
        "{stderr}"
    );
    // The first one's link is untouched and still serves.
    assert_eq!(std::fs::read_link(&link).unwrap(), target);
    assert_eq!(first_command(&link, Duration::from_secs(2)).len(), 2);
    assert_eq!(stop(first), Some(0));
}

#[test]
fn a_file_put_at_the_link_path_while_serving_is_not_deleted_on_exit() {
    let dir = tempfile::tempdir().unwrap();
    let link = link_in(&dir);
    let mut sim = spawn_sim(&link, &[]);
    wait_for_link(&link, &mut sim);
    // The user replaces the link with a file of their own.
    std::fs::remove_file(&link).unwrap();
    std::fs::write(&link, "mine\n").unwrap();
    assert_eq!(stop(sim), Some(0));
    assert_eq!(std::fs::read_to_string(&link).unwrap(), "mine\n");

    // A symlink of somebody else's (to an existing file) is refused too, and kept.
    std::fs::remove_file(&link).unwrap();
    let other = dir.path().join("other");
    std::fs::write(&other, "").unwrap();
    std::os::unix::fs::symlink(&other, &link).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_robobus"))
        .args(["sim", "wck", "--link"])
        .arg(&link)
        .output()
        .unwrap();
    assert_eq!(
        out.status.code(),
        Some(2),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(std::fs::read_link(&link).unwrap(), other);
}

#[test]
fn a_stale_link_of_a_killed_simulator_is_replaced() {
    let dir = tempfile::tempdir().unwrap();
    let link = link_in(&dir);
    let mut sim = spawn_sim(&link, &[]);
    wait_for_link(&link, &mut sim);
    sim.kill().unwrap(); // SIGKILL: no clean-up
    sim.wait().unwrap();
    assert!(
        std::fs::symlink_metadata(&link).is_ok(),
        "link left by the killed one"
    );
    let mut again = spawn_sim(&link, &[]);
    let deadline = Instant::now() + Duration::from_secs(20);
    // The new simulator replaces it once its servos listen.
    loop {
        // The old link dangles (its pty is gone) until the new one replaces it.
        let points_to_a_pty = std::fs::metadata(&link).is_ok();
        if points_to_a_pty && first_command(&link, Duration::from_millis(500)).len() == 2 {
            break;
        }
        std::thread::sleep(Duration::from_millis(5));
        assert!(
            again.try_wait().unwrap().is_none(),
            "second simulator exited"
        );
        assert!(Instant::now() < deadline, "stale link never replaced");
    }
    assert_eq!(stop(again), Some(0));
    assert!(std::fs::symlink_metadata(&link).is_err());
}
