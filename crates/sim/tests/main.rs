//! The integration tests of robobus-sim, one test binary: each file of `tests/` is a module
//! (`cargo test -p robobus-sim --test integration FILE::`), and the helpers they share are
//! modules too, used as `crate::NAME`. A new file is declared here, or the guard below
//! fails.

mod wck_bus;
mod wck_commands;
mod wck_endpoint;
mod wck_endpoint_backpressure;
mod wck_link;
mod wck_mechanics;
mod wck_program;
mod wck_support;
mod whj_broadcast;
mod whj_bus;
mod whj_common;
mod whj_demo_replay;
mod whj_endpoint;
mod whj_fdcanusb;
mod whj_modes;
mod whj_protection;
mod whj_registers;

/// Every file of `tests/` is declared above: a file that is not would never run.
#[test]
fn every_test_file_is_a_module_of_this_binary() {
    robobus_testkit::assert_every_test_file_declared(
        env!("CARGO_MANIFEST_DIR"),
        include_str!("main.rs"),
    );
}
