//! The ranks' [`Communicator`](wgsph::solver::Communicator) over MPI: one rank per process,
//! started by `mpirun` (Open MPI, MPICH or any MPI the `mpi` crate builds against). See
//! docs/scale-out.md.

use wgsph::solver::Communicator as RankCommunicator;
use mpi::datatype::{Partition, PartitionMut};
use mpi::topology::SimpleCommunicator;
use mpi::traits::*;
use mpi::Count;

/// Messages to the lower rank and to the upper rank carry different tags, so that a rank with
/// one neighbour on each side never takes one for the other.
const TOWARDS_LOWER: i32 = 1;
const TOWARDS_UPPER: i32 = 2;

/// MPI's world, and this process's place on its machine. MPI stays initialised while it lives
/// (MPI_Finalize when it is dropped).
pub struct MpiCommunicator {
    world: SimpleCommunicator,
    node: (usize, usize),
    description: String,
    // Dropped last: finalises MPI.
    _universe: mpi::environment::Universe,
}

// Every MPI call is made by the thread that runs the step loop (the rayon threads of a stage
// never call it), which is what MPI's funneled threading level, asked for at initialisation,
// allows.
unsafe impl Send for MpiCommunicator {}
unsafe impl Sync for MpiCommunicator {}

impl MpiCommunicator {
    /// Initialises MPI (once per process).
    pub fn init() -> anyhow::Result<MpiCommunicator> {
        let (universe, _level) = mpi::initialize_with_threading(mpi::Threading::Funneled)
            .ok_or_else(|| anyhow::anyhow!("MPI was initialised before in this process"))?;
        let world = universe.world();
        let node_comm = world.split_shared(world.rank());
        let node = (node_comm.rank() as usize, node_comm.size() as usize);
        let library = mpi::environment::library_version().unwrap_or_default();
        // "Open MPI v4.1.4, package: ...": the name and version.
        let library = library.split(',').next().unwrap_or("MPI").trim_matches(|c: char| c.is_whitespace() || c == '\0').to_string();
        let description = format!("{library}, {} ranks", world.size());
        Ok(MpiCommunicator { world, node, description, _universe: universe })
    }
}

impl RankCommunicator for MpiCommunicator {
    fn rank(&self) -> usize {
        self.world.rank() as usize
    }
    fn size(&self) -> usize {
        self.world.size() as usize
    }
    fn exchange(&self, to_lower: &[u8], to_upper: &[u8]) -> anyhow::Result<(Vec<u8>, Vec<u8>)> {
        let (rank, size) = (self.world.rank(), self.world.size());
        // MPI counts in a C int. The neighbour waits for this message: stop every rank.
        for message in [to_lower, to_upper] {
            if Count::try_from(message.len()).is_err() {
                self.abort(&format!("a message to a neighbour of {} bytes is beyond MPI's count of {} bytes (more ranks make each slab's messages smaller)", message.len(), Count::MAX));
            }
        }
        let mut from_lower = Vec::new();
        let mut from_upper = Vec::new();
        mpi::request::scope(|scope| {
            // Sends posted first, then the blocking receives: no order of ranks can deadlock.
            let down = (rank > 0).then(|| self.world.process_at_rank(rank - 1).immediate_send_with_tag(scope, to_lower, TOWARDS_LOWER));
            let up = (rank + 1 < size).then(|| self.world.process_at_rank(rank + 1).immediate_send_with_tag(scope, to_upper, TOWARDS_UPPER));
            if rank > 0 {
                from_lower = self.world.process_at_rank(rank - 1).receive_vec_with_tag::<u8>(TOWARDS_UPPER).0;
            }
            if rank + 1 < size {
                from_upper = self.world.process_at_rank(rank + 1).receive_vec_with_tag::<u8>(TOWARDS_LOWER).0;
            }
            if let Some(r) = down {
                r.wait();
            }
            if let Some(r) = up {
                r.wait();
            }
        });
        Ok((from_lower, from_upper))
    }
    fn all_gather(&self, values: &[f64]) -> anyhow::Result<Vec<Vec<f64>>> {
        let size = self.world.size() as usize;
        let mut counts: Vec<Count> = vec![0; size];
        self.world.all_gather_into(&(values.len() as Count), &mut counts[..]);
        let displs = displacements(&counts);
        let mut all = vec![0.0f64; counts.iter().map(|&c| c as usize).sum()];
        {
            let mut partition = PartitionMut::new(&mut all[..], &counts[..], &displs[..]);
            self.world.all_gather_varcount_into(values, &mut partition);
        }
        Ok(split(&all, &counts, &displs))
    }
    fn gather(&self, values: &[f64]) -> anyhow::Result<Option<Vec<Vec<f64>>>> {
        let root = self.world.process_at_rank(0);
        let count = values.len() as Count;
        if self.world.rank() != 0 {
            root.gather_into(&count);
            root.gather_varcount_into(values);
            return Ok(None);
        }
        let mut counts: Vec<Count> = vec![0; self.world.size() as usize];
        root.gather_into_root(&count, &mut counts[..]);
        let displs = displacements(&counts);
        let mut all = vec![0.0f64; counts.iter().map(|&c| c as usize).sum()];
        {
            let mut partition = PartitionMut::new(&mut all[..], &counts[..], &displs[..]);
            root.gather_varcount_into_root(values, &mut partition);
        }
        Ok(Some(split(&all, &counts, &displs)))
    }
    fn all_to_all(&self, parts: &[Vec<f64>]) -> anyhow::Result<Vec<Vec<f64>>> {
        let size = self.world.size() as usize;
        anyhow::ensure!(parts.len() == size, "rank {} sent {} parts to {size} ranks", self.world.rank(), parts.len());
        let send_counts: Vec<Count> = parts.iter().map(|p| p.len() as Count).collect();
        let mut receive_counts: Vec<Count> = vec![0; size];
        self.world.all_to_all_into(&send_counts[..], &mut receive_counts[..]);
        let (send_displs, receive_displs) = (displacements(&send_counts), displacements(&receive_counts));
        let sent: Vec<f64> = parts.concat();
        let mut all = vec![0.0f64; receive_counts.iter().map(|&c| c as usize).sum()];
        {
            let send = Partition::new(&sent[..], &send_counts[..], &send_displs[..]);
            let mut receive = PartitionMut::new(&mut all[..], &receive_counts[..], &receive_displs[..]);
            self.world.all_to_all_varcount_into(&send, &mut receive);
        }
        Ok(split(&all, &receive_counts, &receive_displs))
    }
    fn abort(&self, message: &str) -> ! {
        eprintln!("error: rank {} of {} stops every rank: {message}", self.world.rank(), self.world.size());
        self.world.abort(1)
    }
    fn describe(&self) -> String {
        self.description.clone()
    }
    fn node_rank(&self) -> (usize, usize) {
        self.node
    }
}

/// Where each rank's part starts in a gathered buffer.
fn displacements(counts: &[Count]) -> Vec<Count> {
    counts
        .iter()
        .scan(0, |acc, &c| {
            let start = *acc;
            *acc += c;
            Some(start)
        })
        .collect()
}

/// A gathered buffer cut into the ranks' parts.
fn split(all: &[f64], counts: &[Count], displs: &[Count]) -> Vec<Vec<f64>> {
    counts.iter().zip(displs).map(|(&c, &d)| all[d as usize..(d + c) as usize].to_vec()).collect()
}
