//! Cell binning, step 4 of 4: the particle state gathered into cell order. Twin of
//! wgsl/sim/reorder.wgsl.

/// `out[j] = input[sorted[j]]` for one per-particle array.
pub fn reorder<T: Copy + Send + Sync>(sorted: &[u32], input: &[T], out: &mut Vec<T>) {
    out.clear();
    out.extend(sorted.iter().map(|&i| input[i as usize]));
}
