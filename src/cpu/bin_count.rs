//! Cell key of every particle and the particle count of every cell: twin of wgsl/bin_count.wgsl.

use super::common::{cell_coords, GridR};
use crate::real::{Real, V3};

/// Writes `keys[i]` for each particle and accumulates `counts[key]` (counts must start at zero).
pub fn bin_count<R: Real>(grid: &GridR<R>, positions: &[V3<R>], keys: &mut [u32], counts: &mut [u32]) {
    for (i, p) in positions.iter().enumerate() {
        let k = grid.key(cell_coords(grid, *p));
        keys[i] = k;
        counts[k as usize] += 1;
    }
}
