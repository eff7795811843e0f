//! Counting-sort scatter: twin of wgsl/bin_scatter.wgsl (with the in-cell ordering of
//! wgsl/reorder.wgsl). Stable: inside a cell, particles keep their current order.

/// `sorted[j]` = index of the particle that goes to slot j of the cell-ordered arrays.
pub fn bin_scatter(keys: &[u32], starts: &[u32], sorted: &mut [u32]) {
    let mut cursor: Vec<u32> = starts[..starts.len() - 1].to_vec();
    for (i, &k) in keys.iter().enumerate() {
        let slot = &mut cursor[k as usize];
        sorted[*slot as usize] = i as u32;
        *slot += 1;
    }
}
