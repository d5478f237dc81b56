//! Fuzz target: `robobus_fuzzing::robot_toml` (see its docs for the properties checked).
#![no_main]

robobus_fuzz::target!(robot_toml);
