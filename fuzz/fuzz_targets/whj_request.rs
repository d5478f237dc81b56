//! Fuzz target: `robobus_fuzzing::whj_request` (see its docs for the properties checked).
#![no_main]

robobus_fuzz::target!(whj_request);
