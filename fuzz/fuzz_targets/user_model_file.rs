//! Fuzz target `user_model_file`: see `suite_fuzz::user_model_file` for the input and what must hold.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| suite_fuzz::user_model_file(data));
