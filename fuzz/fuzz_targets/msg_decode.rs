//! Fuzz target `msg_decode`: see `suite_fuzz::msg_decode` for the input and what must hold.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| suite_fuzz::msg_decode(data));
