//! Files: scene errors, imports, snapshots in every format (whole and streamed), checkpoints and
//! restart, run directories and surface meshes.

#[path = "../common/mod.rs"]
mod common;

mod scene_errors;
mod refusals;
mod lattice;
mod splishsplash;
mod export;
mod stream;
mod checkpoint;
mod run_dir;
mod surface;
mod probes;
mod meshes;
