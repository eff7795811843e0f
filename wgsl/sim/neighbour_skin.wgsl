// The neighbour skin (Verlet 1967; docs/performance.md, "Lists that outlast a step"): with a skin
// s the grid's cells are h (1 + s) wide and the neighbour lists hold the candidates within
// h (1 + s) of each particle, both taken at a rebuild, and the particles keep their order in
// between. While no particle has moved s h / 2 or more since the rebuild, two particles within h
// of each other were within h (1 + s) then: the lists and the cells of the rebuild still hold
// every neighbour. After each step this stage marks the step when one has moved that far, and
// the host rebuilds before the next. Twin: src/solver/cpu/neighbour_skin.rs.

//! include shared/common.wgsl
//! array positions: vec4<f32>, read
//! array rebuild_positions: vec4<f32>, read
// Word 0: 1 once a particle has moved s h / 2 or more (cleared before each step).
//! array skin_left: u32, atomic, whole

// The skin s, a fraction of h.
override SKIN: f32 = 0.0;

@compute @workgroup_size(WORKGROUP_SIZE)
fn check_skin(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let i = thread_index(gid, groups);
    if (i < params.fluid_count) {
        let d = positions_at(i).xyz - rebuild_positions_at(i).xyz;
        let reach = 0.5 * SKIN * params.h;
        // Not "greater": a position that is not finite leaves the skin too.
        if (!(dot(d, d) < reach * reach)) {
            atomicMax(&skin_left[0], 1u);
        }
    }
}
