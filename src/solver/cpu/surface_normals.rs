//! Each fluid particle's surface normal, with `physics.surface_tension` above zero: twin of
//! wgsl/sim/surface_normals.wgsl.
//!
//! Akinci, Akinci & Teschner (2013, ACM Trans. Graph. 32(6)), the normal of their curvature term:
//!
//! ```text
//! n_i = h sum_j (m_j / rho_j) grad W_ij
//! ```
//!
//! over the fluid neighbours j within h. Deep inside the fluid the sum cancels; near the free
//! surface it points out of the fluid with a length that grows with the surface's curvature, so
//! the forces' curvature term -gamma (n_i - n_j) pulls a bulge in and a hollow out, and a
//! particle with no neighbours has the normal zero. Wall particles take no part: the surface
//! along a wall is not a free surface (adhesion acts there instead).
//!
//! Like the forces, the CPU sums either each particle over its stencil as the GPU walks it
//! ([`surface_normal`]) or eight particles of a cell at a time from the density stage's neighbour
//! lists, which hold the same neighbours in the same order: the same bits.

use super::cell_batches::{wide, ListChunk, NeighbourLists, RowMasks};
use crate::model::kernels::{KernelCoefficients, Neighbours};
use crate::model::lanes::{Pack, PackV3};
use crate::model::params::Grid;
use crate::model::real::{Real, V3};
use rayon::prelude::*;

pub struct SurfaceNormalsInput<'a, R> {
    pub kernel: &'a KernelCoefficients<R>,
    pub grid: &'a Grid<R>,
    pub fluid_mass: R,
    /// The fluid in cell order, with the densities of this step's density stage.
    pub fluid: Neighbours<'a, R>,
    pub densities: &'a [R],
    /// The density stage's neighbour lists and each particle's position
    /// (`ForcesInput::lists`, `ForcesInput::fluid_points`); without lists, each particle walks
    /// its stencil.
    pub lists: &'a NeighbourLists,
    pub fluid_points: &'a [[R; 4]],
}

/// The normal of fluid particle `i` (wgsl `surface_normal`).
pub fn surface_normal<R: Real>(input: &SurfaceNormalsInput<R>, i: usize) -> V3<R> {
    let kernel = input.kernel;
    let xi = input.fluid.positions[i];
    let mut sum = V3::zero();
    for (k0, k1) in input.grid.stencil_runs(input.grid.cell_coords(xi)) {
        for j in input.fluid.span(k0, k1) {
            let rij = xi - input.fluid.positions[j];
            let r2 = rij.length_squared();
            if r2 >= kernel.h2 {
                continue;
            }
            sum += kernel.grad_w(rij, r2.sqrt()) * (R::one() / input.densities[j]);
        }
    }
    sum * (kernel.h * input.fluid_mass)
}

/// Every fluid particle's normal, in the fluid's cell order (`normals` takes the fluid's length).
pub fn surface_normals<R: Real>(input: &SurfaceNormalsInput<R>, normals: &mut Vec<V3<R>>) {
    normals.resize(input.fluid.positions.len(), V3::zero());
    let lists = input.lists;
    if lists.chunks().is_empty() {
        normals.par_iter_mut().enumerate().for_each(|(i, out)| *out = surface_normal(input, i));
        return;
    }
    lists.chunks().par_iter().zip(lists.split(normals)).for_each(|(chunk, out)| {
        wide(
            #[inline(always)]
            || chunk_normals(input, chunk, out),
        );
    });
}

/// The normals of a chunk's particles, eight at a time from the neighbour lists: the sum of
/// [`surface_normal`] lane by lane, in the same order.
#[inline(always)]
fn chunk_normals<R: Real>(input: &SurfaceNormalsInput<R>, chunk: &ListChunk, normals: &mut [V3<R>]) {
    let first = chunk.particles().start;
    let kernel = input.kernel;
    let scale = kernel.h * input.fluid_mass;
    for batch in &chunk.batches {
        let (xi, _) = PackV3::gather_with_w(input.fluid_points, &batch.indices());
        let mut sum = PackV3::zero();
        let (rows, counts) = chunk.fluid_rows(batch);
        let mut live = RowMasks::new(&counts);
        for index in rows {
            let valid = live.next_row();
            let rij = xi - PackV3::gather_with_w(input.fluid_points, index).0;
            let r = rij.dot(rij).sqrt();
            let term = kernel.grad_w_lanes(rij, r).scale(Pack::splat(R::one()) / Pack::gather(input.densities, index));
            sum = PackV3::select(valid, sum + term, sum);
        }
        for (k, n) in sum.to_arrays().into_iter().enumerate().take(batch.lanes as usize) {
            normals[batch.first as usize + k - first] = V3(n) * scale;
        }
    }
}
