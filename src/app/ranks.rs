//! `mpirun -np N wgsph-mpi run ...`: the ranks of a run started by an MPI launcher. `wgsph-mpi`
//! joins them into one simulation; plain `wgsph` says so instead of running N copies of the
//! whole scene side by side. See docs/scale-out.md.

use super::errors::InputError;
use crate::solver::communicator::launched_ranks;
use crate::solver::Ranks;

/// How an executable joins the ranks an MPI launcher started: `wgsph-mpi` (the `mpi/` crate)
/// passes one that initialises MPI; plain `wgsph` has none and refuses a multi-rank launch. The
/// MPI binding lives outside this crate so that the simulator builds once, with or without MPI.
pub type Join = fn() -> anyhow::Result<Ranks>;

/// The ranks of this process: `None` alone, else its rank of the simulation across all of them.
pub fn start(command: &str, join: Option<Join>) -> anyhow::Result<Option<Ranks>> {
    let Some(n) = launched_ranks() else { return Ok(None) };
    if command != "run" {
        return Err(InputError(format!("`wgsph {command}` was started as one of {n} processes by an MPI launcher; only `wgsph run` runs across ranks: start it without mpirun")).into());
    }
    match join {
        Some(join) => Ok(Some(join()?)),
        None => Err(InputError(format!(
            "this wgsph was started as one of {n} processes by an MPI launcher (OMPI_COMM_WORLD_SIZE / PMI_SIZE is set), but it is built without MPI, so each process would run the whole scene on its own: build wgsph-mpi with `cargo build --release -p wgsph-mpi` (needs Open MPI and libclang) and start target/release/wgsph-mpi with mpirun, or run wgsph without mpirun"
        ))
        .into()),
    }
}

/// Runs `work` as this rank. Across ranks an error on one rank stops every rank (MPI_Abort),
/// naming the rank and the error, so that no rank waits forever in the next collective; alone
/// the error is returned as it is.
pub fn run_as_rank(ranks: Option<Ranks>, work: impl FnOnce(Option<&Ranks>) -> anyhow::Result<i32>) -> anyhow::Result<i32> {
    let result = work(ranks.as_ref());
    match (result, &ranks) {
        (Err(e), Some(r)) if r.comm.size() > 1 => r.comm.abort(&format!("{e:#}")),
        (result, _) => result,
    }
}

/// Whether this process writes the run's files and prints its report: every process alone,
/// rank 0 across ranks.
pub fn writes_files(ranks: Option<&Ranks>) -> bool {
    ranks.is_none_or(|r| r.comm.rank() == 0)
}
