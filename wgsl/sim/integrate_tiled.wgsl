// The integration where the neighbour stages run in subgroup tiles (a software adapter's
// subgroups of 8): integrate.wgsl's `integrate`, the same state written, with the step's largest
// speed taken over each subgroup instead of the workgroup. The workgroup's reduction needs two
// barriers, and lavapipe runs a shader with a barrier as coroutines that suspend and resume
// there (shared/density_write_tiled.wgsl; BENCHMARKS.md). Its twin is the same,
// src/solver/cpu/integrate.rs. A file of its own since its subgroup operation needs an adapter
// with subgroups, which integrate.wgsl does not.

//! include sim/integrate.wgsl
//! include shared/status_max.wgsl

@compute @workgroup_size(WORKGROUP_SIZE)
fn integrate_tiled(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
    @builtin(subgroup_invocation_id) lane: u32,
) {
    let i = thread_index(gid, groups);
    var speed = 0.0;
    if (i < params.fluid_count) {
        speed = advance_particle(i, accelerations_at(i), step_dt());
    }
    // The speeds' bits order like them (infinity above every finite speed).
    let largest = subgroupMax(bitcast<u32>(speed));
    if (lane == 0u) {
        raise_status_word(STATUS_STEP_MAX_SPEED, largest);
    }
}
