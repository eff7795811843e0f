//! Each wall particle's pressure and density extrapolated from the fluid around it, with
//! `physics.boundary_pressure = "adami"`: twin of wgsl/sim/wall_pressure.wgsl.
//!
//! The generalised wall boundary of Adami, Hu & Adams (2012, J. Comput. Phys. 231, Eq. 27):
//!
//!     p_w = (sum_f p_f W_wf + (g - a_w) . sum_f rho_f r_wf W_wf) / sum_f W_wf,   r_wf = x_w - x_f
//!
//! over the fluid particles f within h of wall particle w; walls are at rest (a_w = 0). The
//! first term is the Shepard average of the fluid's pressure, the second carries it from the
//! fluid to the wall particle along gravity (hydrostatics), so that a wall below water pushes
//! with the pressure of its own depth. The wall particle's density is the one the equation of
//! state gives p_w (Adami et al. 2012, Eq. 28). A wall particle with no fluid within h has the
//! pressure 0 and the rest density; with clamped negative pressure a negative p_w (a wall above
//! the fluid's centre of weight) is clamped as the fluid's is.

use crate::model::kernels::{density_above_rest, KernelCoefficients, Neighbours};
use crate::model::params::Grid;
use crate::model::real::{Real, V3};
use crate::model::scene::EquationOfState;
use rayon::prelude::*;

pub struct WallPressureInput<'a, R> {
    pub kernel: &'a KernelCoefficients<R>,
    pub grid: &'a Grid<R>,
    pub rest_density: R,
    pub stiffness: R,
    pub eos: EquationOfState,
    pub clamp_negative_pressure: bool,
    pub gravity: V3<R>,
    /// The fluid in cell order, with the fields of this step's density stage.
    pub fluid: Neighbours<'a, R>,
    pub densities: &'a [R],
    pub pressures: &'a [R],
    /// The wall particles' positions (sorted by cell; their starts are not needed: each wall
    /// particle visits the fluid's cells).
    pub wall_positions: &'a [V3<R>],
}

/// The pressure and density of wall particle `w` (wgsl `wall_state`).
pub fn wall_state<R: Real>(input: &WallPressureInput<R>, w: usize) -> [R; 2] {
    let kernel = input.kernel;
    // Terms the scene does not use are skipped, as they are compiled out on the GPU.
    let gravity = input.gravity != V3::zero();
    let xw = input.wall_positions[w];
    let mut weights = R::zero();
    let mut pressure = R::zero();
    let mut hydrostatic = V3::zero();
    for (k0, k1) in input.grid.stencil_runs(input.grid.cell_coords(xw)) {
        for f in input.fluid.span(k0, k1) {
            let r_wf = xw - input.fluid.positions[f];
            let r2 = r_wf.length_squared();
            if r2 >= kernel.h2 {
                continue;
            }
            let weight = kernel.w(r2);
            weights = weights + weight;
            pressure = pressure + input.pressures[f] * weight;
            if gravity {
                hydrostatic += r_wf * (input.densities[f] * weight);
            }
        }
    }
    if weights <= R::zero() {
        return [R::zero(), input.rest_density];
    }
    let mut p = pressure;
    if gravity {
        p = p + input.gravity.dot(hydrostatic);
    }
    p = p / weights;
    if input.clamp_negative_pressure && p < R::zero() {
        p = R::zero();
    }
    [p, input.rest_density + density_above_rest(p, input.rest_density, input.stiffness, input.eos)]
}

/// Every wall particle's pressure and density (`fields[w] = [p_w, rho_w]`), in the walls' cell
/// order.
pub fn wall_pressure<R: Real>(input: &WallPressureInput<R>, fields: &mut [[R; 2]]) {
    fields.par_iter_mut().enumerate().for_each(|(w, out)| *out = wall_state(input, w));
}
