//! External-client test: the built `robobus sim whj` binary serves seven joints on
//! python-can's UDP multicast bus, and a python-can script (`scripts/py/whj_position_client.py`)
//! enables joint 1, switches to position mode, streams position servo frames at 1 kHz for a
//! ±2° move and checks that the feedback follows.
//!
//! Both processes run inside a private network namespace (`unshare -n`, loopback up, a
//! multicast route on `lo`, as the `robobus-link` UDP docs explain), so no datagram can
//! leave the machine. The test provisions python-can itself (`scripts/py/ensure-venv`)
//! and fails loudly if it cannot.

#![cfg(target_os = "linux")] // a private network namespace
#![allow(
    clippy::unwrap_used,
    clippy::float_cmp,
    clippy::cast_possible_truncation,
    clippy::cast_sign_loss,
    clippy::cast_possible_wrap,
    clippy::cast_precision_loss,
    clippy::unchecked_time_subtraction,
    clippy::panic
)] // Test code: a failed unwrap is a failed test; exact float equality is asserted on purpose.

use std::path::{Path, PathBuf};

use robobus_testkit::Guest;
use robobus_testkit::workspace_root as workspace;

fn python() -> PathBuf {
    PathBuf::from(robobus_testkit::provision("py/ensure-venv"))
}

fn field(json: &str, key: &str) -> f64 {
    let pat = format!("\"{key}\": ");
    let at = json
        .find(&pat)
        .unwrap_or_else(|| panic!("{key} missing in {json}"))
        + pat.len();
    let rest = &json[at..];
    let end = rest.find([',', '}']).unwrap_or(rest.len());
    rest[..end]
        .trim()
        .parse()
        .unwrap_or_else(|_| panic!("{key} in {json}"))
}

#[test]
fn python_can_client_streams_position_at_1khz_over_udp() {
    let py = python();
    let client = workspace().join("scripts/py/whj_position_client.py");
    let sim = env!("CARGO_BIN_EXE_robobus");
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("sim.log");
    let script = dir.path().join("run.sh");
    let q = |p: &Path| format!("'{}'", p.display());
    std::fs::write(
        &script,
        format!(
            r#"set -u
'{sim}' sim whj --joints 1-7 --model whj30 --bus udp --seed 3 2>{log} &
sim=$!
for i in $(seq 200); do grep -q serving {log} && break; kill -0 $sim 2>/dev/null || break; sleep 0.05; done
grep -q serving {log} || {{ echo "simulator did not start:" >&2; cat {log} >&2; exit 91; }}
{py} {client} --interface udp_multicast --channel 239.74.163.2 --joint 1 --amplitude-deg 2 --period-s 2 --rate-hz 1000 --max-error-deg 3 --allow-lost 100
rc=$?
kill -INT $sim
wait $sim
simrc=$?
cat {log} >&2
[ $simrc -eq 0 ] || {{ echo "simulator exited with $simrc after SIGINT" >&2; exit 92; }}
exit $rc
"#,
            log = q(&log),
            py = q(&py),
            client = q(&client),
        ),
    )
    .unwrap();
    let ran = Guest::new("bash")
        .arg(&script)
        .timeout_s(120)
        .in_private_netns()
        .expect_success();
    let (stdout, stderr) = (ran.stdout, ran.stderr);
    let json = stdout
        .lines()
        .rev()
        .find(|l| l.starts_with('{'))
        .unwrap_or_else(|| panic!("no result line: {stdout}"));
    eprintln!("client result: {json}");
    assert!(json.contains("\"ok\": true"), "{json}");
    // The 2001 frames were answered (UDP drops datagrams when a stall of the simulator
    // overflows its socket buffer: at 1 kHz a 200 ms stall queues 200 of them, so up to
    // 5 % may be lost), the joint swept ±2° and followed.
    assert_eq!(field(json, "sent"), 2001.0);
    assert!(field(json, "replies") >= 1901.0, "{json}");
    assert!(
        field(json, "max_deg") >= 1.8 && field(json, "min_deg") <= -1.8,
        "{json}"
    );
    // Within 3°. The ±2° sweep peaks at 6.3 °/s, so even a 300 ms stall of either process
    // (a shared virtual machine stalls threads for up to ~200 ms) leaves the joint less
    // than 2° behind; a larger sweep could trip the joint's 10° step protection then.
    assert!(field(json, "max_follow_error_deg") <= 3.0, "{json}");
    // The simulator saw the servo frames (all but datagrams lost in a stall) plus the 6
    // start-up / status frames, and answered each.
    let stats = stderr
        .lines()
        .find(|l| l.contains("frames in"))
        .unwrap_or_else(|| panic!("no stop line: {stderr}"));
    let count = |what: &str| -> u64 {
        let before = stats.split(what).next().unwrap_or_default();
        before
            .rsplit(|c: char| !c.is_ascii_digit())
            .find(|t| !t.is_empty())
            .unwrap_or("0")
            .parse()
            .unwrap()
    };
    assert!(count(" frames in") >= 1907, "{stats}");
    assert_eq!(count(" frames in"), count(" frames out"), "{stats}");
}
