// Neighbour tiles, the walk of the tiled stages (density_tiled.wgsl, continuity_tiled.wgsl,
// forces_tiled.wgsl, and DFSPH's solve passes, shared/dfsph_tiles.wgsl): the TILE invocations
// of a subgroup, consecutive particles in cell order, walk their stencils together. Each chunk
// of TILE candidates is read once, one candidate per invocation, and handed to every invocation
// by subgroup shuffles with constant lanes, instead of every invocation reading every
// candidate. Each invocation counts only the candidates of its own runs of cells, in the order
// of the per-particle loop, so the sums are those of the per-particle entry points bit for bit.
// Chosen by the host where the adapter's subgroups are exactly TILE invocations (a software
// adapter's 8-wide SIMD; docs/performance.md says why and what it gains).

// The `//! unroll 8` lines of the tiled stages hand out one chunk of TILE candidates.
const TILE: u32 = 8u;

// The row of cells (y, z) that the subgroup's pending invocations take next (the smallest of
// their rows), whether this invocation is in it, and the x range of their cells in that row.
struct TileRow {
    mine: bool,
    y: u32,
    z: u32,
    x_lo: u32,
    x_hi: u32,
}

fn tile_row(c: vec3<u32>, pending: bool) -> TileRow {
    let my_row = c.y + params.grid_dims.y * c.z;
    let row = subgroupMin(select(0xffffffffu, my_row, pending));
    let mine = pending && my_row == row;
    let x_lo = subgroupMin(select(0xffffffffu, c.x, mine));
    let x_hi = subgroupMax(select(0u, c.x, mine));
    return TileRow(mine, row % params.grid_dims.y, row / params.grid_dims.y, x_lo, x_hi);
}

// Run `run` (0 to 8) of the row's stencil as cell keys: the union of the invocations' runs from
// x to y (exclusive) and this invocation's own run (stencil_run's) from z to w; empty outside
// the grid, and the own run empty for an invocation not in the row.
fn tile_run_cells(t: TileRow, cx: u32, run: u32) -> vec4<u32> {
    let y = i32(t.y) + i32(run % 3u) - 1;
    let z = i32(t.z) + i32(run / 3u) - 1;
    if (y < 0 || z < 0 || y >= i32(params.grid_dims.y) || z >= i32(params.grid_dims.z)) {
        return vec4<u32>(0u);
    }
    let base = params.grid_dims.x * (u32(y) + params.grid_dims.y * u32(z));
    let last = params.grid_dims.x - 1u;
    let together = vec2<u32>(base + select(t.x_lo - 1u, 0u, t.x_lo == 0u), base + min(t.x_hi + 1u, last) + 1u);
    let own = vec2<u32>(base + select(cx - 1u, 0u, cx == 0u), base + min(cx + 1u, last) + 1u);
    return vec4<u32>(together, select(vec2<u32>(0u), own, t.mine));
}

// Run `run` of the row's stencil as spans of the cell-sorted fluid arrays: the subgroup's
// candidates from x to y (exclusive), this invocation's own from z to w.
fn tile_fluid_spans(t: TileRow, cx: u32, run: u32) -> vec4<u32> {
    let cells = tile_run_cells(t, cx, run);
    return vec4<u32>(starts_at(cells.x), starts_at(cells.y), starts_at(cells.z), starts_at(cells.w));
}

// Whether candidate j is in the span [own.x, own.y).
fn in_span(j: u32, own: vec2<u32>) -> bool {
    return j >= own.x && j < own.y;
}

// The sums of one particle over its stencil, walked with the subgroup. The including stage
// defines the types TileOwn (what a particle brings to its pairs) and TileSums, no_tile_sums(),
// tile_wall_spans (the wall arrays' spans, as tile_fluid_spans; shared/tiles_walls.wgsl), and
// tile_fluid_chunk and tile_wall_chunk(sums, own, j, b, span): this invocation reads
// candidate j, and the chunk's candidates b to b + TILE - 1 (one per lane) that lie in `span`
// are added to the sums, in order. Every invocation of the subgroup must call it (the shuffles
// need all TILE lanes); `pending_at_start` is false for one without a particle.
fn tile_walk(own: TileOwn, c: vec3<u32>, lane: u32, pending_at_start: bool) -> TileSums {
    var sums = no_tile_sums();
    var pending = pending_at_start;
    while (subgroupAny(pending)) {
        let t = tile_row(c, pending);
        for (var run = 0u; run < 9u; run++) {
            let fluid = tile_fluid_spans(t, c.x, run);
            for (var b = fluid.x; b < fluid.y; b += TILE) {
                tile_fluid_chunk(&sums, own, min(b + lane, fluid.y - 1u), b, fluid.zw);
            }
            if (WALLS) {
                let walls = tile_wall_spans(t, c.x, run);
                for (var b = walls.x; b < walls.y; b += TILE) {
                    tile_wall_chunk(&sums, own, min(b + lane, walls.y - 1u), b, walls.zw);
                }
            }
        }
        pending = pending && !t.mine;
    }
    return sums;
}

// The particle an invocation takes: its own, or for one past the last the last one (whose
// sums it computes for the shuffles' sake and drops).
fn tile_particle(i: u32) -> u32 {
    return min(i, max(params.fluid_count, 1u) - 1u);
}
