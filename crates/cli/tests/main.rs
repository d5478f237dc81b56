//! The integration tests of robobus-cli, one test binary: each file of `tests/` is a module
//! (`cargo test -p robobus-cli --test integration FILE::`), and the helpers they share are
//! modules too, used as `crate::NAME`. A new file is declared here, or the guard below
//! fails.

mod bad_input;
mod bridge;
mod can_health;
mod capture_e2e;
mod common;
mod demo;
mod doctor_and_generate;
mod dry_run;
mod fdcanusb_e2e;
mod logging;
mod monitor;
mod plot;
mod ports;
mod replay;
mod robot_calibrate;
mod robot_play;
mod robot_safe_state;
mod robot_teach;
mod robot_teleop;
mod robot_velocity_play;
mod run;
mod sim_faults_e2e;
mod sim_wck_link;
mod sim_wck_python;
mod sim_whj_udp;
mod sim_whj_vcan;
mod sim_whj_vcan_deadlines;
mod slcan_e2e;
mod snapshots;
mod studio;
mod wck_e2e;
mod wck_files;
mod wck_tcp_e2e;
mod whj_e2e;
mod windows_wine;

/// Every file of `tests/` is declared above: a file that is not would never run.
#[test]
fn every_test_file_is_a_module_of_this_binary() {
    robobus_testkit::assert_every_test_file_declared(
        env!("CARGO_MANIFEST_DIR"),
        include_str!("main.rs"),
    );
}
