//! Fuzz target: `robobus_fuzzing::hex_line` (see its docs for the properties checked).
#![no_main]

robobus_fuzz::target!(hex_line);
