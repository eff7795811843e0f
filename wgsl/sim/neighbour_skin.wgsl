// The neighbour skin (Verlet 1967; docs/performance.md, "Lists that outlast a step"): with a skin
// s the grid's cells are h (1 + s) wide and the neighbour lists hold the candidates within
// h (1 + s) of each particle, both taken at a rebuild, and the particles keep their order in
// between. Two fluid particles within h of each other now were within h + |d_i - d_j| then
// (d: a particle's displacement since the rebuild), and a fluid particle within h of a wall
// particle, which does not move, within h + |d_i|. So the lists and the rebuild's cells hold
// every neighbour while every |d_i| < s h and the box bounding all the displacements has a
// diagonal under s h (|d_i - d_j| is at most that diagonal): a block that moves as one keeps its
// lists, where a test of |d_i| against s h / 2 alone would rebuild. After each step this stage
// gathers both, and the host rebuilds before the next step where either reaches s h (less a
// margin, SKIN_MARGIN). Twin: src/solver/cpu/neighbour_skin.rs.

//! include shared/common.wgsl
//! array positions: vec4<f32>, read
//! array rebuild_positions: vec4<f32>, read
// Word 0: 1 once a particle has moved s h or more, or is not finite; words 1-3 the largest
// key of -d per axis (so the smallest d), words 4-6 the largest key of d (cleared before each
// step; 0 is below every key a number has).
//! array skin_left: u32, atomic, whole

// The skin s, a fraction of h, with the margin the host's test keeps.
override SKIN: f32 = 0.0;

// A key that orders as the float does (the sign bit flips the rest for negatives).
fn order_key(v: f32) -> u32 {
    let b = bitcast<u32>(v);
    return select(b | 0x80000000u, ~b, (b & 0x80000000u) != 0u);
}

// Particle i's displacement since the rebuild, marking the step where it reaches the skin.
fn displacement(i: u32) -> vec3<f32> {
    let d = positions_at(i).xyz - rebuild_positions_at(i).xyz;
    let reach = SKIN * params.h;
    // Not "greater": a position that is not finite leaves the skin too.
    if (!(dot(d, d) < reach * reach)) {
        atomicMax(&skin_left[0], 1u);
    }
    return d;
}

// Offers displacement d to the box's words. The keys only grow, so a key at or below the
// word's is not offered: after the first workgroups almost every offer is a plain load, not an
// atomic write that the other cores must wait for.
fn offer_displacement(d: vec3<f32>) {
    for (var axis = 0u; axis < 3u; axis++) {
        offer_key(1u + axis, order_key(-d[axis]));
        offer_key(4u + axis, order_key(d[axis]));
    }
}

fn offer_key(word: u32, key: u32) {
    if (key > atomicLoad(&skin_left[word])) {
        atomicMax(&skin_left[word], key);
    }
}

// Each invocation offers its particle's displacement. (Gathering a subgroup's extent first, so
// that one invocation in eight reads the shared words, measured no faster on lavapipe.)
@compute @workgroup_size(WORKGROUP_SIZE)
fn check_skin(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let i = thread_index(gid, groups);
    if (i < params.fluid_count) {
        offer_displacement(displacement(i));
    }
}
