// The tiled density stages' largest density (density_tiled.wgsl, continuity_tiled.wgsl,
// dfsph_factors_tiled.wgsl): the largest over the subgroup, into the status words by one of its
// invocations, in place of shared/density_write.wgsl's workgroup reduction. That one needs two
// workgroup barriers, and lavapipe runs a shader with a barrier as coroutines, one per SIMD
// batch, suspended and resumed at the barrier: on Mesa 26.2 the tiled density stage took 1.3
// times as long as the forces with them, 0.7-0.9 times without (BENCHMARKS.md).

//! include shared/status_max.wgsl

// Every invocation of the subgroup, in uniform control flow, after its offer_density.
fn finish_densities_in_subgroup(lane: u32) {
    let largest = subgroupMax(offered_density_key);
    if (lane == 0u) {
        raise_status_word(STATUS_STEP_MAX_DENSITY, largest);
        raise_status_word(STATUS_MAX_DENSITY, largest);
    }
}
