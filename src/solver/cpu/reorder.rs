//! Cell binning, step 4 of 4: the particle state gathered into cell order. Twin of
//! wgsl/sim/reorder.wgsl (`reorder_rank` and `reorder`).

/// `dest[i]` = the slot particle `i` goes to: the inverse of `sorted`, which the GPU counts from
/// the unordered slots of the particle's cell.
pub fn reorder_rank(sorted: &[u32], dest: &mut Vec<u32>) {
    dest.clear();
    dest.resize(sorted.len(), 0);
    for (slot, &i) in sorted.iter().enumerate() {
        dest[i as usize] = slot as u32;
    }
}

/// `out[j] = input[sorted[j]]` for one per-particle array.
pub fn reorder<T: Copy + Send + Sync>(sorted: &[u32], input: &[T], out: &mut Vec<T>) {
    out.clear();
    out.extend(sorted.iter().map(|&i| input[i as usize]));
}
