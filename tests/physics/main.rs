//! The physics: kernels and equations of state, the CPU reference on its own (conservation,
//! stability, hydrostatics), the extremes, and the validation cases at coarse resolution.

#[path = "../common/mod.rs"]
mod common;

mod kernels;
mod cpu_reference;
mod extremes;
mod blowups;
mod coarse_walls;
mod validation;
mod dfsph;
mod pressure;
mod meshes;
mod surface_tension;
