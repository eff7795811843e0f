//! Cell binning, step 2 of 4: the exclusive prefix sum of the cell counts, as the GPU computes
//! it: blocks of [`SCAN_BLOCK`] values scanned one by one (`scan_blocks`), the block totals
//! scanned one level up the same way, and added back (`add_block_offsets`). Twin of
//! wgsl/sim/prefix_sum.wgsl; exact, like any order of integer additions, so it equals
//! [`crate::model::kernels::exclusive_scan`].

/// Values per block (the WGSL `SCAN_BLOCK`: two per thread of a 128-thread workgroup).
pub const SCAN_BLOCK: usize = 256;

/// Scans every block of `data` in place (exclusive) and writes each block's total to
/// `block_sums[block]`.
pub fn scan_blocks(data: &mut [u32], block_sums: &mut [u32]) {
    for (block, values) in data.chunks_mut(SCAN_BLOCK).enumerate() {
        let mut acc = 0u32;
        for v in values.iter_mut() {
            let x = *v;
            *v = acc;
            acc += x;
        }
        if let Some(total) = block_sums.get_mut(block) {
            *total = acc;
        }
    }
}

/// Adds the scanned total of the blocks before it to every value of each block.
pub fn add_block_offsets(data: &mut [u32], block_sums: &[u32]) {
    for (values, &offset) in data.chunks_mut(SCAN_BLOCK).zip(block_sums) {
        for v in values {
            *v += offset;
        }
    }
}

/// `starts[c]` = sum of `counts[..c]`, and `starts[counts.len()]` = the total, so that cell c's
/// particles are `starts[c]..starts[c + 1]` and any run of cells is one contiguous span: the
/// multi-level scan of `counts` with a zero appended.
pub fn prefix_sum(counts: &[u32], starts: &mut [u32]) {
    assert_eq!(starts.len(), counts.len() + 1);
    starts[..counts.len()].copy_from_slice(counts);
    starts[counts.len()] = 0;
    scan_in_place(starts);
}

fn scan_in_place(data: &mut [u32]) {
    let mut block_sums = vec![0u32; data.len().div_ceil(SCAN_BLOCK).max(1)];
    scan_blocks(data, &mut block_sums);
    if block_sums.len() > 1 {
        scan_in_place(&mut block_sums);
        add_block_offsets(data, &block_sums);
    }
}
