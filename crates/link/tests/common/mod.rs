//! Helpers shared by the integration tests that provision outside programs.

#![allow(clippy::unwrap_used, clippy::panic)]
#![allow(dead_code)]

use std::path::PathBuf;
use std::sync::OnceLock;

#[allow(unused_imports)] // each test file uses a subset
pub(crate) use robobus_testkit::{provision, workspace_root};

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
