// Cell binning, step 1 of 4: cell key of every particle and the count of every cell.
// Twin of src/solver/cpu/bin_count.rs. The rank a particle gets from the atomic counter depends on
// thread timing; reorder.wgsl replaces it by a deterministic one.

//! include shared/common.wgsl
//! array positions: vec4<f32>, read
//! array keys: u32, read_write
//! array ranks: u32, read_write
//! array counts: u32, atomic

@compute @workgroup_size(WORKGROUP_SIZE)
fn bin_count(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = thread_index(gid, groups);
    if (i >= params.fluid_count) {
        return;
    }
    let k = cell_key(cell_coords(positions_at(i).xyz));
    keys_set(i, k);
    ranks_set(i, counts_add(k, 1u));
}
