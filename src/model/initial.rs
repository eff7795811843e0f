//! The particles of a scene at t = 0: fluid blocks on jittered lattices, walls on regular
//! lattices, and the solid regions fluid must never enter.

use super::kernels::{sort_by_cell, KernelCoefficients};
use super::lattice::lattice;
use super::params::Grid;
use super::real::V3;
use super::scene::{Boundary, BoundaryVolume, Kernel, Scene};
use rand::{Rng, SeedableRng};
use rayon::prelude::*;

/// A solid region (inside of an obstacle or of a tank's walls) that fluid must never enter.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SolidRegion {
    pub min: [f64; 3],
    pub max: [f64; 3],
}

/// Particles of a scene at t = 0.
#[derive(Clone, Debug, Default)]
pub struct InitialState {
    pub fluid_positions: Vec<[f64; 3]>,
    pub fluid_velocities: Vec<[f64; 3]>,
    pub wall_positions: Vec<[f64; 3]>,
    pub wall_masses: Vec<f64>,
}

impl Scene {
    /// Regions fluid must never enter: the wall shells of containers and the obstacle boxes.
    pub fn solid_regions(&self) -> Vec<SolidRegion> {
        let mut out = Vec::new();
        for b in &self.boundary {
            match b {
                Boundary::Box { min, max, .. } => out.push(SolidRegion { min: *min, max: *max }),
                Boundary::Container { min, max, open_top, walls } => {
                    let s = walls.spacing.unwrap_or(self.physics.particle_spacing);
                    let l = self.wall_layers(walls) as f64 * s;
                    let top = if *open_top { max[1] } else { max[1] + l };
                    let slab = |a: usize, lo: f64, hi: f64| {
                        let mut r = SolidRegion { min: [min[0] - l, min[1] - l, min[2] - l], max: [max[0] + l, top, max[2] + l] };
                        r.min[a] = lo;
                        r.max[a] = hi;
                        r
                    };
                    out.push(slab(0, min[0] - l, min[0]));
                    out.push(slab(0, max[0], max[0] + l));
                    out.push(slab(1, min[1] - l, min[1]));
                    if !*open_top {
                        out.push(slab(1, max[1], max[1] + l));
                    }
                    out.push(slab(2, min[2] - l, min[2]));
                    out.push(slab(2, max[2], max[2] + l));
                }
                Boundary::Plane { .. } => {}
            }
        }
        out
    }

    /// The particles at t = 0: fluid on jittered lattices, walls on regular lattices.
    pub fn initial_state(&self) -> InitialState {
        let s = self.physics.particle_spacing;
        let mut rng = rand_pcg::Pcg64::seed_from_u64(self.seed);
        let mut st = InitialState::default();
        for b in &self.fluid {
            let j = b.jitter * s;
            for q in lattice(b.min, b.max, s) {
                let mut q = q;
                if j > 0.0 {
                    for c in q.iter_mut() {
                        *c += rng.random_range(-j..=j);
                    }
                }
                st.fluid_positions.push(q);
                st.fluid_velocities.push(b.velocity);
            }
        }
        for b in &self.boundary {
            let (min, max, walls, open_top, hollow_box) = match b {
                Boundary::Container { min, max, walls, open_top } => (min, max, walls, *open_top, false),
                Boundary::Box { min, max, walls } => (min, max, walls, false, true),
                Boundary::Plane { .. } => continue,
            };
            let ws = walls.spacing.unwrap_or(s);
            let l = self.wall_layers(walls) as f64 * ws;
            let mass = walls.rest_density.unwrap_or(self.physics.rest_density) * ws.powi(3);
            let inner = |q: &[f64; 3], lo: [f64; 3], hi: [f64; 3]| (0..3).all(|a| q[a] > lo[a] && q[a] < hi[a]);
            if hollow_box {
                // Obstacle: a shell of `layers` inside its faces; the core is never reached.
                let lo = [min[0] + l, min[1] + l, min[2] + l];
                let hi = [max[0] - l, max[1] - l, max[2] - l];
                for q in lattice(*min, *max, ws) {
                    if !inner(&q, lo, hi) {
                        st.wall_positions.push(q);
                        st.wall_masses.push(mass);
                    }
                }
            } else {
                let lo = [min[0] - l, min[1] - l, min[2] - l];
                let top = if open_top { max[1] } else { max[1] + l };
                let hi = [max[0] + l, top, max[2] + l];
                // The walls' first layer sits half a spacing outside the container's faces.
                let cavity_hi = [max[0], if open_top { f64::INFINITY } else { max[1] }, max[2]];
                for q in lattice(lo, hi, ws) {
                    if !inner(&q, *min, cavity_hi) {
                        st.wall_positions.push(q);
                        st.wall_masses.push(mass);
                    }
                }
            }
        }
        if self.physics.boundary_volume == BoundaryVolume::Akinci {
            st.wall_masses = akinci_volumes(&st.wall_positions, self.physics.kernel, self.physics.smoothing_length, &self.grid(), self.physics.rest_density);
        }
        st
    }
}

/// The mass each wall particle stands for in Akinci et al. 2012 (Eq. 4 and 5): its volume
/// V_b = 1 / sum_k W(|x_b - x_k|, h), summed over the wall particles k within h (b itself
/// included), times the fluid's rest density: psi_b = rho0 V_b. A wall particle with few wall
/// neighbours (a single layer, a sparse sampling) stands for more volume, so that a fluid
/// particle next to any wall sees about the density of a full kernel support. Walls never move:
/// computed once, in f64, and used by both backends.
pub fn akinci_volumes(walls: &[[f64; 3]], kernel: Kernel, h: f64, grid: &Grid, rest_density: f64) -> Vec<f64> {
    let k = KernelCoefficients::<f64>::new(kernel, h);
    let points: Vec<V3<f64>> = walls.iter().map(|&p| V3(p)).collect();
    let (order, starts) = sort_by_cell(grid, &points);
    let sorted: Vec<V3<f64>> = order.iter().map(|&i| points[i as usize]).collect();
    points
        .par_iter()
        .map(|&xb| {
            let mut sum = 0.0;
            for (k0, k1) in grid.stencil_runs(grid.cell_coords(xb)) {
                for xk in &sorted[starts[k0 as usize] as usize..starts[k1 as usize] as usize] {
                    sum += k.w((xb - *xk).length_squared());
                }
            }
            // b itself is always within h, so the sum is at least W(0) > 0.
            rest_density / sum
        })
        .collect()
}
