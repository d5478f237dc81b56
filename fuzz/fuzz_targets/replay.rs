//! Fuzz target: `robobus_fuzzing::replay` (see its docs for the properties checked).
#![no_main]

robobus_fuzz::target!(replay);
