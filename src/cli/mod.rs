//! The binaries' command lines: each binary's clap parser and the function it calls with what was parsed.
//! They live in the library so that a test can parse the commands the documentation shows with the very
//! parsers the binaries use (`tests/doc_commands.rs`).

pub mod calibrate;
pub mod campaign;
pub mod real_data;
