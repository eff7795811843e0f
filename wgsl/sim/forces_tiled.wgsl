// The forces stage with the stencils of a subgroup walked together (shared/tiles.wgsl): the
// pair terms of forces.wgsl, the same sums in the same order as its `forces`, so its twin is
// the same, src/solver/cpu/forces.rs. A file of its own since its subgroup operations need an
// adapter with subgroups, which the other stages do not.

//! include sim/forces.wgsl
//! include shared/tiles.wgsl

// Lane k's candidate, for every invocation.
fn shuffled_fluid(n: FluidCandidate, k: u32) -> FluidCandidate {
    var u = vec3<f32>(0.0);
    if (reads_velocities()) {
        u = subgroupShuffle(n.u, k);
    }
    return FluidCandidate(subgroupShuffle(n.x, k), u, subgroupShuffle(n.rho, k), subgroupShuffle(n.p, k));
}

// The fluid candidates b to b + TILE - 1 (one per lane in n), in order.
fn fluid_chunk(sums: ptr<function, ForceSums>, own: OwnParticle, n: FluidCandidate, b: u32, span: vec2<u32>) {
    add_fluid_pair(sums, own, shuffled_fluid(n, 0u), in_span(b, span));
    add_fluid_pair(sums, own, shuffled_fluid(n, 1u), in_span(b + 1u, span));
    add_fluid_pair(sums, own, shuffled_fluid(n, 2u), in_span(b + 2u, span));
    add_fluid_pair(sums, own, shuffled_fluid(n, 3u), in_span(b + 3u, span));
    add_fluid_pair(sums, own, shuffled_fluid(n, 4u), in_span(b + 4u, span));
    add_fluid_pair(sums, own, shuffled_fluid(n, 5u), in_span(b + 5u, span));
    add_fluid_pair(sums, own, shuffled_fluid(n, 6u), in_span(b + 6u, span));
    add_fluid_pair(sums, own, shuffled_fluid(n, 7u), in_span(b + 7u, span));
}

fn shuffled_wall(n: WallCandidate, k: u32) -> WallCandidate {
    var fields = vec2<f32>(0.0, 1.0);
    if (ADAMI_WALL_PRESSURE) {
        fields = subgroupShuffle(n.fields, k);
    }
    return WallCandidate(subgroupShuffle(n.w, k), fields);
}

fn wall_chunk(sums: ptr<function, ForceSums>, own: OwnParticle, n: WallCandidate, b: u32, span: vec2<u32>) {
    add_wall_pair(sums, own, shuffled_wall(n, 0u), in_span(b, span));
    add_wall_pair(sums, own, shuffled_wall(n, 1u), in_span(b + 1u, span));
    add_wall_pair(sums, own, shuffled_wall(n, 2u), in_span(b + 2u, span));
    add_wall_pair(sums, own, shuffled_wall(n, 3u), in_span(b + 3u, span));
    add_wall_pair(sums, own, shuffled_wall(n, 4u), in_span(b + 4u, span));
    add_wall_pair(sums, own, shuffled_wall(n, 5u), in_span(b + 5u, span));
    add_wall_pair(sums, own, shuffled_wall(n, 6u), in_span(b + 6u, span));
    add_wall_pair(sums, own, shuffled_wall(n, 7u), in_span(b + 7u, span));
}

// `forces` with the subgroup's stencils walked together (shared/tiles.wgsl): every invocation
// of a subgroup runs every loop, since the shuffles need all TILE lanes.
@compute @workgroup_size(WORKGROUP_SIZE)
fn forces_tiled(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
    @builtin(subgroup_invocation_id) lane: u32,
) {
    let i = thread_index(gid, groups);
    let is_fluid = i < params.fluid_count;
    let own = own_particle(min(i, max(params.fluid_count, 1u) - 1u));
    let c = cell_coords(own.x);
    var sums = no_sums();
    var pending = is_fluid;
    while (subgroupAny(pending)) {
        let t = tile_row(c, pending);
        for (var run = 0u; run < 9u; run++) {
            let fluid = tile_spans(t, c.x, run, false);
            for (var b = fluid.x; b < fluid.y; b += TILE) {
                let j = min(b + lane, fluid.y - 1u);
                fluid_chunk(&sums, own, fluid_candidate(j, positions_at(j).xyz), b, fluid.zw);
            }
            if (WALLS) {
                let walls = tile_spans(t, c.x, run, true);
                for (var b = walls.x; b < walls.y; b += TILE) {
                    let j = min(b + lane, walls.y - 1u);
                    wall_chunk(&sums, own, wall_candidate(j, wall_positions_at(j)), b, walls.zw);
                }
            }
        }
        pending = pending && !t.mine;
    }
    if (is_fluid) {
        accelerations_set(i, finish_acceleration(own, sums));
    }
}
