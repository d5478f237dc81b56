//! Fuzz target: `robobus_fuzzing::wck_reply` (see its docs for the properties checked).
#![no_main]

robobus_fuzz::target!(wck_reply);
