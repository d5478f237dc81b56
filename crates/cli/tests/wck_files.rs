//! wCK file arguments: bounded reads, and an output path checked before any device.

#![allow(clippy::unwrap_used, clippy::panic)] // test helpers: a failed unwrap is a failed test

use crate::common;

use common::robobus;

const PORT: &str = "/nonexistent/ttyUSB9";

#[test]
fn endless_keyframe_and_program_files_are_refused_with_the_limit() {
    let r = robobus(&["wck", "--dry-run", "play", "/dev/zero"]);
    assert_eq!(r.code, Some(2), "{r:#?}");
    assert!(
        r.stderr
            .contains("/dev/zero: larger than the limit of 4 MiB"),
        "{}",
        r.stderr
    );
    let r = robobus(&["wck", "--dry-run", "program", "upload", "0", "/dev/zero"]);
    assert_eq!(r.code, Some(2), "{r:#?}");
    assert!(r.stderr.contains("limit of 64 KiB"), "{}", r.stderr);
    let r = robobus(&["wck", "program", "check", "/dev/zero"]);
    assert_eq!(r.code, Some(2), "{r:#?}");
}

#[test]
fn teach_checks_its_output_file_before_opening_the_port() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("no-such-dir").join("poses.txt");
    let r = robobus(&[
        "wck",
        "--port",
        PORT,
        "teach",
        "0-1",
        "-o",
        out.to_str().unwrap(),
    ]);
    assert_eq!(r.code, Some(2), "{r:#?}");
    assert!(r.stderr.contains("poses.txt: cannot write"), "{}", r.stderr);
    assert!(
        !r.stderr.contains(PORT),
        "the port was never opened: {}",
        r.stderr
    );
}
