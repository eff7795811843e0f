//! `wgsph-mpi`: the `wgsph` command line, able to join the ranks an MPI launcher starts into one
//! simulation (`mpirun -np 4 wgsph-mpi run ...`). Everything but the MPI binding is the wgsph
//! library's, so this crate is small and the simulator builds once for both executables.

mod communicator;

use std::sync::Arc;
use wgsph::solver::Ranks;

fn join() -> anyhow::Result<Ranks> {
    Ok(Ranks::new(Arc::new(communicator::MpiCommunicator::init()?)))
}

fn main() {
    std::process::exit(wgsph::app::main_joining_ranks(Some(join)));
}
