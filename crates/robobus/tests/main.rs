//! The integration tests of robobus, one test binary: each file of `tests/` is a module
//! (`cargo test -p robobus --test integration FILE::`), and the helpers they share are
//! modules too, used as `crate::NAME`. A new file is declared here, or the guard below
//! fails.

mod catalogue;
mod catalogue_docs;
mod common;
mod device_suite;
mod handles;
mod host_ports;
mod jog_guard;
mod layers;
mod mcap_recording;
mod monitor_sampling;
mod preflight;
mod protection_config;
mod replay_capture;
mod replay_uml;
mod report_schema;
mod robot_config;
mod robot_protection;
mod robot_reports;
mod robot_sim;
mod robot_velocity;
mod sim_faults;
mod station_support;
mod telemetry_shared;
mod wck_faults;
mod wck_guard;
mod wck_late;
mod wck_ops;
mod wck_policy;
mod wck_protection;
mod wck_reports;
mod wck_run_reports;
mod wck_settings;
mod wck_sim;
mod wck_support;
mod wck_tcp;
mod wck_tune;
mod whj_common;
mod whj_config_reports;
mod whj_cyclic;
mod whj_end_board;
mod whj_faults;
mod whj_fdcanusb;
mod whj_joint;
mod whj_lag;
mod whj_late_replies;
mod whj_ops;
mod whj_plan_stop;
mod whj_protection;
mod whj_rates;
mod whj_reply_faults;
mod whj_reports;
mod whj_runs;
mod whj_servo_many;
mod whj_settings;
mod whj_slcan;
mod whj_socketcan;
mod whj_udp;

/// Every file of `tests/` is declared above: a file that is not would never run.
#[test]
fn every_test_file_is_a_module_of_this_binary() {
    robobus_testkit::assert_every_test_file_declared(
        env!("CARGO_MANIFEST_DIR"),
        include_str!("main.rs"),
    );
}
