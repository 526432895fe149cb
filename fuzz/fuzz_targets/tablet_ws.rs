//! Fuzz target `tablet_ws`: see `suite_fuzz::tablet_ws` for the input and what must hold.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| suite_fuzz::tablet_ws(data));
