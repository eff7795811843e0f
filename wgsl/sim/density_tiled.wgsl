// The density stage with the stencils of a subgroup walked together (shared/tiles.wgsl): the
// same sums in the same order as density.wgsl's `density`, so its twin is the same,
// src/solver/cpu/density.rs. A file of its own since its subgroup operations need an adapter
// with subgroups, which the other stages do not.

//! include sim/density.wgsl
//! include shared/tiles.wgsl

// W of a fluid candidate at xj, zero unless j is in the invocation's own span.
fn tile_w(xi: vec3<f32>, xj: vec3<f32>, j: u32, own: vec2<u32>) -> f32 {
    let d = xi - xj;
    return select(0.0, kernel_w(dot(d, d)), in_span(j, own));
}

// The fluid sum over a chunk: the candidates b to b + TILE - 1, one per lane in xj, in order.
fn fluid_chunk(sum: f32, xi: vec3<f32>, xj: vec3<f32>, b: u32, own: vec2<u32>) -> f32 {
    var s = sum;
    s += tile_w(xi, subgroupShuffle(xj, 0u), b, own);
    s += tile_w(xi, subgroupShuffle(xj, 1u), b + 1u, own);
    s += tile_w(xi, subgroupShuffle(xj, 2u), b + 2u, own);
    s += tile_w(xi, subgroupShuffle(xj, 3u), b + 3u, own);
    s += tile_w(xi, subgroupShuffle(xj, 4u), b + 4u, own);
    s += tile_w(xi, subgroupShuffle(xj, 5u), b + 5u, own);
    s += tile_w(xi, subgroupShuffle(xj, 6u), b + 6u, own);
    s += tile_w(xi, subgroupShuffle(xj, 7u), b + 7u, own);
    return s;
}

// m W of a wall candidate (w: position and mass), zero unless j is in the own span.
fn tile_wall_w(xi: vec3<f32>, w: vec4<f32>, j: u32, own: vec2<u32>) -> f32 {
    let d = xi - w.xyz;
    return select(0.0, w.w * kernel_w(dot(d, d)), in_span(j, own));
}

fn wall_chunk(sum: f32, xi: vec3<f32>, w: vec4<f32>, b: u32, own: vec2<u32>) -> f32 {
    var s = sum;
    s += tile_wall_w(xi, subgroupShuffle(w, 0u), b, own);
    s += tile_wall_w(xi, subgroupShuffle(w, 1u), b + 1u, own);
    s += tile_wall_w(xi, subgroupShuffle(w, 2u), b + 2u, own);
    s += tile_wall_w(xi, subgroupShuffle(w, 3u), b + 3u, own);
    s += tile_wall_w(xi, subgroupShuffle(w, 4u), b + 4u, own);
    s += tile_wall_w(xi, subgroupShuffle(w, 5u), b + 5u, own);
    s += tile_wall_w(xi, subgroupShuffle(w, 6u), b + 6u, own);
    s += tile_wall_w(xi, subgroupShuffle(w, 7u), b + 7u, own);
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
            let cells = tile_run_cells(t, c.x, run);
            let e = starts_at(cells.y);
            let own = vec2<u32>(starts_at(cells.z), starts_at(cells.w));
            for (var b = starts_at(cells.x); b < e; b += TILE) {
                fluid_sum = fluid_chunk(fluid_sum, xi, positions_at(min(b + lane, e - 1u)).xyz, b, own);
            }
            if (WALLS) {
                let e = wall_starts_at(cells.y);
                let own = vec2<u32>(wall_starts_at(cells.z), wall_starts_at(cells.w));
                for (var b = wall_starts_at(cells.x); b < e; b += TILE) {
                    wall_sum = wall_chunk(wall_sum, xi, wall_positions_at(min(b + lane, e - 1u)), b, own);
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
