// The continuity density with the stencils of a subgroup walked together (shared/tiles.wgsl):
// the pair terms of continuity.wgsl, the same sums in the same order as its
// `continuity_density`, so its twin is the same, src/solver/cpu/continuity.rs. A file of its own
// since its subgroup operations need an adapter with subgroups, which the other stages do not.

//! include sim/continuity.wgsl
//! include shared/tiles.wgsl
//! include shared/tiles_walls.wgsl

alias TileOwn = RateOwn;
alias TileSums = RateSums;

fn no_tile_sums() -> TileSums {
    return RateSums(0.0, 0.0, 0.0);
}

// The fluid candidates b to b + TILE - 1 (this lane's: j), in order.
fn tile_fluid_chunk(sums: ptr<function, RateSums>, own: RateOwn, j: u32, b: u32, span: vec2<u32>) {
    let xj = positions_at(j).xyz;
    let vj = velocities_at(j);
    //! unroll 8 add_fluid_rate(sums, own, subgroupShuffle(xj, {k}u), subgroupShuffle(vj, {k}u), in_span(b + {k}u, span));
}

fn tile_wall_chunk(sums: ptr<function, RateSums>, own: RateOwn, j: u32, b: u32, span: vec2<u32>) {
    let w = wall_positions_at(j);
    //! unroll 8 add_wall_rate(sums, own, subgroupShuffle(w, {k}u), in_span(b + {k}u, span));
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn continuity_tiled(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
    @builtin(subgroup_invocation_id) lane: u32,
) {
    reduce_begin(lid);
    let i = thread_index(gid, groups);
    let own = rate_own(tile_particle(i));
    let sums = tile_walk(own, cell_coords(own.x), lane, i < params.fluid_count);
    if (i < params.fluid_count) {
        set_carried_density(i, finish_rate(sums));
    }
    finish_densities(lid);
}
