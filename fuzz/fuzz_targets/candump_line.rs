//! Fuzz target: `robobus_fuzzing::candump_line` (see its docs for the properties checked).
#![no_main]

robobus_fuzz::target!(candump_line);
