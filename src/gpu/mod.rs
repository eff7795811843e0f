//! The GPU path: device, structure-of-arrays buffers, the WGSL pipelines and their dispatch order.

pub mod device;
pub mod memory;
pub mod pipelines;
pub mod scan;
pub mod solver;
pub mod workgroups;

pub use device::{GpuContext, GpuError};
pub use solver::{GpuOptions, GpuSolver, ParticleBuffers};
pub use workgroups::WorkgroupSizes;
