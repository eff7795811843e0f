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

use crate::model::kernels::{KernelCoefficients, Neighbours};
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

/// Every fluid particle's normal, in the fluid's cell order.
pub fn surface_normals<R: Real>(input: &SurfaceNormalsInput<R>, normals: &mut [V3<R>]) {
    normals.par_iter_mut().enumerate().for_each(|(i, out)| *out = surface_normal(input, i));
}
