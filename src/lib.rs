//! wgsph: a weakly compressible SPH fluid simulator whose time step runs as WGSL compute shaders
//! through wgpu, with a CPU reference path (f32 or f64) that checks every GPU result.
//!
//! The physics follows "An Implementation of Smoothed Particle Hydrodynamics" (the seed report):
//! density by kernel summation, a linear or Tait equation of state, the symmetric pressure force,
//! Laplacian viscosity, gravity, wall particles and analytic planes, a uniform grid of cell size
//! h and symplectic Euler.
//!
//! The crate is built in floors, each importing only the floors below it (docs/design.md):
//! - [`model`]: what a scene, its constants and a state are (no GPU, no files);
//! - [`solver`]: the [`Backend`] trait, the one builder [`solver::open`], and the GPU and CPU
//!   twins that implement it;
//! - [`io`]: files (snapshots, checkpoints, summaries, surface meshes);
//! - [`viz`]: pictures (frames, the viewer, plots);
//! - [`app`]: the `wgsph` command line, which nothing imports.
//!
//! Programs that embed the simulator start from [`Simulation`]: a [`Scene`] (from a file, a
//! TOML string or built in code) on the GPU or the CPU, [`Simulation::step`],
//! [`Simulation::snapshot`], and on the GPU the wgpu device and particle buffers for their own
//! rendering.

pub mod app;
pub mod io;
pub mod model;
pub mod solver;
pub mod viz;

pub use model::{Health, Scene, SceneError, Snapshot};
pub use solver::{Backend, Simulation};
