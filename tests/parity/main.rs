//! GPU against the CPU reference: every stage alone, whole steps and runs, adaptive time steps,
//! the specialised shaders, and arrays bound in segments. Every GPU test runs on every adapter
//! found.

#[path = "../common/mod.rs"]
mod common;

mod stages;
mod gpu;
mod adaptive;
mod specialise;
mod scale;
mod dfsph;
mod probes;
mod pressure;
mod lanes;
mod ranks;
mod tiles;
mod skin;
