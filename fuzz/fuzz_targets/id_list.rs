//! Fuzz target: `robobus_fuzzing::id_list` (see its docs for the properties checked).
#![no_main]

robobus_fuzz::target!(id_list);
