// The neighbour skin's check (neighbour_skin.wgsl) on an adapter with subgroups: each subgroup
// gathers its particles' extent first and one of its invocations offers it.
// The same words as `check_skin`; twin: src/solver/cpu/neighbour_skin.rs.

//! include sim/neighbour_skin.wgsl

// Beyond every displacement a step can make: what a lane without a particle offers.
const NO_DISPLACEMENT: f32 = 3.0e38;

@compute @workgroup_size(WORKGROUP_SIZE)
fn check_skin_subgroups(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
    @builtin(subgroup_invocation_id) lane: u32,
) {
    let i = thread_index(gid, groups);
    let has_particle = i < params.fluid_count;
    var d = vec3<f32>(0.0);
    if (has_particle) {
        d = displacement(i);
    }
    let lo = subgroupMin(select(vec3<f32>(NO_DISPLACEMENT), d, has_particle));
    let hi = subgroupMax(select(vec3<f32>(-NO_DISPLACEMENT), d, has_particle));
    let any_particle = subgroupAny(has_particle);
    if (lane == 0u && any_particle) {
        offer_extent(lo, hi);
    }
}
