//! wgsph: a weakly compressible SPH fluid simulator whose time step runs as WGSL compute shaders
//! through wgpu, with a CPU reference path (f32 or f64) that checks every GPU result.
//!
//! The physics follows "An Implementation of Smoothed Particle Hydrodynamics" (the seed report):
//! density by kernel summation, a linear or Tait equation of state, the symmetric pressure force,
//! Laplacian viscosity, gravity, wall particles and analytic planes, a uniform grid of cell size
//! h and symplectic Euler.

pub mod cli;
pub mod compare;
pub mod cpu;
pub mod gpu;
pub mod output;
pub mod plot;
pub mod real;
pub mod run;
pub mod scene;
pub mod sim;
pub mod validate;

pub use scene::{Scene, SceneError};
pub use sim::{Backend, Health, Snapshot};
