//! Files: written atomically, snapshots in every format (whole or in pieces), the run's
//! summary, checkpoints, the run directory, and surface meshes. A solver is reached only
//! through the [`crate::solver::Backend`] trait.

pub mod atomic;
pub mod checkpoint;
pub mod probes;
pub mod rundir;
pub mod snapshot;
pub mod summary;
pub mod surface;
