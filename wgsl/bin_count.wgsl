// Cell binning, step 1 of 4: cell key of every particle and the count of every cell.
// Twin of src/cpu/bin_count.rs. The rank a particle gets from the atomic counter depends on
// thread timing; reorder.wgsl replaces it by a deterministic one.

@group(0) @binding(1) var<storage, read> positions: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read_write> keys: array<u32>;
@group(0) @binding(3) var<storage, read_write> ranks: array<u32>;
@group(0) @binding(4) var<storage, read_write> counts: array<atomic<u32>>;

@compute @workgroup_size(WORKGROUP_SIZE)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = thread_index(gid, groups);
    if (i >= params.fluid_count) {
        return;
    }
    let k = cell_key(cell_coords(positions[i].xyz));
    keys[i] = k;
    ranks[i] = atomicAdd(&counts[k], 1u);
}
