//! The launcher's library half: the launch-description parser, so tests and the fuzzer can
//! parse launch files the way `launch` does without starting any process.

pub mod description;
