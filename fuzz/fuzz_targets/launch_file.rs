//! Fuzz target `launch_file`: see `suite_fuzz::launch_file` for the input and what must hold.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| suite_fuzz::launch_file(data));
