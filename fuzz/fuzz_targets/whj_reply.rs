//! Fuzz target: `robobus_fuzzing::whj_reply` (see its docs for the properties checked).
#![no_main]

robobus_fuzz::target!(whj_reply);
