//! The GPU path: the device, the memory plan, the shaders and their pipelines, the buffers, the
//! one step order (`schedule.rs`), the readback in pieces, and the solver that holds them.

pub mod buffers;
pub mod device;
pub mod dfsph;
pub mod dfsph_ranks;
pub mod memory;
pub mod params;
pub mod pipelines;
pub mod prefix_sum;
pub mod probes;
pub mod ranks;
pub mod readback;
pub mod resident;
pub mod schedule;
pub mod shaders;
pub mod skin;
pub mod solver;
pub mod workgroups;

pub use buffers::ParticleBuffers;
pub use device::{GpuContext, GpuError};
pub use solver::{GpuSolver, ListUsage};
pub use workgroups::{GpuOptions, SolverLoop, WorkgroupSizes};
