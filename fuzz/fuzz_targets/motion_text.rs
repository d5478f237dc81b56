//! Fuzz target: `robobus_fuzzing::motion_text` (see its docs for the properties checked).
#![no_main]

robobus_fuzz::target!(motion_text);
