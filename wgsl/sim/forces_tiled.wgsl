// The forces stage with the stencils of a subgroup walked together (shared/tiles.wgsl): the
// pair terms of forces.wgsl, the same sums in the same order as its `forces`, so its twin is
// the same, src/solver/cpu/forces.rs. With NEIGHBOUR_LISTS a subgroup whose particles' lists
// all fit walks those lists instead (shared/neighbour_lists.wgsl): the same pairs in the same
// order. A file of its own since its subgroup operations need an adapter with subgroups, which
// the other stages do not.

//! include sim/forces.wgsl
//! include shared/tiles.wgsl
//! include shared/tiles_walls.wgsl
//! include shared/neighbour_lists.wgsl
//! include shared/list_walk.wgsl

// Lane k's candidate, for every invocation.
fn shuffled_fluid(n: FluidCandidate, k: u32) -> FluidCandidate {
    var u = vec3<f32>(0.0);
    if (reads_velocities()) {
        u = subgroupShuffle(n.u, k);
    }
    var normal = vec3<f32>(0.0);
    if (SURFACE_TENSION) {
        normal = subgroupShuffle(n.n, k);
    }
    return FluidCandidate(subgroupShuffle(n.x, k), u, subgroupShuffle(n.rho, k), subgroupShuffle(n.p, k), normal);
}

alias TileOwn = OwnParticle;
alias TileSums = ForceSums;

fn no_tile_sums() -> TileSums {
    return no_sums();
}

// The fluid candidates b to b + TILE - 1 (this lane's: j), in order.
fn tile_fluid_chunk(sums: ptr<function, ForceSums>, own: OwnParticle, j: u32, b: u32, span: vec2<u32>) {
    let n = fluid_candidate(j, positions_at(j).xyz);
    //! unroll 8 add_fluid_pair(sums, own, shuffled_fluid(n, {k}u), in_span(b + {k}u, span));
}

fn shuffled_wall(n: WallCandidate, k: u32) -> WallCandidate {
    var fields = vec2<f32>(0.0, 1.0);
    if (ADAMI_WALL_PRESSURE) {
        fields = subgroupShuffle(n.fields, k);
    }
    return WallCandidate(subgroupShuffle(n.w, k), fields);
}

fn tile_wall_chunk(sums: ptr<function, ForceSums>, own: OwnParticle, j: u32, b: u32, span: vec2<u32>) {
    let n = wall_candidate(j, wall_positions_at(j));
    //! unroll 8 add_wall_pair(sums, own, shuffled_wall(n, {k}u), in_span(b + {k}u, span));
}

// Candidate j's terms over a list (shared/list_walk.wgsl), in the tiles' order.
fn listed_fluid(sums: ptr<function, ForceSums>, own: OwnParticle, j: u32) {
    add_fluid_pair(sums, own, fluid_candidate(j, positions_at(j).xyz), true);
}

fn listed_wall(sums: ptr<function, ForceSums>, own: OwnParticle, j: u32) {
    add_wall_pair(sums, own, wall_candidate(j, wall_positions_at(j)), true);
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn forces_tiled(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
    @builtin(subgroup_invocation_id) lane: u32,
) {
    let i = thread_index(gid, groups);
    let own = own_particle(tile_particle(i));
    // Each branch finishes its own sums: with one finish after both, lavapipe (Mesa 22.3)
    // compiled the acceleration's sum differently from the stage without lists, one unit in the
    // last place apart (tests/parity/tiles.rs, the scene with planes only).
    if (walks_lists(tile_particle(i))) {
        let sums = list_walk(own, tile_particle(i));
        if (i < params.fluid_count) {
            accelerations_set(i, finish_acceleration(own, sums));
        }
    } else {
        let sums = tile_walk(own, cell_coords(own.x), lane, i < params.fluid_count);
        if (i < params.fluid_count) {
            accelerations_set(i, finish_acceleration(own, sums));
        }
    }
}
