//! How the ranks of one simulation talk: the [`Communicator`] trait the exchange stage and the
//! global decisions use, and [`LocalGroup`], ranks as threads of one process (the tests run N
//! ranks against one rank with it, without MPI). The MPI implementation is
//! the `wgsph-mpi` crate's (`mpi/src/communicator.rs`), outside this crate. See docs/scale-out.md.

use std::sync::mpsc::{channel, Receiver, Sender};
use std::sync::{Arc, Mutex};

/// The ranks of one simulation, as one of them sees them. Every call is collective: each rank
/// makes the same calls in the same order (the step order guarantees it), so a call never
/// needs a tag. The neighbours' messages are bytes (particles as their bits, in the float type
/// of the run); the collectives' values are `f64`, in which ids and counts below 2^53 travel
/// exactly.
pub trait Communicator: Send + Sync {
    /// This rank, `0..size()`.
    fn rank(&self) -> usize;
    fn size(&self) -> usize;
    /// Sends `to_lower` to rank - 1 and `to_upper` to rank + 1 (nothing past either end of the
    /// rank order) and returns what those ranks sent here: (from the lower, from the upper).
    fn exchange(&self, to_lower: &[u8], to_upper: &[u8]) -> anyhow::Result<(Vec<u8>, Vec<u8>)>;
    /// Every rank's `values`, in rank order: the same result on every rank.
    fn all_gather(&self, values: &[f64]) -> anyhow::Result<Vec<Vec<f64>>>;
    /// Every rank's `values`, in rank order, on rank 0 (`None` on the others).
    fn gather(&self, values: &[f64]) -> anyhow::Result<Option<Vec<Vec<f64>>>>;
    /// Sends `parts[r]` to rank r (one part per rank, this rank's own included) and returns
    /// what every rank sent here, in rank order.
    fn all_to_all(&self, parts: &[Vec<f64>]) -> anyhow::Result<Vec<Vec<f64>>>;
    /// Stops every rank of the simulation with `message` (said by this rank): what a rank that
    /// cannot go on does, so that no other rank waits forever in the next collective.
    fn abort(&self, message: &str) -> !;
    /// The transport and the number of ranks, in words (for the summary).
    fn describe(&self) -> String;
    /// The rank among those on the same machine, and how many ranks that machine runs (for the
    /// choice of an adapter).
    fn node_rank(&self) -> (usize, usize) {
        (self.rank(), self.size())
    }
}

/// How many processes an MPI launcher started, when more than one: Open MPI sets
/// OMPI_COMM_WORLD_SIZE, MPICH and Intel MPI (Hydra) PMI_SIZE, PMIx launchers PMIX_SIZE.
pub fn launched_ranks() -> Option<usize> {
    let var = |name: &str| std::env::var(name).ok().and_then(|v| v.trim().parse::<usize>().ok());
    var("OMPI_COMM_WORLD_SIZE").or_else(|| var("PMI_SIZE")).or_else(|| var("PMIX_SIZE")).filter(|&n| n > 1)
}

/// The ranks' largest of each of `values` (the same on every rank).
pub fn all_max(comm: &dyn Communicator, values: &[f64]) -> anyhow::Result<Vec<f64>> {
    fold_ranks(comm, values, f64::max)
}

/// The ranks' sum of each of `values`, added in rank order (so the same on every rank).
pub fn all_sum(comm: &dyn Communicator, values: &[f64]) -> anyhow::Result<Vec<f64>> {
    fold_ranks(comm, values, |a, b| a + b)
}

fn fold_ranks(comm: &dyn Communicator, values: &[f64], f: fn(f64, f64) -> f64) -> anyhow::Result<Vec<f64>> {
    let all = comm.all_gather(values)?;
    let mut out = all[0].clone();
    for other in &all[1..] {
        anyhow::ensure!(other.len() == out.len(), "the ranks reduced {} and {} values in one collective", out.len(), other.len());
        for (o, v) in out.iter_mut().zip(other) {
            *o = f(*o, *v);
        }
    }
    Ok(out)
}

/// Which rank of which group runs a backend, as a [`crate::solver::BackendChoice`] holds it.
#[derive(Clone)]
pub struct Ranks {
    pub comm: Arc<dyn Communicator>,
    /// Move the slab bounds towards equal particle counts every this many steps (0: never).
    pub balance_every: u64,
}

/// Steps between moves of the slab bounds, by default.
pub const DEFAULT_BALANCE_EVERY: u64 = 100;

impl Ranks {
    pub fn new(comm: Arc<dyn Communicator>) -> Self {
        Ranks { comm, balance_every: DEFAULT_BALANCE_EVERY }
    }
}

impl std::fmt::Debug for Ranks {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "rank {} of {} ({})", self.comm.rank(), self.comm.size(), self.comm.describe())
    }
}

/// Ranks as threads of one process, connected by channels: one [`LocalCommunicator`] per
/// rank, each to be moved into its own thread.
pub struct LocalGroup;

impl LocalGroup {
    /// `size` connected ranks, in rank order.
    #[allow(clippy::new_ret_no_self)]
    pub fn new(size: usize) -> Vec<LocalCommunicator> {
        let size = size.max(1);
        // senders[from][to], receivers[to][from]
        let mut senders: Vec<Vec<Sender<Vec<u8>>>> = (0..size).map(|_| Vec::new()).collect();
        let mut receivers: Vec<Vec<Option<Receiver<Vec<u8>>>>> = (0..size).map(|_| (0..size).map(|_| None).collect()).collect();
        for (from, row) in senders.iter_mut().enumerate() {
            for inbox in receivers.iter_mut() {
                let (s, r) = channel();
                row.push(s);
                inbox[from] = Some(r);
            }
        }
        senders
            .into_iter()
            .zip(receivers)
            .enumerate()
            .map(|(rank, (to, from))| LocalCommunicator {
                rank,
                size,
                to,
                from: from.into_iter().map(|r| Mutex::new(r.expect("every pair has a channel"))).collect(),
            })
            .collect()
    }
}

/// One rank of a [`LocalGroup`].
pub struct LocalCommunicator {
    rank: usize,
    size: usize,
    /// Every message as bytes (the collectives' values as their bits).
    to: Vec<Sender<Vec<u8>>>,
    from: Vec<Mutex<Receiver<Vec<u8>>>>,
}

impl LocalCommunicator {
    fn send_bytes(&self, to: usize, bytes: &[u8]) -> anyhow::Result<()> {
        self.to[to].send(bytes.to_vec()).map_err(|_| anyhow::anyhow!("rank {to} has stopped (rank {} could not send to it)", self.rank))
    }
    fn receive_bytes(&self, from: usize) -> anyhow::Result<Vec<u8>> {
        let inbox = self.from[from].lock().map_err(|_| anyhow::anyhow!("rank {}'s inbox from rank {from} is poisoned", self.rank))?;
        inbox.recv().map_err(|_| anyhow::anyhow!("rank {from} has stopped (rank {} waited for it)", self.rank))
    }
    fn send(&self, to: usize, values: &[f64]) -> anyhow::Result<()> {
        self.send_bytes(to, bytemuck::cast_slice(values))
    }
    fn receive(&self, from: usize) -> anyhow::Result<Vec<f64>> {
        self.receive_bytes(from).map(|bytes| bytemuck::pod_collect_to_vec(&bytes))
    }
}

impl Communicator for LocalCommunicator {
    fn rank(&self) -> usize {
        self.rank
    }
    fn size(&self) -> usize {
        self.size
    }
    fn exchange(&self, to_lower: &[u8], to_upper: &[u8]) -> anyhow::Result<(Vec<u8>, Vec<u8>)> {
        // Channels buffer, so sending first never blocks.
        if self.rank > 0 {
            self.send_bytes(self.rank - 1, to_lower)?;
        }
        if self.rank + 1 < self.size {
            self.send_bytes(self.rank + 1, to_upper)?;
        }
        let lower = if self.rank > 0 { self.receive_bytes(self.rank - 1)? } else { Vec::new() };
        let upper = if self.rank + 1 < self.size { self.receive_bytes(self.rank + 1)? } else { Vec::new() };
        Ok((lower, upper))
    }
    fn all_gather(&self, values: &[f64]) -> anyhow::Result<Vec<Vec<f64>>> {
        for to in (0..self.size).filter(|&r| r != self.rank) {
            self.send(to, values)?;
        }
        (0..self.size).map(|from| if from == self.rank { Ok(values.to_vec()) } else { self.receive(from) }).collect()
    }
    fn gather(&self, values: &[f64]) -> anyhow::Result<Option<Vec<Vec<f64>>>> {
        if self.rank != 0 {
            self.send(0, values)?;
            return Ok(None);
        }
        (0..self.size).map(|from| if from == 0 { Ok(values.to_vec()) } else { self.receive(from) }).collect::<anyhow::Result<Vec<_>>>().map(Some)
    }
    fn all_to_all(&self, parts: &[Vec<f64>]) -> anyhow::Result<Vec<Vec<f64>>> {
        anyhow::ensure!(parts.len() == self.size, "rank {} sent {} parts to {} ranks", self.rank, parts.len(), self.size);
        for to in (0..self.size).filter(|&r| r != self.rank) {
            self.send(to, &parts[to])?;
        }
        (0..self.size).map(|from| if from == self.rank { Ok(parts[from].clone()) } else { self.receive(from) }).collect()
    }
    fn abort(&self, message: &str) -> ! {
        // Threads of one process: the process ends, and with it every rank.
        eprintln!("error: rank {} of {}: {message}", self.rank, self.size);
        std::process::exit(1)
    }
    fn describe(&self) -> String {
        format!("{} ranks as threads of one process", self.size)
    }
}
