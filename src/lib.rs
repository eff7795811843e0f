//! wgsph: a weakly compressible SPH fluid simulator whose time step runs as WGSL compute shaders
//! through wgpu, with a CPU reference path (f32 or f64) that checks every GPU result.
//!
//! The physics follows "An Implementation of Smoothed Particle Hydrodynamics" (the seed report):
//! density by kernel summation, a linear or Tait equation of state, the symmetric pressure force,
//! Laplacian viscosity, gravity, wall particles and analytic planes, a uniform grid of cell size
//! h and symplectic Euler.
//!
//! Programs that embed the simulator start from [`Simulation`]: a [`Scene`] (from a file, a
//! TOML string or built in code) on the GPU or the CPU, [`Simulation::step`],
//! [`Simulation::snapshot`], and on the GPU the wgpu device and particle buffers for their own
//! rendering. The `wgsph` command line is [`cli`]; snapshot files in other formats are
//! [`export`]; checkpoints are [`checkpoint`].

pub mod checkpoint;
pub mod cli;
pub mod compare;
pub mod cpu;
pub mod export;
pub mod gpu;
pub mod output;
pub mod plot;
pub mod profile;
pub mod real;
pub mod render;
pub mod run;
pub mod rundir;
pub mod scene;
pub mod sim;
pub mod simulation;
pub mod splishsplash;
pub mod surface;
pub mod tradeoff;
pub mod validate;
#[cfg(feature = "view")]
pub mod view;

pub use scene::{Scene, SceneError};
pub use sim::{Backend, Health, Snapshot};
pub use simulation::Simulation;
