// Cell binning, step 3 of 4: every particle's index goes to its cell's span of the sorted order.
// Twin of src/solver/cpu/bin_scatter.rs (whose stable order reorder.wgsl restores).

//! include shared/common.wgsl
//! array keys: u32, read
//! array ranks: u32, read
//! array starts: u32, read
//! array unordered: u32, read_write

@compute @workgroup_size(WORKGROUP_SIZE)
fn bin_scatter(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = thread_index(gid, groups);
    if (i >= params.fluid_count) {
        return;
    }
    unordered_set(starts_at(keys_at(i)) + ranks_at(i), i);
}
