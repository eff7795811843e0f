// DFSPH's tiled solve passes (dfsph_divergence_tiled.wgsl, dfsph_pressure_tiled.wgsl;
// shared/tiles.wgsl): the rate of density change and the velocity change of a stiffness, over
// fluid neighbours only (the walls enter through each particle's wall gradient), with the pair
// terms of shared/dfsph.wgsl in the order of its per-particle loops. The entry points
// `rate_tiled` and `apply_tiled` end as the including solve's `set_stiffness_from_rate` and
// `apply_stiffness_push` do.
//
// With NEIGHBOUR_LISTS (shared/neighbour_lists.wgsl) the tiled factors
// (dfsph_factors_tiled.wgsl) record each particle's fluid neighbours, and every solve pass of
// the step (all on the step's first positions) walks those lists where its subgroup's all fit:
// the same pairs in the same order.

//! include shared/neighbour_lists.wgsl

// A particle's position, velocity and stiffness, and which sum the walk takes (the same for the
// whole dispatch): the push of the stiffness, or the rate.
struct SolveOwn {
    x: vec3<f32>,
    v: vec3<f32>,
    k: f32,
    push: bool,
}

struct SolveSums {
    rate: f32,
    push: vec3<f32>,
}

alias TileOwn = SolveOwn;
alias TileSums = SolveSums;

fn no_tile_sums() -> TileSums {
    return SolveSums(0.0, vec3<f32>(0.0));
}

fn tile_fluid_chunk(sums: ptr<function, SolveSums>, own: SolveOwn, j: u32, b: u32, span: vec2<u32>) {
    let xj = positions_at(j).xyz;
    if (own.push) {
        let kj = stiffness_at(j);
        //! unroll 8 (*sums).push += push_pair(own.x, own.k, subgroupShuffle(xj, {k}u), subgroupShuffle(kj, {k}u), in_span(b + {k}u, span));
    } else {
        let vj = velocities_at(j).xyz;
        //! unroll 8 (*sums).rate += rate_pair(own.x, own.v, subgroupShuffle(xj, {k}u), subgroupShuffle(vj, {k}u), in_span(b + {k}u, span));
    }
}

// No wall candidates: the walls' part is the particle's wall gradient.
fn tile_wall_spans(t: TileRow, cx: u32, run: u32) -> vec4<u32> {
    return vec4<u32>(0u);
}

fn tile_wall_chunk(sums: ptr<function, SolveSums>, own: SolveOwn, j: u32, b: u32, span: vec2<u32>) {
}

// density_rate of particle i (or, past the last, of the last: see tile_particle) with the
// subgroup; every invocation calls it. Each way finishes its own sum (see forces_tiled.wgsl).
fn tiled_density_rate(i: u32, lane: u32) -> f32 {
    let p = tile_particle(i);
    let own = SolveOwn(positions_at(p).xyz, velocities_at(p).xyz, 0.0, false);
    if (walks_lists(p)) {
        var rate = 0.0;
        var at = vec3<u32>(0u);
        var j = 0u;
        while (next_listed(p, list_counts(p) & 0xffffu, false, &at, &j)) {
            rate += rate_pair(own.x, own.v, positions_at(j).xyz, velocities_at(j).xyz, true);
        }
        return rate * params.fluid_volume + dot(own.v, wall_gradients_at(p).xyz);
    } else {
        let sums = tile_walk(own, cell_coords(own.x), lane, i < params.fluid_count);
        return sums.rate * params.fluid_volume + dot(own.v, wall_gradients_at(p).xyz);
    }
}

// stiffness_push of particle i with the subgroup; every invocation calls it.
fn tiled_stiffness_push(i: u32, lane: u32) -> vec3<f32> {
    let p = tile_particle(i);
    let own = SolveOwn(positions_at(p).xyz, vec3<f32>(0.0), stiffness_at(p), true);
    if (walks_lists(p)) {
        var push = vec3<f32>(0.0);
        var at = vec3<u32>(0u);
        var j = 0u;
        while (next_listed(p, list_counts(p) & 0xffffu, false, &at, &j)) {
            push += push_pair(own.x, own.k, positions_at(j).xyz, stiffness_at(j), true);
        }
        return push * params.fluid_volume + wall_gradients_at(p).xyz * own.k;
    } else {
        let sums = tile_walk(own, cell_coords(own.x), lane, i < params.fluid_count);
        return sums.push * params.fluid_volume + wall_gradients_at(p).xyz * own.k;
    }
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn rate_tiled(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
    @builtin(subgroup_invocation_id) lane: u32,
) {
    error_begin(lid);
    let i = thread_index(gid, groups);
    let rate = tiled_density_rate(i, lane);
    if (i < params.fluid_count) {
        set_stiffness_from_rate(i, positions_at(i).w, rate);
    }
    error_end(lid);
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn apply_tiled(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
    @builtin(subgroup_invocation_id) lane: u32,
) {
    let i = thread_index(gid, groups);
    let push = tiled_stiffness_push(i, lane);
    if (i < params.fluid_count) {
        apply_stiffness_push(i, push);
    }
}
