//! Kernel properties and the density of a particle at rest in a lattice.

use wgsph::model::kernels::KernelCoefficients;
use wgsph::model::real::V3;
use wgsph::model::scene::Kernel;

const KERNELS: [Kernel; 3] = Kernel::ALL;

/// Points of a simple cubic lattice of spacing s within distance `reach` of the origin.
fn lattice(s: f64, reach: f64) -> Vec<V3<f64>> {
    let n = (reach / s).ceil() as i64 + 1;
    let mut out = Vec::new();
    for i in -n..=n {
        for j in -n..=n {
            for k in -n..=n {
                let p = V3::new(i as f64 * s, j as f64 * s, k as f64 * s);
                if p.length() < reach {
                    out.push(p);
                }
            }
        }
    }
    out
}

#[test]
fn kernels_are_normalised_over_a_filled_lattice() {
    // sum_k (m_k / rho_k) W = s^3 sum_k W must approximate the integral of W, 1, when the
    // lattice resolves the kernel (h = 4 s), and stay close at the usual h = 2 s.
    for kind in KERNELS {
        let h = 1.0;
        let k = KernelCoefficients::<f64>::new(kind, h);
        for (ratio, tol) in [(4.0, 0.01), (2.0, 0.05)] {
            let s = h / ratio;
            let sum: f64 = lattice(s, h).iter().map(|p| s * s * s * k.w(p.length_squared())).sum();
            assert!((sum - 1.0).abs() < tol, "{kind:?} h/s = {ratio}: sum of V W = {sum}");
        }
    }
}

#[test]
fn kernel_integral_is_one_by_quadrature() {
    // 4 pi int_0^h W(r) r^2 dr = 1, independent of any lattice.
    for kind in KERNELS {
        let h = 0.37;
        let k = KernelCoefficients::<f64>::new(kind, h);
        let n = 20000;
        let dr = h / n as f64;
        let integral: f64 = (0..n)
            .map(|i| {
                let r = (i as f64 + 0.5) * dr;
                4.0 * std::f64::consts::PI * r * r * k.w(r * r) * dr
            })
            .sum();
        assert!((integral - 1.0).abs() < 1e-6, "{kind:?}: integral {integral}");
    }
}

#[test]
fn gradient_sums_vanish_in_the_interior_and_are_antisymmetric() {
    for kind in KERNELS {
        let h = 1.0;
        let k = KernelCoefficients::<f64>::new(kind, h);
        let s = h / 3.0;
        let pts = lattice(s, 1.5 * h);
        let sum = pts.iter().fold(V3::zero(), |acc, p| {
            let rij = V3::zero() - *p;
            acc + k.grad_w(rij, rij.length())
        });
        let scale: f64 = pts.iter().map(|p| k.grad_w(-*p, p.length()).length()).sum();
        assert!(scale > 1.0, "{kind:?}: the gradients must not all vanish");
        assert!(sum.length() < 1e-9 * scale, "{kind:?}: sum of grad W = {:?}", sum);
        // grad_i W(x_i - x_j) = -grad_j W(x_j - x_i), and W depends on |r| only.
        let r = V3::new(0.21, -0.13, 0.34);
        let g1 = k.grad_w(r, r.length());
        let g2 = k.grad_w(-r, r.length());
        assert!((g1 + g2).length() < 1e-12 * g1.length());
        assert_eq!(k.w(r.length_squared()), k.w((-r).length_squared()));
        // Points down the slope: towards the neighbour means away from the centre.
        assert!(g1.dot(r) < 0.0);
    }
}

#[test]
fn gradient_at_zero_distance_is_zero_not_nan() {
    for kind in KERNELS {
        let k = KernelCoefficients::<f32>::new(kind, 0.1);
        let g = k.grad_w(V3::zero(), 0.0);
        assert_eq!(g, V3::zero());
        assert!(k.w(0.0).is_finite() && k.w(0.0) > 0.0);
    }
}

#[test]
fn kernels_vanish_at_and_beyond_the_support() {
    for kind in KERNELS {
        let h = 0.04;
        let k = KernelCoefficients::<f64>::new(kind, h);
        assert_eq!(k.w(h * h), 0.0);
        assert_eq!(k.w(1.5 * h * h), 0.0);
        let r = V3::new(h, 0.0, 0.0);
        assert_eq!(k.grad_w(r, h), V3::zero());
        assert!(k.w(0.99 * 0.99 * h * h) > 0.0);
        // Continuity of the cubic spline at q = 1/2.
        let below = k.w((0.5 * h - 1e-9).powi(2));
        let above = k.w((0.5 * h + 1e-9).powi(2));
        assert!((below - above).abs() < 1e-6 * below);
    }
}

#[test]
fn density_inside_a_rest_lattice_is_near_rest_density() {
    // The dam-break resolution (h = 2 s, m = rho0 s^3): a particle deep inside a lattice.
    let (rho0, s) = (1000.0, 0.02);
    let h = 2.0 * s;
    let m = rho0 * s * s * s;
    for kind in KERNELS {
        let k = KernelCoefficients::<f64>::new(kind, h);
        let rho: f64 = lattice(s, h).iter().map(|p| m * k.w(p.length_squared())).sum();
        assert!((rho / rho0 - 1.0).abs() < 0.05, "{kind:?}: rho = {rho}");
    }
}

#[test]
fn the_gradient_is_the_derivative_of_w_for_the_one_function_kernels() {
    // The cubic spline and Wendland's function take W and grad W from one function (Mueller's
    // pair does not: poly6 and the spiky gradient): grad W . r/|r| = dW/dr, by central
    // differences over the whole support.
    for kind in KERNELS.into_iter().filter(|&k| k != Kernel::Mueller) {
        let h = 0.3;
        let k = KernelCoefficients::<f64>::new(kind, h);
        let dir = V3::new(2.0, -1.0, 2.0) * (1.0 / 3.0);
        let scale = k.w(0.0) / h;
        for i in 1..40 {
            let r = h * i as f64 / 40.0;
            let e = 1e-6 * h;
            let numeric = (k.w((r + e) * (r + e)) - k.w((r - e) * (r - e))) / (2.0 * e);
            let analytic = k.grad_w(dir * r, r).dot(dir);
            assert!((numeric - analytic).abs() < 1e-6 * scale, "{kind:?} at r = {r}: dW/dr {numeric}, grad W . r/|r| {analytic}");
        }
    }
}
