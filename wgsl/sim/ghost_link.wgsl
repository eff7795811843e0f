// DFSPH across ranks: the ghost link's lists from the device's own binning, without reading the
// particles back (src/solver/gpu/dfsph_ranks.rs, docs/scale-out.md). The link lists the
// particles of the cell layers next to the slab's faces: the own particles within the ghost
// layers of a face (their velocities go to that neighbour) and the ghosts beyond it (they take
// the neighbour's). Those are whole cells of the binning, in cell order; the host lists the
// cells, this stage reads where each one's particles lie in the cell starts, and the host
// joins the runs.
//
// Twin of src/solver/cpu/ghost_link.rs.

//! include shared/common.wgsl
//! array starts: u32, read
// Word 0: how many cells; from word 1 the cells, in the lists' order.
//! array link_cells: u32, read
// Per listed cell: its first slot and the slot after its last.
//! array link_bounds: u32, read_write

@compute @workgroup_size(WORKGROUP_SIZE)
fn link_cell_bounds(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let k = thread_index(gid, groups);
    if (k >= link_cells_at(0u)) {
        return;
    }
    let cell = link_cells_at(1u + k);
    link_bounds_set(2u * k, starts_at(cell));
    link_bounds_set(2u * k + 1u, starts_at(cell + 1u));
}
