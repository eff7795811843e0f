//! Across ranks on a GPU, the exchange with the rank's interior left on the device: the band the
//! host reads back, the merge of the kept particles with those the neighbours sent, in the
//! one-process order, and the own particles' health. Twin of wgsl/sim/resident_exchange.wgsl,
//! entry point for entry point, on the device's vectors (the w of a position holds the
//! particle's id with the ghost bit; a velocity's w, the carried or summed density); see
//! src/solver/gpu/resident.rs and docs/scale-out.md.

use crate::model::params::Grid;
use crate::model::real::V3;
use std::ops::Range;

/// Where a rank's slab lies: the axis the slabs cut, the rank's cell layers along it, the ghost
/// layers on each side of a face, and which neighbours it has.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SlabFaces {
    pub axis: usize,
    pub slab: Range<u32>,
    pub halo: u32,
    pub lower: bool,
    pub upper: bool,
}

/// The own particles' health after a step: non-finite and escaped counts, the largest squared
/// speed of the finite ones and the largest finite positive density (0 where none).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct OwnHealth {
    pub non_finite: u32,
    pub escaped: u32,
    pub max_speed2: f32,
    pub max_density: f32,
}

/// The top bit of a position's w marks a ghost (`GHOST_BIT` in wgsl/shared/common.wgsl).
const GHOST_BIT: u32 = 0x8000_0000;

fn is_ghost(position: &[f32; 4]) -> bool {
    position[3].to_bits() & GHOST_BIT != 0
}

/// The cell of `slot` in the binning whose cell starts are `starts`.
pub fn cell_of_slot(starts: &[u32], slot: u32) -> u32 {
    // The last cell whose start is at or below the slot (empty cells share their start).
    (starts.partition_point(|&s| s <= slot) - 1) as u32
}

/// `select_band`: the dropped slots (ghosts, and own particles outside the slab) and the band
/// (the leaving particles and those within `halo` layers of a face with a neighbour), each as
/// (slot, place in the one-process order: cell << 32 | place in the cell), in slot order (the
/// device lists them in no fixed order).
pub fn select_band(positions: &[[f32; 4]], starts: &[u32], grid: &Grid<f32>, faces: &SlabFaces) -> (Vec<u32>, Vec<(u32, u64)>) {
    let (mut dropped, mut band) = (Vec::new(), Vec::new());
    for (i, p) in positions.iter().enumerate() {
        let i = i as u32;
        if is_ghost(p) {
            dropped.push(i);
            continue;
        }
        let layer = grid.layer(V3([p[0], p[1], p[2]]), faces.axis);
        let leaving = !faces.slab.contains(&layer);
        let near_face = (faces.lower && layer < faces.slab.start + faces.halo) || (faces.upper && layer + faces.halo >= faces.slab.end);
        if leaving {
            dropped.push(i);
        }
        if leaving || near_face {
            let cell = cell_of_slot(starts, i);
            band.push((i, (cell as u64) << 32 | (i - starts[cell as usize]) as u64));
        }
    }
    (dropped, band)
}

/// `count_layers`: the own particles (ghosts left out) per cell layer of the slab `axis`.
pub fn count_layers(positions: &[[f32; 4]], grid: &Grid<f32>, axis: usize) -> Vec<u32> {
    let mut counts = vec![0u32; grid.dims[axis] as usize];
    for p in positions.iter().filter(|p| !is_ghost(p)) {
        counts[grid.layer(V3([p[0], p[1], p[2]]), axis) as usize] += 1;
    }
    counts
}

/// `place_inserts`: the held slot before which each received particle goes (its place in the
/// one-process order `keys[j]` against the cells of the last binning), and its new slot, given
/// the `dropped` slots (sorted).
pub fn place_inserts(starts: &[u32], dropped: &[u32], keys: &[u64]) -> (Vec<u32>, Vec<u32>) {
    keys.iter()
        .enumerate()
        .map(|(j, &key)| {
            let (cell, place) = ((key >> 32) as usize, key as u32);
            let before = (starts[cell] + place).min(starts[cell + 1]);
            (before, before - dropped.partition_point(|&d| d < before) as u32 + j as u32)
        })
        .unzip()
}

/// `merge_kept`: each kept slot's new slot (`None` for a dropped one), given the `dropped` slots
/// (sorted) and the received particles' places from [`place_inserts`].
pub fn merge_kept(held: usize, dropped: &[u32], places: &[u32]) -> Vec<Option<u32>> {
    (0..held as u32)
        .map(|i| {
            let below = dropped.partition_point(|&d| d < i);
            if dropped.get(below) == Some(&i) {
                return None;
            }
            Some(i - below as u32 + places.partition_point(|&s| s <= i) as u32)
        })
        .collect()
}

/// `own_health`: the health of the particles that are not ghosts, the density read from
/// `densities` where the step keeps them (continuity density, DFSPH), else from the velocities'
/// w.
pub fn own_health(positions: &[[f32; 4]], velocities: &[[f32; 4]], densities: Option<&[f32]>, domain: ([f32; 3], [f32; 3])) -> OwnHealth {
    let mut h = OwnHealth::default();
    for (i, (p, v)) in positions.iter().zip(velocities).enumerate() {
        if is_ghost(p) {
            continue;
        }
        let finite = p[..3].iter().chain(&v[..3]).all(|x| x.is_finite());
        let inside = (0..3).all(|a| p[a] >= domain.0[a] && p[a] <= domain.1[a]);
        if !finite {
            h.non_finite += 1;
        } else {
            h.escaped += !inside as u32;
            h.max_speed2 = h.max_speed2.max(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
        }
        let density = densities.map_or(v[3], |d| d[i]);
        if density.is_finite() && density > 0.0 {
            h.max_density = h.max_density.max(density);
        }
    }
    h
}

/// With DFSPH across ranks a position's w holds the particle's place in the upload, at which its
/// id and warm starts live (`DFSPH_PLACES` in the shader): each place's (warm pressure, warm
/// divergence, id).
pub type Places = [Vec<u32>; 3];

/// `select_band`, `merge_kept` with DFSPH: the (warm pressure, warm divergence, id) bits of the
/// particle whose position's w is `w` (its place, with the ghost bit).
pub fn at_place(w: f32, places: &Places) -> [u32; 3] {
    let place = (w.to_bits() & !GHOST_BIT) as usize;
    places.each_ref().map(|a| a[place])
}

/// `place_inserts`, `merge_kept` with DFSPH: the w of a merged position, its new `slot` (its
/// place from now on) with the ghost bit of its old `w`.
pub fn place_w(slot: u32, w: f32) -> f32 {
    f32::from_bits(slot | (w.to_bits() & GHOST_BIT))
}
