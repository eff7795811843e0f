//! When a DFSPH solve stops: after each Jacobi step the average error is compared with the
//! tolerance, between the minimum and maximum iteration counts. Twin of
//! wgsl/sim/dfsph_convergence.wgsl (`begin_solve`, `check_convergence`), which does the same on
//! the GPU with the error sum in the status words, and turns the dispatches of the iterations
//! after the last into empty ones.

use super::dfsph_shared::average_error;
use crate::model::state::SolveStats;

/// The limits of one solve.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SolveLimits {
    pub min_iterations: u32,
    pub max_iterations: u32,
    /// The largest error sum (fixed-point units) that meets the tolerance.
    pub threshold: u64,
    pub particles: usize,
}

/// A solve under way.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Solve {
    /// Jacobi steps done.
    pub iterations: u32,
    /// Whether another step is due.
    pub solving: bool,
}

/// Before the first error. Iterations count the velocity changes whose error has been
/// measured (as SPlisHSPlasH counts them): the warm start's is the first, so a warm-started
/// solve begins at 1; otherwise the first error is that of no stiffness at all, at 0.
pub fn begin_solve(warm_start: bool) -> Solve {
    Solve { iterations: warm_start as u32, solving: true }
}

/// After an error sum: the solve ends once at least `min_iterations` steps are done and the
/// error meets the tolerance, or at `max_iterations`; its iterations and error go into `stats`
/// (unconverged when it stopped at the limit above the tolerance). Otherwise one more step is
/// due. A solve that has ended stays ended.
pub fn check_convergence(limits: &SolveLimits, solve: &mut Solve, error_sum: u64, stats: &mut SolveStats) {
    if !solve.solving {
        return;
    }
    let met = error_sum <= limits.threshold;
    let k = solve.iterations;
    if (k >= limits.min_iterations && met) || k >= limits.max_iterations {
        solve.solving = false;
        stats.total += k as u64;
        stats.max = stats.max.max(k);
        stats.last = k;
        stats.last_error = average_error(error_sum, limits.particles);
        if !met {
            stats.unconverged += 1;
        }
    } else {
        solve.iterations = k + 1;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::solver::cpu::dfsph_shared::{average_error, error_threshold, error_units};

    fn limits(min_iterations: u32, max_iterations: u32) -> SolveLimits {
        SolveLimits { min_iterations, max_iterations, threshold: error_threshold(1e-4, 1000), particles: 1000 }
    }

    #[test]
    fn a_solve_runs_its_minimum_then_stops_at_the_tolerance() {
        let l = limits(2, 10);
        let (mut solve, mut stats) = (begin_solve(false), SolveStats::default());
        // Already within the tolerance at 0 iterations: the minimum still runs.
        for _ in 0..2 {
            check_convergence(&l, &mut solve, 0, &mut stats);
            assert!(solve.solving);
        }
        check_convergence(&l, &mut solve, l.threshold, &mut stats);
        assert!(!solve.solving);
        assert_eq!((stats.total, stats.last, stats.max, stats.unconverged), (2, 2, 2, 0));
        assert!((stats.last_error - 1e-4).abs() < 1e-9);
        // Ended stays ended.
        check_convergence(&l, &mut solve, u64::MAX, &mut stats);
        assert_eq!(stats.total, 2);
    }

    #[test]
    fn a_solve_stops_at_its_limit_unconverged() {
        let l = limits(1, 3);
        let (mut solve, mut stats) = (begin_solve(true), SolveStats::default());
        assert_eq!(solve.iterations, 1, "the warm start is the first iteration");
        while solve.solving {
            check_convergence(&l, &mut solve, l.threshold + 1, &mut stats);
        }
        assert_eq!((stats.total, stats.last, stats.unconverged), (3, 3, 1));
    }

    #[test]
    fn errors_are_fixed_point_and_clamped() {
        assert_eq!(error_units(0.0f32), 0);
        assert_eq!(error_units(-1.0f64), 0);
        assert_eq!(error_units(1.0f64), 1 << 30);
        assert_eq!(error_units(100.0f32), 3 << 30);
        assert_eq!(error_units(f64::NAN), 0);
        assert_eq!(error_units(1e-4f32), (1e-4f32 * (1u64 << 30) as f32) as u64);
        let n = 12345;
        assert!((average_error(error_threshold(1e-4, n), n) - 1e-4).abs() < 1e-12);
    }
}
