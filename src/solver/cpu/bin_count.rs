//! Cell binning, step 1 of 4: the cell key of every particle and the count of every cell. Twin
//! of wgsl/sim/bin_count.wgsl (whose atomic ranks the CPU needs not: it scatters in order).

use crate::model::kernels::count_cells;
use crate::model::params::Grid;
use crate::model::real::{Real, V3};

/// Writes `keys[i]` for each particle and accumulates `counts[key]` (counts must start at zero).
pub fn bin_count<R: Real>(grid: &Grid<R>, positions: &[V3<R>], keys: &mut [u32], counts: &mut [u32]) {
    count_cells(grid, positions, keys, counts);
}
