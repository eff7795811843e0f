// DFSPH's divergence solve passes with the stencils of a subgroup walked together
// (shared/dfsph_tiles.wgsl): the same sums in the same order as dfsph_divergence.wgsl's, so the twin is the
// same, src/solver/cpu/dfsph_divergence.rs. A file of its own since its subgroup operations need an adapter
// with subgroups, which the other stages do not.

//! include sim/dfsph_divergence.wgsl
//! include shared/tiles.wgsl
//! include shared/dfsph_tiles.wgsl

@compute @workgroup_size(WORKGROUP_SIZE)
fn divergence_rate_tiled(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
    @builtin(subgroup_invocation_id) lane: u32,
) {
    error_begin(lid);
    let i = thread_index(gid, groups);
    let rate = tiled_density_rate(i, lane);
    if (i < params.fluid_count) {
        set_divergence_stiffness(i, positions_at(i).w, rate);
    }
    error_end(lid);
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn divergence_apply_tiled(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
    @builtin(subgroup_invocation_id) lane: u32,
) {
    let i = thread_index(gid, groups);
    let push = tiled_stiffness_push(i, lane);
    if (i < params.fluid_count) {
        apply_divergence_push(i, push);
    }
}
