// The normals stage with the stencils of a subgroup walked together (shared/tiles.wgsl): the
// same sum in the same order as surface_normals.wgsl's `surface_normals`, so its twin is the
// same, src/solver/cpu/surface_normals.rs. A normal sums over fluid neighbours only: the walk's
// wall spans are empty, and no wall array is bound. A file of its own since its subgroup
// operations need an adapter with subgroups, which the other stages do not.

//! include sim/surface_normals.wgsl
//! include shared/tiles.wgsl

alias TileOwn = vec3<f32>;
alias TileSums = vec3<f32>;

fn no_tile_sums() -> TileSums {
    return vec3<f32>(0.0);
}

// Candidate at x with density rho: its term of surface_normal's sum, where it is in the
// invocation's own span and closer than h (NaN distances included, as a blow-up must show).
fn tile_normal_term(sums: ptr<function, TileSums>, own: TileOwn, x: vec3<f32>, rho: f32, counted: bool) {
    let rij = own - x;
    let r2 = dot(rij, rij);
    *sums += select(vec3<f32>(0.0), kernel_grad(rij, sqrt(r2)) * (1.0 / rho), counted && !(r2 >= params.h2));
}

// The fluid candidates b to b + TILE - 1 (this lane's: j), in order.
fn tile_fluid_chunk(sums: ptr<function, TileSums>, own: TileOwn, j: u32, b: u32, span: vec2<u32>) {
    let x = positions_at(j).xyz;
    let rho = densities_at(j);
    //! unroll 8 tile_normal_term(sums, own, subgroupShuffle(x, {k}u), subgroupShuffle(rho, {k}u), in_span(b + {k}u, span));
}

// No wall takes part in a normal.
fn tile_wall_spans(t: TileRow, cx: u32, run: u32) -> vec4<u32> {
    return vec4<u32>(0u);
}

fn tile_wall_chunk(sums: ptr<function, TileSums>, own: TileOwn, j: u32, b: u32, span: vec2<u32>) {}

@compute @workgroup_size(WORKGROUP_SIZE)
fn surface_normals_tiled(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
    @builtin(subgroup_invocation_id) lane: u32,
) {
    let i = thread_index(gid, groups);
    let xi = positions_at(tile_particle(i)).xyz;
    let sum = tile_walk(xi, cell_coords(xi), lane, i < params.fluid_count);
    if (i < params.fluid_count) {
        normals_set(i, vec4<f32>(sum * (params.h * params.fluid_mass), 0.0));
    }
}
