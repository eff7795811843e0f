//! Kernels, equation of state and grid helpers: the CPU twin of wgsl/common.wgsl.
//!
//! h is the support radius: every kernel is zero for r >= h.

use crate::real::{Real, V3};
use crate::scene::{EquationOfState, Kernel, Params};
use std::f64::consts::PI;

/// Kernel constants for one support radius, precomputed once per scene.
#[derive(Clone, Copy, Debug)]
pub struct KernelCoefficients<R> {
    pub h: R,
    pub h2: R,
    pub kind: Kernel,
    /// poly6: 315 / (64 pi h^9); cubic: 8 / (pi h^3).
    pub w: R,
    /// spiky: -45 / (pi h^6); cubic: 48 / (pi h^4), the derivative's factor.
    pub grad: R,
    /// viscosity Laplacian: 45 / (pi h^6).
    pub lap: R,
}

impl<R: Real> KernelCoefficients<R> {
    pub fn new(kind: Kernel, h: f64) -> Self {
        let (w, grad, lap) = match kind {
            Kernel::Mueller => (315.0 / (64.0 * PI * h.powi(9)), -45.0 / (PI * h.powi(6)), 45.0 / (PI * h.powi(6))),
            Kernel::CubicSpline => (8.0 / (PI * h.powi(3)), 48.0 / (PI * h.powi(4)), 0.0),
        };
        KernelCoefficients { h: R::of(h), h2: R::of(h * h), kind, w: R::of(w), grad: R::of(grad), lap: R::of(lap) }
    }

    /// W(r) from r^2 (Mueller 2003 Eq. 20 poly6, or Monaghan 1992 cubic spline).
    pub fn w(&self, r2: R) -> R {
        if r2 >= self.h2 {
            return R::zero();
        }
        match self.kind {
            Kernel::Mueller => {
                let d = self.h2 - r2;
                self.w * d * d * d
            }
            Kernel::CubicSpline => {
                let q = r2.sqrt() / self.h;
                let one = R::one();
                if q <= R::of(0.5) {
                    self.w * (R::of(6.0) * (q * q * q - q * q) + one)
                } else {
                    let d = one - q;
                    self.w * R::of(2.0) * d * d * d
                }
            }
        }
    }

    /// grad W at r_ij = x_i - x_j (|r_ij| = r). Zero at r = 0, where the direction is undefined.
    pub fn grad_w(&self, rij: V3<R>, r: R) -> V3<R> {
        if r >= self.h || r <= R::of(1e-12) * self.h {
            return V3::zero();
        }
        let dwdr = match self.kind {
            // Spiky (Mueller 2003 Eq. 21): dW/dr = -45/(pi h^6) (h - r)^2.
            Kernel::Mueller => {
                let d = self.h - r;
                self.grad * d * d
            }
            Kernel::CubicSpline => {
                let q = r / self.h;
                let one = R::one();
                if q <= R::of(0.5) {
                    self.grad * q * (R::of(3.0) * q - R::of(2.0))
                } else {
                    let d = one - q;
                    -self.grad * d * d
                }
            }
        };
        rij * (dwdr / r)
    }

    /// Laplacian of the viscosity kernel (Mueller 2003 Eq. 22): 45/(pi h^6) (h - r).
    pub fn lap_w(&self, r: R) -> R {
        if r >= self.h {
            R::zero()
        } else {
            self.lap * (self.h - r)
        }
    }
}

/// Pressure from density: report Eq. 8 (linear) or Eq. 9 (Tait, exponent 7).
pub fn pressure<R: Real>(density: R, rest_density: R, stiffness: R, eos: EquationOfState, clamp: bool) -> R {
    let ratio = density / rest_density;
    let p = match eos {
        EquationOfState::Linear => stiffness * (ratio - R::one()),
        EquationOfState::Tait => {
            let r2 = ratio * ratio;
            let r4 = r2 * r2;
            stiffness * (r4 * r2 * ratio - R::one())
        }
    };
    if clamp && p < R::zero() {
        R::zero()
    } else {
        p
    }
}

/// Cell key of a point: clamped integer cell coordinates, x fastest (same formula as the GPU).
pub fn cell_coords<R: Real>(grid: &GridR<R>, p: V3<R>) -> [u32; 3] {
    let mut c = [0u32; 3];
    for a in 0..3 {
        let f = ((p.0[a] - grid.origin.0[a]) * grid.inv_cell).floor();
        let max = R::of((grid.dims[a] - 1) as f64);
        let f = if f.is_nan() { R::zero() } else { f.max(R::zero()).min(max) };
        c[a] = f.to64() as u32;
    }
    c
}

/// The grid in the solver's float type.
#[derive(Clone, Copy, Debug)]
pub struct GridR<R> {
    pub origin: V3<R>,
    pub inv_cell: R,
    pub dims: [u32; 3],
}

impl<R: Real> GridR<R> {
    pub fn new(params: &Params) -> Self {
        GridR {
            origin: V3::from64(params.grid.origin),
            inv_cell: R::of(1.0 / params.grid.cell_size),
            dims: params.grid.dims,
        }
    }
    pub fn cell_count(&self) -> usize {
        self.dims.iter().map(|&d| d as usize).product()
    }
    pub fn key(&self, c: [u32; 3]) -> u32 {
        c[0] + self.dims[0] * (c[1] + self.dims[1] * c[2])
    }
    /// The 9 contiguous key ranges (x-runs of up to 3 cells) that cover the 27-cell stencil of
    /// cell `c`: each run is one span of the cell-sorted arrays.
    pub fn stencil_runs(&self, c: [u32; 3]) -> impl Iterator<Item = (u32, u32)> + '_ {
        let x0 = c[0].saturating_sub(1);
        let x1 = (c[0] + 1).min(self.dims[0] - 1);
        let (y0, y1) = (c[1].saturating_sub(1), (c[1] + 1).min(self.dims[1] - 1));
        let (z0, z1) = (c[2].saturating_sub(1), (c[2] + 1).min(self.dims[2] - 1));
        (z0..=z1).flat_map(move |z| (y0..=y1).map(move |y| (self.key([x0, y, z]), self.key([x1, y, z]) + 1)))
    }
}
