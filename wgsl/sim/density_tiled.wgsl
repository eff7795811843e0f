// The density stage with the stencils of a subgroup walked together (shared/tiles.wgsl): the
// same sums in the same order as density.wgsl's `density`, so its twin is the same,
// src/solver/cpu/density.rs. A file of its own since its subgroup operations need an adapter
// with subgroups, which the other stages do not.

//! include sim/density.wgsl
//! include shared/tiles.wgsl
//! include shared/tiles_walls.wgsl

// A particle's position; the fluid sum of W (x) and the walls' sum of m W (y).
alias TileOwn = vec3<f32>;
alias TileSums = vec2<f32>;

fn no_tile_sums() -> TileSums {
    return vec2<f32>(0.0);
}

// W of candidate j at w.xyz, times its mass w.w where `weighed` (a wall particle), zero unless
// j is in the invocation's own span.
fn tile_w(xi: vec3<f32>, w: vec4<f32>, weighed: bool, j: u32, span: vec2<u32>) -> f32 {
    let d = xi - w.xyz;
    let kernel = kernel_w(dot(d, d));
    return select(0.0, select(kernel, w.w * kernel, weighed), in_span(j, span));
}

// The chunk's sum: the candidates b to b + TILE - 1, one per lane in w, in order.
fn chunk_sum(sum: f32, xi: vec3<f32>, w: vec4<f32>, weighed: bool, b: u32, span: vec2<u32>) -> f32 {
    var s = sum;
    //! unroll 8 s += tile_w(xi, subgroupShuffle(w, {k}u), weighed, b + {k}u, span);
    return s;
}

fn tile_fluid_chunk(sums: ptr<function, TileSums>, xi: TileOwn, j: u32, b: u32, span: vec2<u32>) {
    (*sums).x = chunk_sum((*sums).x, xi, positions_at(j), false, b, span);
}

fn tile_wall_chunk(sums: ptr<function, TileSums>, xi: TileOwn, j: u32, b: u32, span: vec2<u32>) {
    (*sums).y = chunk_sum((*sums).y, xi, wall_positions_at(j), true, b, span);
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn density_tiled(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
    @builtin(subgroup_invocation_id) lane: u32,
) {
    reduce_begin(lid);
    let i = thread_index(gid, groups);
    let xi = positions_at(tile_particle(i)).xyz;
    let sums = tile_walk(xi, cell_coords(xi), lane, i < params.fluid_count);
    if (i < params.fluid_count) {
        set_density(i, params.fluid_mass * sums.x + sums.y);
    }
    finish_densities(lid);
}
