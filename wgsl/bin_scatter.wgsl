// Cell binning, step 3 of 4: every particle's index goes to its cell's span of the sorted order.
// Twin of src/cpu/bin_scatter.rs (whose stable order reorder.wgsl restores).

@group(0) @binding(1) var<storage, read> keys: array<u32>;
@group(0) @binding(2) var<storage, read> ranks: array<u32>;
@group(0) @binding(3) var<storage, read> starts: array<u32>;
@group(0) @binding(4) var<storage, read_write> unordered: array<u32>;

@compute @workgroup_size(WORKGROUP_SIZE)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = thread_index(gid, groups);
    if (i >= params.fluid_count) {
        return;
    }
    unordered[starts[keys[i]] + ranks[i]] = i;
}
