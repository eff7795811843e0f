//! The command line: runs, exit codes, outputs, the profile and the speed-against-accuracy study.

#[path = "../common/mod.rs"]
mod common;

mod commands;
mod runs;
mod profile;
mod tradeoff;
mod architecture;
mod bench;
mod ranks;
