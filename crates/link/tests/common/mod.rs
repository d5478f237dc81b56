//! Helpers shared by the integration tests that provision outside programs.

#![allow(clippy::unwrap_used, clippy::panic)]
#![allow(dead_code)]

use std::path::PathBuf;
use std::process::Command;
use std::sync::OnceLock;

/// The workspace root (`crates/link/../..`).
pub(crate) fn workspace_root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../..")
        .canonicalize()
        .unwrap()
}

/// Runs a provisioning script from `scripts/` and returns the last line of its stdout;
/// panics loudly with its output if it fails.
pub(crate) fn provision(script: &str) -> String {
    let path = workspace_root().join("scripts").join(script);
    let out = Command::new(&path)
        .output()
        .unwrap_or_else(|e| panic!("cannot run {}: {e}", path.display()));
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(
        out.status.success(),
        "{} failed ({}):\nstdout:\n{stdout}\nstderr:\n{}",
        path.display(),
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    stdout.lines().last().unwrap_or_default().trim().to_owned()
}

/// The venv python with python-can and msgpack (created on first use).
pub(crate) fn python() -> PathBuf {
    static PY: OnceLock<PathBuf> = OnceLock::new();
    PY.get_or_init(|| PathBuf::from(provision("py/ensure-venv")))
        .clone()
}

/// A test helper script under `crates/link/tests/py/`.
pub(crate) fn py_script(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/py")
        .join(name)
}
