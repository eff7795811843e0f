// Cell binning, step 4 of 4: each particle's slot in its cell is the number of particles of the
// cell with a smaller current index (so the order inside a cell never depends on thread timing,
// as in a stable counting sort), and one of its state arrays is gathered into that slot; the
// step dispatches it once for the positions and once for the velocities, which lets the state
// be gathered into a buffer that the first dispatch has just freed (src/solver/gpu/buffers.rs,
// `StateLayout::InPlace`). The particle's original index travels in the w component of its
// position (as u32 bits), so it needs no array of its own.
// Twin of src/solver/cpu/reorder.rs.

//! include shared/common.wgsl
//! array keys: u32, read
//! array starts: u32, read
//! array unordered: u32, read
//! array gathered_in: vec4<f32>, read
//! array gathered_out: vec4<f32>, read_write

@compute @workgroup_size(WORKGROUP_SIZE)
fn reorder(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = thread_index(gid, groups);
    if (i >= params.fluid_count) {
        return;
    }
    let k = keys_at(i);
    let begin = starts_at(k);
    let end = starts_at(k + 1u);
    var rank = 0u;
    for (var s = begin; s < end; s++) {
        rank += select(0u, 1u, unordered_at(s) < i);
    }
    gathered_out_set(begin + rank, gathered_in_at(i));
}
