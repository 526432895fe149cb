//! Fuzz target `read_bag`: see `suite_fuzz::read_bag` for the input and what must hold.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| suite_fuzz::read_bag(data));
