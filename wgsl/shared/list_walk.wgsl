// The walk over one particle's neighbour list (shared/neighbour_lists.wgsl) in the weakly
// compressible stages that walk lists (density_tiled.wgsl and continuity_tiled.wgsl between the
// rebuilds of a neighbour skin, forces_tiled.wgsl every step), and the tiled density stages'
// choice of walk. The including stage defines the types TileOwn and TileSums and
// no_tile_sums() as for shared/tiles.wgsl, and listed_fluid(sums, own, j) and
// listed_wall(sums, own, j), which add the terms of fluid (or wall) candidate j. A list's
// fluid entries, then its wall entries, each in the order of the tiles' walk: a stage's fluid
// and wall sums are kept apart, so each is the walk's bit for bit.

fn list_walk(own: TileOwn, i: u32) -> TileSums {
    let counts = list_counts(i);
    var sums = no_tile_sums();
    var at = vec3<u32>(0u);
    var j = 0u;
    while (next_listed(i, counts & 0xffffu, false, &at, &j)) {
        listed_fluid(&sums, own, j);
    }
    if (WALLS) {
        at = vec3<u32>(0u);
        while (next_listed(i, counts >> 16u, true, &at, &j)) {
            listed_wall(&sums, own, j);
        }
    }
    return sums;
}

// Particle i's sums (p: the particle its invocation takes, tile_particle(i)), over its list
// where its subgroup walks lists (walks_lists), else over the tiles on the grid's cells.
fn list_or_tile_walk(own: TileOwn, i: u32, p: u32, c: vec3<u32>, lane: u32) -> TileSums {
    if (walks_lists(p)) {
        return list_walk(own, p);
    }
    return tile_walk(own, c, lane, i < params.fluid_count);
}

// The walk of a tiled density stage: where it records the lists (RECORD_LISTS, the default),
// the tiles, recording as they go; between the rebuilds of a neighbour skin (built with
// RECORD_LISTS false) the lists of the last rebuild, or the tiles on that rebuild's cells where
// a list of the subgroup overflowed, which hold every neighbour as the lists do
// (neighbour_skin.wgsl).
fn density_walk(own: TileOwn, i: u32, c: vec3<u32>, lane: u32) -> TileSums {
    if (RECORD_LISTS) {
        return tile_walk(own, c, lane, i < params.fluid_count);
    }
    return list_or_tile_walk(own, i, tile_particle(i), c, lane);
}
