// Cell binning, step 4 of 4: each particle's slot in its cell is the number of particles of the
// cell with a smaller current index (so the order inside a cell never depends on thread timing,
// as in a stable counting sort), and its state is gathered into that slot.
// Twin of src/cpu/reorder.rs.

@group(0) @binding(1) var<storage, read> keys: array<u32>;
@group(0) @binding(2) var<storage, read> starts: array<u32>;
@group(0) @binding(3) var<storage, read> unordered: array<u32>;
@group(0) @binding(4) var<storage, read> positions_in: array<vec4<f32>>;
@group(0) @binding(5) var<storage, read> velocities_in: array<vec4<f32>>;
@group(0) @binding(6) var<storage, read> ids_in: array<u32>;
@group(0) @binding(7) var<storage, read_write> positions_out: array<vec4<f32>>;
@group(0) @binding(8) var<storage, read_write> velocities_out: array<vec4<f32>>;
@group(0) @binding(9) var<storage, read_write> ids_out: array<u32>;

@compute @workgroup_size(WORKGROUP_SIZE)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = thread_index(gid, groups);
    if (i >= params.fluid_count) {
        return;
    }
    let k = keys[i];
    let begin = starts[k];
    let end = starts[k + 1u];
    var rank = 0u;
    for (var s = begin; s < end; s++) {
        rank += select(0u, 1u, unordered[s] < i);
    }
    let dest = begin + rank;
    positions_out[dest] = positions_in[i];
    velocities_out[dest] = velocities_in[i];
    ids_out[dest] = ids_in[i];
}
