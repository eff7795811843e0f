//! Kernels, equations of state, cell coordinates, stencil runs and the counting sort on the host:
//! the formulas of wgsl/shared/common.wgsl, used by the CPU reference, by the GPU host (the
//! f32 constants of its parameter block, the walls sorted once) and by the profile.
//!
//! h is the support radius: every kernel is zero for r >= h.

use super::lanes::{Pack, PackV3};
use super::params::Grid;
use super::real::{Real, V3};
use super::scene::{EquationOfState, Kernel};
use std::f64::consts::PI;
use std::ops::Range;

/// Kernel constants for one support radius, precomputed once per scene.
#[derive(Clone, Copy, Debug)]
pub struct KernelCoefficients<R> {
    pub h: R,
    pub h2: R,
    pub kind: Kernel,
    /// poly6: 315 / (64 pi h^9); cubic: 8 / (pi h^3); Wendland: 21 / (2 pi h^3).
    pub w: R,
    /// spiky: -45 / (pi h^6); cubic: 48 / (pi h^4); Wendland: -210 / (pi h^4), the
    /// derivative's factor.
    pub grad: R,
    /// viscosity Laplacian: 45 / (pi h^6).
    pub lap: R,
}

impl<R: Real> KernelCoefficients<R> {
    pub fn new(kind: Kernel, h: f64) -> Self {
        let (w, grad, lap) = match kind {
            Kernel::Mueller => (315.0 / (64.0 * PI * h.powi(9)), -45.0 / (PI * h.powi(6)), 45.0 / (PI * h.powi(6))),
            Kernel::CubicSpline => (8.0 / (PI * h.powi(3)), 48.0 / (PI * h.powi(4)), 0.0),
            // W = 21 / (2 pi h^3) (1 - q)^4 (1 + 4 q), so dW/dr = -210 / (pi h^4) q (1 - q)^3.
            Kernel::Wendland => (21.0 / (2.0 * PI * h.powi(3)), -210.0 / (PI * h.powi(4)), 0.0),
        };
        KernelCoefficients { h: R::of(h), h2: R::of(h * h), kind, w: R::of(w), grad: R::of(grad), lap: R::of(lap) }
    }

    /// W(r) from r^2 (Mueller 2003 Eq. 20 poly6, Monaghan 1992 cubic spline, or Wendland 1995
    /// C2).
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
            Kernel::Wendland => {
                let q = r2.sqrt() / self.h;
                let d = R::one() - q;
                let d2 = d * d;
                self.w * d2 * d2 * (R::one() + R::of(4.0) * q)
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
            Kernel::Wendland => {
                let q = r / self.h;
                let d = R::one() - q;
                self.grad * q * d * d * d
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

/// The shape of Akinci et al.'s cohesion spline (2013) at q = r / h < 1, without its
/// factor 32 / (pi h^3): (1 - q)^3 q^3 beyond q = 1/2, 2 (1 - q)^3 q^3 - 1/64 within, so that
/// particles closer than about 0.3 h repel and farther ones attract. Twin of `cohesion_shape` in
/// wgsl/shared/common.wgsl.
pub fn cohesion_shape<R: Real>(q: R) -> R {
    let d = R::one() - q;
    let t = d * d * d * q * q * q;
    if q > R::of(0.5) {
        t
    } else {
        R::of(2.0) * t - R::of(1.0 / 64.0)
    }
}

/// The shape of Akinci et al.'s adhesion spline (2013) at q = r / h, without its factor
/// 0.007 / h^3: (-4 q^2 + 6 q - 2)^(1/4) for 1/2 < q < 1, zero elsewhere (a pull that peaks at
/// 3/4 h). Twin of `adhesion_shape` in wgsl/shared/common.wgsl.
pub fn adhesion_shape<R: Real>(q: R) -> R {
    if q > R::of(0.5) && q < R::one() {
        (R::of(6.0) * q - R::of(4.0) * q * q - R::of(2.0)).max(R::zero()).sqrt().sqrt()
    } else {
        R::zero()
    }
}

/// The kernel on eight distances at once ([`Pack`] lanes): each lane is the scalar function's
/// value bit for bit (both branches computed, one kept), for the CPU path's batches of a cell's
/// particles.
impl<R: Real> KernelCoefficients<R> {
    /// [`KernelCoefficients::w`] lane by lane.
    #[inline(always)]
    pub fn w_lanes(&self, r2: Pack<R>) -> Pack<R> {
        let outside = r2.ge(Pack::splat(self.h2));
        let w = Pack::splat(self.w);
        let inside = match self.kind {
            Kernel::Mueller => {
                let d = Pack::splat(self.h2) - r2;
                w * d * d * d
            }
            Kernel::CubicSpline => {
                let q = r2.sqrt() / Pack::splat(self.h);
                let one = Pack::splat(R::one());
                let near = w * (Pack::splat(R::of(6.0)) * (q * q * q - q * q) + one);
                let d = one - q;
                let far = w * Pack::splat(R::of(2.0)) * d * d * d;
                Pack::select(q.le(Pack::splat(R::of(0.5))), near, far)
            }
            Kernel::Wendland => {
                let q = r2.sqrt() / Pack::splat(self.h);
                let one = Pack::splat(R::one());
                let d = one - q;
                let d2 = d * d;
                w * d2 * d2 * (one + Pack::splat(R::of(4.0)) * q)
            }
        };
        Pack::select(outside, Pack::zero(), inside)
    }

    /// [`KernelCoefficients::grad_w`] lane by lane.
    #[inline(always)]
    pub fn grad_w_lanes(&self, rij: PackV3<R>, r: Pack<R>) -> PackV3<R> {
        let h = Pack::splat(self.h);
        let degenerate = r.ge(h).or(r.le(Pack::splat(R::of(1e-12) * self.h)));
        let grad = Pack::splat(self.grad);
        let dwdr = match self.kind {
            Kernel::Mueller => {
                let d = h - r;
                grad * d * d
            }
            Kernel::CubicSpline => {
                let q = r / h;
                let one = Pack::splat(R::one());
                let near = grad * q * (Pack::splat(R::of(3.0)) * q - Pack::splat(R::of(2.0)));
                let d = one - q;
                let far = Pack::splat(-self.grad) * d * d;
                Pack::select(q.le(Pack::splat(R::of(0.5))), near, far)
            }
            Kernel::Wendland => {
                let q = r / h;
                let d = Pack::splat(R::one()) - q;
                grad * q * d * d * d
            }
        };
        PackV3::select(degenerate, PackV3::zero(), rij.scale(dwdr / r))
    }

    /// [`KernelCoefficients::lap_w`] lane by lane.
    #[inline(always)]
    pub fn lap_w_lanes(&self, r: Pack<R>) -> Pack<R> {
        let h = Pack::splat(self.h);
        Pack::select(r.ge(h), Pack::zero(), Pack::splat(self.lap) * (h - r))
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

/// The density above rest density at which the equation of state gives the pressure `p`:
/// rho0 p / k (linear) or rho0 ((1 + p / k)^(1/7) - 1) (Tait). With p = rho0 g . (x_j - x_i),
/// the hydrostatic density difference between two particles (Fourtakas et al. 2019, Eq. 12);
/// with p = rho0 |g| depth, a still column's density at that depth.
pub fn density_above_rest<R: Real>(p: R, rest_density: R, stiffness: R, eos: EquationOfState) -> R {
    match eos {
        EquationOfState::Linear => rest_density * p / stiffness,
        EquationOfState::Tait => rest_density * ((R::one() + p / stiffness).powf(R::one() / R::of(7.0)) - R::one()),
    }
}

impl<R: Real> Grid<R> {
    /// Integer cell coordinates of a point, clamped into the grid so that a particle outside
    /// the domain still has a valid cell (it is counted as escaped elsewhere); the same formula
    /// as the GPU's `cell_coords`.
    pub fn cell_coords(&self, p: V3<R>) -> [u32; 3] {
        [0, 1, 2].map(|axis| self.layer(p, axis))
    }
    /// The cell coordinate of a point along one `axis` (its cell layer), as `cell_coords` gives
    /// it: the exchange across ranks asks only this, for every particle near a slab's faces.
    pub fn layer(&self, p: V3<R>, axis: usize) -> u32 {
        let f = (p.0[axis] - self.origin.0[axis]) * self.inv_cell;
        // The floor clamped into the grid, without a floor: truncation is the floor from 0 up,
        // and the saturating cast takes what lies below 0 (and NaN) to 0, as the clamp did.
        // (`floor` is a libm call on CPUs without SSE4.1, once per coordinate of every
        // particle the binning and the exchange place.)
        (f.to64() as u32).min(self.dims[axis] - 1)
    }
    /// The cell key of cell coordinates, x fastest.
    pub fn key(&self, c: [u32; 3]) -> u32 {
        c[0] + self.dims[0] * (c[1] + self.dims[1] * c[2])
    }
    /// The cell key of a point.
    pub fn key_of(&self, p: V3<R>) -> u32 {
        self.key(self.cell_coords(p))
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

/// The counting sort by cell, in three steps that the GPU stages mirror (wgsl/sim/bin_count,
/// prefix_sum, bin_scatter): `keys[i]` = cell of point i with `counts[key]` incremented
/// (`counts` must start at zero).
pub fn count_cells<R: Real>(grid: &Grid<R>, positions: &[V3<R>], keys: &mut [u32], counts: &mut [u32]) {
    for (i, p) in positions.iter().enumerate() {
        let k = grid.key_of(*p);
        keys[i] = k;
        counts[k as usize] += 1;
    }
}

/// `starts[c]` = sum of `counts[..c]`, and `starts[counts.len()]` = the total, so that cell c's
/// points are `starts[c]..starts[c + 1]` and any run of cells is one contiguous span.
pub fn exclusive_scan(counts: &[u32], starts: &mut [u32]) {
    assert_eq!(starts.len(), counts.len() + 1);
    let mut acc = 0u32;
    for (s, &c) in starts.iter_mut().zip(counts) {
        *s = acc;
        acc += c;
    }
    starts[counts.len()] = acc;
}

/// `sorted[j]` = index of the point that goes to slot j of the cell-ordered arrays. Stable:
/// inside a cell, points keep their current order.
pub fn scatter_by_cell(keys: &[u32], starts: &[u32], sorted: &mut [u32]) {
    let mut cursor: Vec<u32> = starts[..starts.len() - 1].to_vec();
    for (i, &k) in keys.iter().enumerate() {
        let slot = &mut cursor[k as usize];
        sorted[*slot as usize] = i as u32;
        *slot += 1;
    }
}

/// Sorts points by cell (stable counting sort) and returns the permutation and the cell
/// starts (the walls, sorted once on the host by both paths).
pub fn sort_by_cell<R: Real>(grid: &Grid<R>, positions: &[V3<R>]) -> (Vec<u32>, Vec<u32>) {
    let mut keys = vec![0u32; positions.len()];
    let mut counts = vec![0u32; grid.cell_count()];
    let mut starts = vec![0u32; grid.cell_count() + 1];
    let mut sorted = vec![0u32; positions.len()];
    count_cells(grid, positions, &mut keys, &mut counts);
    exclusive_scan(&counts, &mut starts);
    scatter_by_cell(&keys, &starts, &mut sorted);
    (sorted, starts)
}

/// Particles sorted by cell with the start of every cell: `starts[c]..starts[c + 1]`.
#[derive(Clone, Copy)]
pub struct Neighbours<'a, R> {
    pub positions: &'a [V3<R>],
    pub starts: &'a [u32],
}

impl<R> Neighbours<'_, R> {
    /// The particles of the cells with keys `k0..k1` (a contiguous run of cells).
    pub fn span(&self, k0: u32, k1: u32) -> Range<usize> {
        self.starts[k0 as usize] as usize..self.starts[k1 as usize] as usize
    }
}

/// s^3 sum over the simple cubic lattice of spacing s of W(|x|, h), for h = `h_over_spacing` s:
/// the kernel's integral, 1, as the lattice sees it. Past 8 spacings the lattice resolves every
/// kernel to within 0.1 %, and 1 is returned (the sum would cost (2 h / s)^3 terms).
pub fn lattice_kernel_sum(kernel: Kernel, h_over_spacing: f64) -> f64 {
    if !(h_over_spacing.is_finite() && h_over_spacing > 0.0) || h_over_spacing > 8.0 {
        return 1.0;
    }
    let w = KernelCoefficients::<f64>::new(kernel, h_over_spacing);
    let n = h_over_spacing.ceil() as i64;
    let mut sum = 0.0;
    for i in -n..=n {
        for j in -n..=n {
            for k in -n..=n {
                sum += w.w((i * i + j * j + k * k) as f64);
            }
        }
    }
    sum
}

/// The viscosity's nu as the pair sums use it: with the gradient form (the cubic spline's and
/// Wendland's), 2 (d + 2) nu = 10 nu (Monaghan 2005, Eq. 6.3); the twin of `viscous_nu` in
/// wgsl/shared/common.wgsl.
pub fn viscous_nu<R: Real>(kernel: Kernel, viscosity: R) -> R {
    if kernel.gradient_viscosity() {
        R::of(10.0) * viscosity
    } else {
        viscosity
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The cell layer without a floor call is the floor clamped into the grid, for every
    /// value a coordinate can take: inside, on a cell's edge, just below 0, far outside, NaN
    /// and the infinities, in both float types.
    fn layer_is_the_clamped_floor<R: Real>() {
        let grid: Grid<R> = Grid { origin: V3::from64([-0.3, 0.0, 2.0]), cell_size: R::of(0.1), inv_cell: R::of(10.0), dims: [7, 1, 40] };
        let clamped_floor = |x: R, axis: usize| {
            let f = ((x - grid.origin.0[axis]) * grid.inv_cell).floor();
            if f.is_nan() { 0 } else { f.max(R::zero()).min(R::of((grid.dims[axis] - 1) as f64)).to64() as u32 }
        };
        let mut values: Vec<f64> = vec![f64::NAN, f64::INFINITY, f64::NEG_INFINITY, f64::MAX, -f64::MAX, 1e30, -1e30, 0.0, -0.0, f64::MIN_POSITIVE, -f64::MIN_POSITIVE];
        values.extend((-200..800).map(|k| k as f64 * 0.0123 - 0.5));
        values.extend((-10..70).map(|k| -0.3 + k as f64 * 0.1));
        for axis in 0..3 {
            for &v in &values {
                let x = R::of(v);
                let mut p = V3::from64([0.0; 3]);
                p.0[axis] = x;
                assert_eq!(grid.layer(p, axis), clamped_floor(x, axis), "axis {axis}, coordinate {v}");
            }
        }
    }

    #[test]
    fn layer_is_the_clamped_floor_in_f32_and_f64() {
        layer_is_the_clamped_floor::<f32>();
        layer_is_the_clamped_floor::<f64>();
    }
}
