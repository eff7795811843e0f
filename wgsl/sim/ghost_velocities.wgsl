// DFSPH across ranks: after a velocity change of the solves, the velocities of the particles a
// rank sends to its neighbours as ghosts are gathered into a compact array, and the velocities
// their owners sent are scattered onto the rank's ghosts, so that only the face layers cross
// the bus (src/solver/gpu/dfsph_ranks.rs). Twin of src/solver/cpu/ghost_velocities.rs.

//! include shared/common.wgsl
//! array velocities: vec4<f32>, read_write
// Words 0 and 1: how many slots to gather and to scatter; from word 2 the slots to gather, then
// the slots to scatter.
//! array ghost_slots: u32, read
// The gathered velocities, then (written by the host) the velocities to scatter, from 0 again.
//! array ghost_values: vec4<f32>, read_write

@compute @workgroup_size(WORKGROUP_SIZE)
fn gather_ghost_velocities(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let k = thread_index(gid, groups);
    if (k >= ghost_slots_at(0u)) {
        return;
    }
    ghost_values_set(k, velocities_at(ghost_slots_at(2u + k)));
}

// Each ghost takes its owner's velocity; its w (another quantity the state keeps there) stays.
@compute @workgroup_size(WORKGROUP_SIZE)
fn scatter_ghost_velocities(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let k = thread_index(gid, groups);
    if (k >= ghost_slots_at(1u)) {
        return;
    }
    let i = ghost_slots_at(2u + ghost_slots_at(0u) + k);
    velocities_set(i, vec4<f32>(ghost_values_at(k).xyz, velocities_at(i).w));
}
