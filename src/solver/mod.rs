//! The solvers: the [`Backend`] trait every layer above drives, the one builder [`open`], and
//! the two twins that implement it, the GPU pipeline ([`gpu`]) and the CPU reference ([`cpu`]).
//! A method is a set of stages (one WGSL file and one CPU file of the same name each) and its
//! place in the step order: `gpu/schedule.rs` records the GPU's, `cpu/mod.rs` runs the CPU's.

pub mod backend;
pub mod communicator;
pub mod compare;
pub mod cpu;
pub mod decomposition;
pub mod gpu;
pub mod simulation;

pub use backend::{id_block, Backend, DfsphStage, SnapshotPiece, SnapshotRow, StateArray, StatePiece, StateSource, WholeState};
pub use communicator::{Communicator, LocalGroup, Ranks};
pub use simulation::{open, open_with, BackendChoice, Device, Precision, Simulation, Solver};
