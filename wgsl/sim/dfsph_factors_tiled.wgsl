// DFSPH's factors with the stencils of a subgroup walked together (shared/tiles.wgsl): the pair
// terms of dfsph_factors.wgsl, the same sums in the same order as its `density_and_factor`, so
// its twin is the same, src/solver/cpu/dfsph_factors.rs. With NEIGHBOUR_LISTS it also records
// each particle's fluid neighbours, which every solve pass of the step walks
// (shared/dfsph_tiles.wgsl). A file of its own since its subgroup operations need an adapter
// with subgroups, which the other stages do not.

//! include sim/dfsph_factors.wgsl
//! include shared/tiles.wgsl
//! include shared/density_write_tiled.wgsl
//! include shared/tiles_walls.wgsl
//! include shared/neighbour_lists.wgsl

// A particle's position, and its index (fluid_count or more for an invocation without one).
struct TileOwn {
    x: vec3<f32>,
    i: u32,
}

struct TileSums {
    factors: FactorSums,
    list: ListCounts,
}

fn no_tile_sums() -> TileSums {
    return TileSums(no_factor_sums(), ListCounts(0u, 0u));
}

// The fluid candidates b to b + TILE - 1 (this lane's: j), in order; with lists, the chunk's
// neighbours recorded.
fn tile_fluid_chunk(sums: ptr<function, TileSums>, own: TileOwn, j: u32, b: u32, span: vec2<u32>) {
    let xj = positions_at(j).xyz;
    var factors = (*sums).factors;
    //! unroll 8 add_factor_fluid(&factors, own.x, subgroupShuffle(xj, {k}u), in_span(b + {k}u, span));
    (*sums).factors = factors;
    (*sums).list = record_shuffled_chunk((*sums).list, own.i, own.x, xj, b, span, false);
}

// The solves take the walls through each particle's wall gradient: no wall is recorded.
fn tile_wall_chunk(sums: ptr<function, TileSums>, own: TileOwn, j: u32, b: u32, span: vec2<u32>) {
    let w = wall_positions_at(j);
    var factors = (*sums).factors;
    //! unroll 8 add_factor_wall(&factors, own.x, subgroupShuffle(w, {k}u), in_span(b + {k}u, span));
    (*sums).factors = factors;
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn factors_tiled(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
    @builtin(subgroup_invocation_id) lane: u32,
) {
    let i = thread_index(gid, groups);
    let p = positions_at(tile_particle(i));
    let sums = tile_walk(TileOwn(p.xyz, i), cell_coords(p.xyz), lane, i < params.fluid_count);
    if (i < params.fluid_count) {
        finish_factors(i, p, sums.factors);
        finish_list(i, sums.list);
    }
    finish_densities_in_subgroup(lane);
}
