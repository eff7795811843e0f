//! DFSPH across ranks: the ghost link's lists from a binning's cell starts, so that a GPU rank
//! makes them without reading its particles back. Twin of wgsl/sim/ghost_link.wgsl (the host
//! lists the cells and joins the runs; the stage reads the cell starts), see
//! src/solver/gpu/dfsph_ranks.rs and docs/scale-out.md.

use super::resident_exchange::SlabFaces;

/// The cells of the link's four lists, each in cell order (the cells' keys, x fastest): the
/// slab's own cell layers within `halo` of its lower face (sent to the lower neighbour), those
/// within `halo` of its upper face (sent to the upper one), then the ghost layers below the
/// slab (the lower neighbour's particles) and above it; a face without a neighbour lists none.
/// A binning puts the own particles in the slab's layers and the ghosts in the `halo` layers
/// beyond its faces, so these cells hold exactly the particles the link lists.
pub fn link_cells(dims: [u32; 3], faces: &SlabFaces) -> [Vec<u32>; 4] {
    let (start, end, halo, last) = (faces.slab.start, faces.slab.end, faces.halo, dims[faces.axis]);
    let layers = [
        if faces.lower { start..(start + halo).min(end) } else { 0..0 },
        if faces.upper { end.saturating_sub(halo).max(start)..end } else { 0..0 },
        if faces.lower { start.saturating_sub(halo)..start.min(last) } else { 0..0 },
        if faces.upper { end.min(last)..(end + halo).min(last) } else { 0..0 },
    ];
    layers.map(|layers| {
        let mut cells = Vec::new();
        if layers.is_empty() {
            return cells;
        }
        let mut ranges = dims.map(|d| 0..d);
        ranges[faces.axis] = layers;
        for z in ranges[2].clone() {
            for y in ranges[1].clone() {
                for x in ranges[0].clone() {
                    cells.push(x + dims[0] * (y + dims[1] * z));
                }
            }
        }
        cells
    })
}

/// `link_cell_bounds`: each of `cells`' first slot and the slot after its last, from the cell
/// starts of a binning.
pub fn link_cell_bounds(starts: &[u32], cells: &[u32]) -> Vec<[u32; 2]> {
    cells.iter().map(|&c| [starts[c as usize], starts[c as usize + 1]]).collect()
}

/// The link's lists (as [`link_cells`] orders them): the slots of each list's cells, joined,
/// from `bounds`, the cells' bounds in the order of the lists' cells joined.
pub fn link_slots(lists: &[Vec<u32>; 4], bounds: &[[u32; 2]]) -> [Vec<usize>; 4] {
    let mut at = 0;
    lists.each_ref().map(|cells| {
        let runs = &bounds[at..at + cells.len()];
        at += cells.len();
        runs.iter().flat_map(|b| b[0] as usize..b[1] as usize).collect()
    })
}
