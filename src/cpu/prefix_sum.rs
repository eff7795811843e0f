//! Exclusive prefix sum of the cell counts: twin of wgsl/prefix_sum.wgsl.

/// `starts[c]` = sum of `counts[..c]`, and `starts[counts.len()]` = the total, so that cell c's
/// particles are `starts[c]..starts[c + 1]` and any run of cells is one contiguous span.
pub fn prefix_sum(counts: &[u32], starts: &mut [u32]) {
    assert_eq!(starts.len(), counts.len() + 1);
    let mut acc = 0u32;
    for (s, &c) in starts.iter_mut().zip(counts) {
        *s = acc;
        acc += c;
    }
    starts[counts.len()] = acc;
}
