// Cell binning, step 4 of 4: each particle's slot in its cell is the number of particles of the
// cell with a smaller current index (so the order inside a cell never depends on thread timing,
// as in a stable counting sort), and its state is gathered into that slot.
//
// `reorder_rank` writes every particle's slot into `dest`; `reorder` then gathers one state
// array by it and runs once for the positions and once for the velocities. Two gathers let the
// state be gathered into a buffer that the first has just freed (src/solver/gpu/buffers.rs,
// `StateLayout::InPlace`); `dest` lives where nothing else is kept during the binning (the w of
// the velocities when density is summed, or the densities' array). The particle's original
// index travels in the w component of its position (as u32 bits), so it needs no array of its
// own.
// Twin of src/solver/cpu/reorder.rs.

//! include shared/common.wgsl
// Each entry point binds only its own arrays (the others are optional and left out): a gather
// may write the buffer the cell keys and slots lived in. `gathered_in` is read_write only because
// the gather of the velocities may read `dest` from the same buffer, which the rank writes (one
// buffer may not be bound read-only and read_write in one dispatch).
//! array keys: u32, read, optional
//! array starts: u32, read
//! array unordered: u32, read, optional
//! array dest: u32, read_write
//! array gathered_in: vec4<f32>, read_write, optional
//! array gathered_out: vec4<f32>, read_write, optional

@compute @workgroup_size(WORKGROUP_SIZE)
fn reorder_rank(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
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
    dest_set(i, begin + rank);
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn reorder(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = thread_index(gid, groups);
    if (i >= params.fluid_count) {
        return;
    }
    gathered_out_set(dest_at(i), gathered_in_at(i));
}
