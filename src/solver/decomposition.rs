//! The domain cut into slabs, one per rank: whole layers of grid cells across the grid's axis
//! of most cells (the domain's longest), so that faces are small and slabs can be thin. See
//! docs/scale-out.md.

/// The axis the slabs cut: the one with the most cell layers; on a tie the later axis, whose
/// layers are longer runs of cell keys (the key is `x + nx (y + ny z)`; slabs across z are one
/// contiguous run each).
pub fn slab_axis(dims: [u32; 3]) -> usize {
    let mut axis = 2;
    for a in [1, 0] {
        if dims[a] > dims[axis] {
            axis = a;
        }
    }
    axis
}

/// The runs of cell keys of the cells whose layer along `axis` lies in `layers`, in key order
/// (neighbouring runs joined): a slab's cells, or the cells next to a face.
pub fn cell_runs(dims: [u32; 3], axis: usize, layers: std::ops::Range<u32>) -> Vec<std::ops::Range<usize>> {
    let mut lo = [0u32; 3];
    let mut hi = dims;
    lo[axis] = layers.start;
    hi[axis] = layers.end;
    let key = |x: u32, y: u32, z: u32| x as usize + dims[0] as usize * (y as usize + dims[1] as usize * z as usize);
    let mut runs: Vec<std::ops::Range<usize>> = Vec::new();
    if lo.iter().zip(&hi).any(|(a, b)| a >= b) {
        return runs;
    }
    for z in lo[2]..hi[2] {
        for y in lo[1]..hi[1] {
            let run = key(lo[0], y, z)..key(hi[0] - 1, y, z) + 1;
            match runs.last_mut() {
                Some(last) if last.end == run.start => last.end = run.end,
                _ => runs.push(run),
            }
        }
    }
    runs
}

/// Cell layers of ghosts on each side of a slab. Two, so that a ghost next to the face has its
/// whole neighbourhood here: its density is computed locally, and the forces on the rank's own
/// particles need one exchange per step (positions, velocities and carried densities) instead
/// of a second one for the ghosts' densities and pressures.
pub const HALO_LAYERS: u32 = 2;

/// The ghost layers a scene needs: [`HALO_LAYERS`], and one more where the forces on an own
/// particle read a value its neighbours sum over their own neighbourhood from densities:
/// Adami's wall pressure, where a wall particle next to the face takes its pressure from the
/// fluid one layer beyond it (Adami et al. 2012, Eq. 27), and Akinci's surface tension, whose
/// curvature term reads a fluid neighbour's normal n_j = h sum_k m_k / rho_k grad W_jk (Akinci
/// et al. 2013). In both the densities one layer beyond the inner ghosts must be whole, which
/// needs the layer beyond that.
pub fn halo_layers(adami_walls: bool, surface_tension: bool) -> u32 {
    HALO_LAYERS + (adami_walls || surface_tension) as u32
}

/// The slabs: rank r owns the cell layers `bounds[r]..bounds[r + 1]`; `bounds[0]` is 0 and the
/// last bound is the number of layers. Every slab is at least `halo` layers thick (the ghost
/// layers on each side), so the ghosts a rank needs all come from its two neighbours.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Slabs {
    pub bounds: Vec<u32>,
    pub halo: u32,
}

impl Slabs {
    /// Slabs holding as equal counts as whole layers allow, for `layer_counts[l]` particles in
    /// layer l, over `ranks` ranks, with `halo` ghost layers on each side. Errs when the grid
    /// has fewer layers than the ranks need.
    pub fn balanced(layer_counts: &[u64], ranks: usize, halo: u32) -> anyhow::Result<Slabs> {
        let layers = layer_counts.len() as u64;
        let need = halo as u64 * ranks as u64;
        anyhow::ensure!(
            layers >= need,
            "the grid has {layers} cell layers along its longest axis (domain length / smoothing_length); {ranks} ranks need at least {need} ({halo} per rank): use fewer ranks or a smaller smoothing_length"
        );
        Ok(Slabs { bounds: equal_cuts(layer_counts, ranks, halo, |_| (0, u32::MAX)), halo })
    }

    /// The slabs moved towards equal counts: each bound goes to the equal-count cut but stays
    /// inside the two slabs it separates now, so that every particle's new owner is its owner
    /// or a neighbour of it (one migration moves it).
    pub fn rebalanced(&self, layer_counts: &[u64]) -> Slabs {
        let old = &self.bounds;
        Slabs { bounds: equal_cuts(layer_counts, self.ranks(), self.halo, |i| (old[i - 1] + 1, old[i + 1] - 1)), halo: self.halo }
    }

    pub fn ranks(&self) -> usize {
        self.bounds.len() - 1
    }
    pub fn layers(&self) -> u32 {
        *self.bounds.last().unwrap_or(&0)
    }
    /// The layers of rank `r`'s slab.
    pub fn layers_of(&self, r: usize) -> std::ops::Range<u32> {
        self.bounds[r]..self.bounds[r + 1]
    }
    /// The rank whose slab holds `layer`.
    pub fn owner(&self, layer: u32) -> usize {
        // The first bound above the layer closes its slab.
        self.bounds[1..].partition_point(|&b| b <= layer).min(self.ranks() - 1)
    }
}

/// Bounds for `ranks` slabs over `layer_counts`, each at the first layer whose running count
/// reaches its share, kept inside `limits(i)` and leaving every slab `halo` layers thick.
fn equal_cuts(layer_counts: &[u64], ranks: usize, halo: u32, limits: impl Fn(usize) -> (u32, u32)) -> Vec<u32> {
    let layers = layer_counts.len() as u32;
    let total: u64 = layer_counts.iter().sum();
    let mut running = Vec::with_capacity(layer_counts.len() + 1);
    running.push(0u64);
    for c in layer_counts {
        running.push(running.last().copied().unwrap_or(0) + c);
    }
    let mut bounds = vec![0u32; ranks + 1];
    bounds[ranks] = layers;
    for i in 1..ranks {
        // The first cut at or past i/ranks of the particles (exact in integers).
        let target = |b: usize| running[b] as u128 * ranks as u128 >= total as u128 * i as u128;
        let ideal = (0..=layers as usize).find(|&b| target(b)).unwrap_or(layers as usize) as u32;
        let (lo, hi) = limits(i);
        let lo = lo.max(bounds[i - 1] + halo);
        let hi = hi.min(layers - halo * (ranks - i) as u32);
        bounds[i] = ideal.clamp(lo, hi.max(lo));
    }
    bounds
}

/// What the exchange measured on one rank.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RankStats {
    /// Seconds in the exchange stage and the per-step collectives.
    pub exchange_seconds: f64,
    /// Particles this rank sent to a neighbour because they left its slab.
    pub migrated: u64,
    /// Ghosts held after the last exchange.
    pub ghosts: usize,
    /// Times the slab bounds were moved.
    pub rebalances: u64,
    /// The largest particle count of a rank over the mean, at the last balance check (or at
    /// the start).
    pub last_imbalance: f64,
    /// The largest such ratio seen so far.
    pub max_imbalance: f64,
    /// On a device: steps whose particles stayed on it (src/solver/cpu/resident_steps.rs).
    pub resident_steps: u64,
    /// On a device: bytes of particles that crossed between the host and the device, both ways.
    pub bus_bytes: u64,
    /// On a device: seconds in its calls (uploads, steps, read-backs and the waits for them),
    /// less the solves' exchanges across ranks inside them (counted in `exchange_seconds`).
    pub device_seconds: f64,
}

/// One rank's part of a simulation across ranks, as the backend reports it.
#[derive(Clone, Debug, PartialEq)]
pub struct RankReport {
    pub rank: usize,
    pub ranks: usize,
    /// The communicator in words.
    pub transport: String,
    /// The axis the slabs cut (0 x, 1 y, 2 z) and the slab bounds in cell layers.
    pub axis: usize,
    pub bounds: Vec<u32>,
    /// The particles this rank owns now (ghosts left out).
    pub own_particles: usize,
    /// The wall particles it holds: those near its slab.
    pub walls: usize,
    /// Its place among the ranks of its machine, and how many run there.
    pub node_rank: usize,
    pub node_ranks: usize,
    /// The CPU threads it computes with.
    pub threads: usize,
    /// The device it computes on, in words (the CPU path's threads, or a GPU adapter and why
    /// this rank took it).
    pub adapter: String,
    pub stats: RankStats,
}

/// The largest count over the mean (1 when perfectly balanced; 0 without particles).
pub fn imbalance(counts: &[u64]) -> f64 {
    let total: u64 = counts.iter().sum();
    if total == 0 {
        return 0.0;
    }
    let mean = total as f64 / counts.len() as f64;
    *counts.iter().max().unwrap_or(&0) as f64 / mean
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn balanced_slabs_cut_equal_counts_and_keep_the_halo_thickness() {
        let counts = vec![10u64; 12];
        let s = Slabs::balanced(&counts, 3, HALO_LAYERS).unwrap();
        assert_eq!(s.bounds, vec![0, 4, 8, 12]);
        // All particles in the two lowest layers: the other slabs are as thin as allowed, and
        // empty.
        let mut low = vec![0u64; 12];
        low[0] = 50;
        low[1] = 50;
        let s = Slabs::balanced(&low, 4, HALO_LAYERS).unwrap();
        assert_eq!(s.bounds, vec![0, 2, 4, 6, 12]);
        assert_eq!((s.owner(0), s.owner(1), s.owner(2), s.owner(5), s.owner(6), s.owner(11)), (0, 0, 1, 2, 3, 3));
        let e = Slabs::balanced(&counts, 7, HALO_LAYERS).unwrap_err().to_string();
        assert!(e.contains("12 cell layers") && e.contains("7 ranks need at least 14"), "{e}");
    }

    #[test]
    fn the_longest_axis_is_cut_and_its_cells_are_found_as_runs_of_keys() {
        assert_eq!((slab_axis([43, 28, 6]), slab_axis([5, 5, 5]), slab_axis([5, 9, 9])), (0, 2, 2));
        let dims = [4, 3, 2];
        // Across z: one run.
        assert_eq!(cell_runs(dims, 2, 1..2), vec![12..24]);
        // Across x: one run per row of x.
        assert_eq!(cell_runs(dims, 0, 1..3), vec![1..3, 5..7, 9..11, 13..15, 17..19, 21..23]);
        // Across y: full rows join.
        assert_eq!(cell_runs(dims, 1, 0..2), vec![0..8, 12..20]);
        assert!(cell_runs(dims, 0, 2..2).is_empty());
    }

    #[test]
    fn rebalancing_moves_each_bound_no_further_than_its_neighbouring_slabs() {
        let s = Slabs { bounds: vec![0, 2, 4, 6, 20], halo: HALO_LAYERS };
        let counts = vec![5u64; 20];
        let once = s.rebalanced(&counts);
        // Every new bound lies strictly inside the two old slabs it separates.
        for i in 1..4 {
            assert!(once.bounds[i] > s.bounds[i - 1] && once.bounds[i] < s.bounds[i + 1], "{:?} -> {:?}", s.bounds, once.bounds);
            assert!(once.bounds[i] >= once.bounds[i - 1] + HALO_LAYERS);
        }
        // Repeated, the bounds reach the equal cut.
        let mut b = s;
        for _ in 0..20 {
            b = b.rebalanced(&counts);
        }
        assert_eq!(b.bounds, vec![0, 5, 10, 15, 20]);
        assert!((imbalance(&[10, 10, 10, 10]) - 1.0).abs() < 1e-12 && (imbalance(&[40, 0, 0, 0]) - 4.0).abs() < 1e-12);
    }
}
