//! Fuzz target: `robobus_fuzzing::program_text` (see its docs for the properties checked).
#![no_main]

robobus_fuzz::target!(program_text);
