//! Fuzz target: `robobus_fuzzing::register_name` (see its docs for the properties checked).
#![no_main]

robobus_fuzz::target!(register_name);
