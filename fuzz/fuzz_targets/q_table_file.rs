//! Fuzz target `q_table_file`: see `suite_fuzz::q_table_file` for the input and what must hold.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| suite_fuzz::q_table_file(data));
