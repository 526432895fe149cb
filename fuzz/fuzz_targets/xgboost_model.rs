//! Fuzz target `xgboost_model`: see `suite_fuzz::xgboost_model` for the input and what must hold.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| suite_fuzz::xgboost_model(data));
