//! Cell binning, step 3 of 4: every particle's index goes to its cell's span of the sorted
//! order. Twin of wgsl/sim/bin_scatter.wgsl together with the in-cell order that
//! wgsl/sim/reorder.wgsl restores: stable, so inside a cell particles keep their current order.

use crate::model::kernels::scatter_by_cell;

/// `sorted[j]` = index of the particle that goes to slot j of the cell-ordered arrays.
pub fn bin_scatter(keys: &[u32], starts: &[u32], sorted: &mut [u32]) {
    scatter_by_cell(keys, starts, sorted);
}
