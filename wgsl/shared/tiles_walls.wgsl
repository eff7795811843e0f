// The wall spans of the weakly compressible tiled stages' walk (shared/tiles.wgsl): run `run` of
// the row's stencil in the cell-sorted wall arrays, as tile_fluid_spans gives the fluid's.

fn tile_wall_spans(t: TileRow, cx: u32, run: u32) -> vec4<u32> {
    let cells = tile_run_cells(t, cx, run);
    return vec4<u32>(wall_starts_at(cells.x), wall_starts_at(cells.y), wall_starts_at(cells.z), wall_starts_at(cells.w));
}
