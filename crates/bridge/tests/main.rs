//! The integration tests of robobus-bridge, one test binary: each file of `tests/` is a module
//! (`cargo test -p robobus-bridge --test integration FILE::`), and the helpers they share are
//! modules too, used as `crate::NAME`. A new file is declared here, or the guard below
//! fails.

mod namespace;
mod rates;
mod velocity;

/// Live bridges: a test that times one on the wall clock runs alone
/// ([`live_bridge_alone`]); others may run beside each other ([`bridges_beside_each_other`])
/// but not beside it. A failed test's poison is not the next one's failure.
static LIVE_BRIDGES: std::sync::RwLock<()> = std::sync::RwLock::new(());

/// Holds every other live bridge of these tests off while a wall-clock-timed one runs.
fn live_bridge_alone() -> std::sync::RwLockWriteGuard<'static, ()> {
    LIVE_BRIDGES
        .write()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// Keeps a wall-clock-timed bridge test from running beside this one.
fn bridges_beside_each_other() -> std::sync::RwLockReadGuard<'static, ()> {
    LIVE_BRIDGES
        .read()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// Every file of `tests/` is declared above: a file that is not would never run.
#[test]
fn every_test_file_is_a_module_of_this_binary() {
    robobus_testkit::assert_every_test_file_declared(
        env!("CARGO_MANIFEST_DIR"),
        include_str!("main.rs"),
    );
}
