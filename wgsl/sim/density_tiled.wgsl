// The density stage with the stencils of a subgroup walked together (shared/tiles.wgsl): the
// same sums in the same order as density.wgsl's `density`, so its twin is the same,
// src/solver/cpu/density.rs. With NEIGHBOUR_LISTS it also records each particle's neighbours
// for the forces (shared/neighbour_lists.wgsl); with a neighbour skin, built with RECORD_LISTS
// false for the steps between rebuilds, it walks the lists of the last rebuild instead
// (shared/list_walk.wgsl). A file of its own since its subgroup operations need an adapter
// with subgroups, which the other stages do not.

//! include sim/density.wgsl
//! include shared/tiles.wgsl
//! include shared/density_write_tiled.wgsl
//! include shared/tiles_walls.wgsl
//! include shared/neighbour_lists.wgsl
//! include shared/list_walk.wgsl

// A particle's position, and its index (fluid_count or more for an invocation without one).
struct TileOwn {
    x: vec3<f32>,
    i: u32,
}

// The fluid sum of W (x) and the walls' sum of m W (y), and the list's counts.
struct TileSums {
    w: vec2<f32>,
    list: ListCounts,
}

fn no_tile_sums() -> TileSums {
    return TileSums(vec2<f32>(0.0), ListCounts(0u, 0u));
}

// Candidate j at w.xyz (a wall particle with `wall`, its mass in w.w): its W, times its mass for
// a wall, added where j is in the invocation's own span; 1 where it is also a neighbour for the
// forces (within LIST_MARGIN h^2, shared/neighbour_lists.wgsl), else 0.
fn tile_candidate(sums: ptr<function, TileSums>, own: TileOwn, w: vec4<f32>, wall: bool, j: u32, span: vec2<u32>) -> u32 {
    let d = own.x - w.xyz;
    let r2 = dot(d, d);
    let kernel = kernel_w(r2);
    let counted = in_span(j, span);
    if (wall) {
        (*sums).w.y += select(0.0, w.w * kernel, counted);
    } else {
        (*sums).w.x += select(0.0, kernel, counted);
    }
    return select(0u, 1u, counted && !(r2 >= LIST_MARGIN * LIST_RADIUS2 * params.h2));
}

// The chunk's candidates b to b + TILE - 1, one per lane in w, in order; with lists, the chunk
// recorded.
fn tile_fluid_chunk(sums: ptr<function, TileSums>, own: TileOwn, j: u32, b: u32, span: vec2<u32>) {
    let w = positions_at(j);
    var mask = 0u;
    //! unroll 8 mask |= tile_candidate(sums, own, subgroupShuffle(w, {k}u), false, b + {k}u, span) << {k}u;
    (*sums).list = record_chunk((*sums).list, own.i, b, mask, false);
}

fn tile_wall_chunk(sums: ptr<function, TileSums>, own: TileOwn, j: u32, b: u32, span: vec2<u32>) {
    let w = wall_positions_at(j);
    var mask = 0u;
    //! unroll 8 mask |= tile_candidate(sums, own, subgroupShuffle(w, {k}u), true, b + {k}u, span) << {k}u;
    (*sums).list = record_chunk((*sums).list, own.i, b, mask, true);
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn density_tiled(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
    @builtin(subgroup_invocation_id) lane: u32,
) {
    let i = thread_index(gid, groups);
    let xi = positions_at(tile_particle(i)).xyz;
    let sums = density_walk(TileOwn(xi, i), i, cell_coords(xi), lane);
    if (i < params.fluid_count) {
        set_density(i, params.fluid_mass * sums.w.x + sums.w.y);
        finish_list(i, sums.list);
    }
    finish_densities_in_subgroup(lane);
}

// Candidate j's terms over a list (shared/list_walk.wgsl): those of tile_candidate where it
// is counted (a candidate the list leaves out lies beyond h, where W adds an exact zero to the
// walk's sums).
fn listed_fluid(sums: ptr<function, TileSums>, own: TileOwn, j: u32) {
    let d = own.x - positions_at(j).xyz;
    (*sums).w.x += kernel_w(dot(d, d));
}

fn listed_wall(sums: ptr<function, TileSums>, own: TileOwn, j: u32) {
    let w = wall_positions_at(j);  // w: mass
    let d = own.x - w.xyz;
    (*sums).w.y += w.w * kernel_w(dot(d, d));
}
