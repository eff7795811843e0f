//! Gathers the particle state into cell order: twin of wgsl/reorder.wgsl.

/// `out[j] = input[sorted[j]]` for one per-particle array.
pub fn reorder<T: Copy + Send + Sync>(sorted: &[u32], input: &[T], out: &mut Vec<T>) {
    out.clear();
    out.extend(sorted.iter().map(|&i| input[i as usize]));
}
