//! The density and pressure of every particle into arrays of their own. Twin of
//! wgsl/sim/fields.wgsl, whose GPU step keeps no pressure array: the pressure is the equation of
//! state's for the density (report Eq. 8 or 9), here `pressure`.

use crate::model::real::Real;

/// `density_out[i] = densities[i]`, `pressure_out[i] = pressure(densities[i])`.
pub fn output_fields<R: Real>(densities: &[R], pressure: impl Fn(R) -> R, density_out: &mut Vec<R>, pressure_out: &mut Vec<R>) {
    density_out.clear();
    density_out.extend_from_slice(densities);
    pressure_out.clear();
    pressure_out.extend(densities.iter().map(|&rho| pressure(rho)));
}
