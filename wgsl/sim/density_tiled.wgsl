// The density stage with the stencils of a subgroup walked together (shared/tiles.wgsl): the
// same sums in the same order as density.wgsl's `density`, so its twin is the same,
// src/solver/cpu/density.rs. A file of its own since its subgroup operations need an adapter
// with subgroups, which the other stages do not.

//! include sim/density.wgsl
//! include shared/tiles.wgsl

// W of candidate j at w.xyz, times its mass w.w where `weighed` (a wall particle), zero unless
// j is in the invocation's own span.
fn tile_w(xi: vec3<f32>, w: vec4<f32>, weighed: bool, j: u32, own: vec2<u32>) -> f32 {
    let d = xi - w.xyz;
    let kernel = kernel_w(dot(d, d));
    return select(0.0, select(kernel, w.w * kernel, weighed), in_span(j, own));
}

// The sum over a chunk: the candidates b to b + TILE - 1, one per lane in w, in order.
fn chunk_sum(sum: f32, xi: vec3<f32>, w: vec4<f32>, weighed: bool, b: u32, own: vec2<u32>) -> f32 {
    var s = sum;
    s += tile_w(xi, subgroupShuffle(w, 0u), weighed, b, own);
    s += tile_w(xi, subgroupShuffle(w, 1u), weighed, b + 1u, own);
    s += tile_w(xi, subgroupShuffle(w, 2u), weighed, b + 2u, own);
    s += tile_w(xi, subgroupShuffle(w, 3u), weighed, b + 3u, own);
    s += tile_w(xi, subgroupShuffle(w, 4u), weighed, b + 4u, own);
    s += tile_w(xi, subgroupShuffle(w, 5u), weighed, b + 5u, own);
    s += tile_w(xi, subgroupShuffle(w, 6u), weighed, b + 6u, own);
    s += tile_w(xi, subgroupShuffle(w, 7u), weighed, b + 7u, own);
    return s;
}

// `density` with the subgroup's stencils walked together (shared/tiles.wgsl): every invocation
// of a subgroup runs every loop, since the shuffles need all TILE lanes.
@compute @workgroup_size(WORKGROUP_SIZE)
fn density_tiled(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
    @builtin(subgroup_invocation_id) lane: u32,
) {
    reduce_begin(lid);
    let i = thread_index(gid, groups);
    let is_fluid = i < params.fluid_count;
    let xi = positions_at(min(i, max(params.fluid_count, 1u) - 1u)).xyz;
    let c = cell_coords(xi);
    var fluid_sum = 0.0;
    var wall_sum = 0.0;
    var pending = is_fluid;
    while (subgroupAny(pending)) {
        let t = tile_row(c, pending);
        for (var run = 0u; run < 9u; run++) {
            let fluid = tile_spans(t, c.x, run, false);
            for (var b = fluid.x; b < fluid.y; b += TILE) {
                fluid_sum = chunk_sum(fluid_sum, xi, positions_at(min(b + lane, fluid.y - 1u)), false, b, fluid.zw);
            }
            if (WALLS) {
                let walls = tile_spans(t, c.x, run, true);
                for (var b = walls.x; b < walls.y; b += TILE) {
                    wall_sum = chunk_sum(wall_sum, xi, wall_positions_at(min(b + lane, walls.y - 1u)), true, b, walls.zw);
                }
            }
        }
        pending = pending && !t.mine;
    }
    if (is_fluid) {
        set_density(i, params.fluid_mass * fluid_sum + wall_sum);
    }
    finish_densities(lid);
}
