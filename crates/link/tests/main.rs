//! The integration tests of robobus-link, one test binary: each file of `tests/` is a module
//! (`cargo test -p robobus-link --test integration FILE::`), and the helpers they share are
//! modules too, used as `crate::NAME`. A new file is declared here, or the guard below
//! fails.

mod common;
mod fault_capture;
mod pty;
mod python_interop;
mod socketcan_uml;
mod udp_bus;
mod udp_malformed_flood;

/// Every file of `tests/` is declared above: a file that is not would never run.
#[test]
fn every_test_file_is_a_module_of_this_binary() {
    robobus_testkit::assert_every_test_file_declared(
        env!("CARGO_MANIFEST_DIR"),
        include_str!("main.rs"),
    );
}
