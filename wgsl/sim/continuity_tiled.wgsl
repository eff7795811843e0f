// The continuity density with the stencils of a subgroup walked together (shared/tiles.wgsl):
// the pair terms of continuity.wgsl, the same sums in the same order as its
// `continuity_density`, so its twin is the same, src/solver/cpu/continuity.rs. With
// NEIGHBOUR_LISTS it also records each particle's neighbours for the forces
// (shared/neighbour_lists.wgsl); with a neighbour skin, built with RECORD_LISTS false for the
// steps between rebuilds, it walks the lists of the last rebuild instead
// (shared/list_walk.wgsl). A file of its own since its subgroup operations need an
// adapter with subgroups, which the other stages do not.

//! include sim/continuity.wgsl
//! include shared/tiles.wgsl
//! include shared/density_write_tiled.wgsl
//! include shared/tiles_walls.wgsl
//! include shared/neighbour_lists.wgsl
//! include shared/list_walk.wgsl

// What a particle brings to its pairs, and its index (fluid_count or more for an invocation
// without one).
struct TileOwn {
    rate: RateOwn,
    i: u32,
}

struct TileSums {
    rate: RateSums,
    list: ListCounts,
}

fn no_tile_sums() -> TileSums {
    return TileSums(RateSums(0.0, 0.0, 0.0), ListCounts(0u, 0u));
}

// The fluid candidates b to b + TILE - 1 (this lane's: j), in order; with lists, the chunk
// recorded.
fn tile_fluid_chunk(sums: ptr<function, TileSums>, own: TileOwn, j: u32, b: u32, span: vec2<u32>) {
    let xj = positions_at(j).xyz;
    let vj = velocities_at(j);
    var rate = (*sums).rate;
    //! unroll 8 add_fluid_rate(&rate, own.rate, subgroupShuffle(xj, {k}u), subgroupShuffle(vj, {k}u), in_span(b + {k}u, span));
    (*sums).rate = rate;
    (*sums).list = record_shuffled_chunk((*sums).list, own.i, own.rate.x, xj, b, span, false);
}

fn tile_wall_chunk(sums: ptr<function, TileSums>, own: TileOwn, j: u32, b: u32, span: vec2<u32>) {
    let w = wall_positions_at(j);
    var rate = (*sums).rate;
    //! unroll 8 add_wall_rate(&rate, own.rate, subgroupShuffle(w, {k}u), in_span(b + {k}u, span));
    (*sums).rate = rate;
    (*sums).list = record_shuffled_chunk((*sums).list, own.i, own.rate.x, w.xyz, b, span, true);
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn continuity_tiled(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
    @builtin(subgroup_invocation_id) lane: u32,
) {
    let i = thread_index(gid, groups);
    let own = rate_own(tile_particle(i));
    let sums = density_walk(TileOwn(own, i), i, cell_coords(own.x), lane);
    if (i < params.fluid_count) {
        set_carried_density(i, finish_rate(sums.rate));
        finish_list(i, sums.list);
    }
    finish_densities_in_subgroup(lane);
}

// Candidate j's terms over a list (shared/list_walk.wgsl): those of the tiles' chunks where it
// is counted (a candidate the list leaves out lies beyond h, where its terms add exact zeros).
fn listed_fluid(sums: ptr<function, TileSums>, own: TileOwn, j: u32) {
    var rate = (*sums).rate;
    add_fluid_rate(&rate, own.rate, positions_at(j).xyz, velocities_at(j), true);
    (*sums).rate = rate;
}

fn listed_wall(sums: ptr<function, TileSums>, own: TileOwn, j: u32) {
    var rate = (*sums).rate;
    add_wall_rate(&rate, own.rate, wall_positions_at(j), true);
    (*sums).rate = rate;
}
