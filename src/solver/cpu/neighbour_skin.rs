//! Twin of wgsl/sim/neighbour_skin.wgsl: whether the lists and cells of the last rebuild may
//! miss a neighbour, from each fluid particle's displacement since that rebuild.

use crate::model::real::{Real, V3};

/// A rebuild is due once a displacement, or the spread of all of them, reaches this share of
/// the skin: a percent short of it, so that rounding cannot lose a neighbour at the very reach
/// of the lists (h (1 + skin)) or of the rebuild's cells.
pub const SKIN_MARGIN: f64 = 0.99;

/// The skin as the check tests it, a fraction of h less the margin (the GPU check's `SKIN`).
pub fn checked_skin(skin: f64) -> f64 {
    skin * SKIN_MARGIN
}

/// The distance `check_skin` tests against: `skin` h, less the margin (in `R` as the GPU
/// computes it, its override times h).
pub fn skin_reach<R: Real>(skin: f64, h: f64) -> R {
    R::of(checked_skin(skin)) * R::of(h)
}

/// What `check_skin` gathers over the fluid particles.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SkinCheck<R> {
    /// A particle has moved `reach` or more, or is not finite: a wall particle (which does not
    /// move) may have come within h of it from beyond the lists' reach.
    pub moved_far: bool,
    /// The smallest and largest displacement per axis (`None` without particles).
    pub extent: Option<([R; 3], [R; 3])>,
}

impl<R: Real> SkinCheck<R> {
    /// Whether the next step must rebuild: two fluid particles' displacements differ by at
    /// most the diagonal of the box that bounds all of them, so below `reach` no fluid pair has
    /// closed in by the skin either.
    pub fn rebuild_due(&self, reach: R) -> bool {
        let Some((lo, hi)) = self.extent else { return self.moved_far };
        let diagonal = V3([hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]]);
        self.moved_far || !(diagonal.length_squared() < reach * reach)
    }
}

/// `check_skin`: each particle's displacement from its place in `rebuild_positions`.
pub fn check_skin<R: Real>(positions: &[V3<R>], rebuild_positions: &[V3<R>], reach: R) -> SkinCheck<R> {
    let mut check = SkinCheck { moved_far: false, extent: None };
    for (x, x0) in positions.iter().zip(rebuild_positions) {
        let d = *x - *x0;
        // Not "greater": a position that is not finite leaves the skin too.
        check.moved_far |= !(d.dot(d) < reach * reach);
        let (lo, hi) = check.extent.get_or_insert((d.0, d.0));
        for axis in 0..3 {
            lo[axis] = lo[axis].min(d.0[axis]);
            hi[axis] = hi[axis].max(d.0[axis]);
        }
    }
    check
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lattice(n: usize, spacing: f64) -> Vec<V3<f64>> {
        let mut points = Vec::new();
        for i in 0..n {
            for j in 0..n {
                for k in 0..n {
                    points.push(V3([i as f64 * spacing, j as f64 * spacing, k as f64 * spacing]));
                }
            }
        }
        points
    }

    #[test]
    fn a_block_moving_as_one_keeps_its_lists_until_it_reaches_the_walls_skin() {
        let (h, skin) = (0.1, 0.1);
        let reach = skin_reach::<f64>(skin, h);
        let at = lattice(3, 0.05);
        let moved = |dx: f64| at.iter().map(|x| *x + V3([dx, 0.0, 0.0])).collect::<Vec<_>>();
        // Half the skin: a test of each displacement against s h / 2 would rebuild here.
        assert!(!check_skin(&moved(0.006), &at, reach).rebuild_due(reach));
        assert!(!check_skin(&moved(0.0098), &at, reach).rebuild_due(reach));
        assert!(check_skin(&moved(0.0100), &at, reach).rebuild_due(reach));
    }

    #[test]
    fn two_particles_closing_in_rebuild_once_they_may_have_met() {
        let (h, skin) = (0.1, 0.1);
        let reach = skin_reach::<f64>(skin, h);
        let at = [V3([0.0f64, 0.0, 0.0]), V3([1.0, 1.0, 1.0])];
        let moved = |dx: f64| [V3([dx / 2.0, 0.0, 0.0]), V3([1.0 - dx / 2.0, 1.0, 1.0])];
        assert!(!check_skin(&moved(0.0098), &at, reach).rebuild_due(reach));
        assert!(check_skin(&moved(0.0100), &at, reach).rebuild_due(reach));
        let mut lost = moved(0.0);
        lost[1].0[0] = f64::NAN;
        assert!(check_skin(&lost, &at, reach).rebuild_due(reach));
    }

    /// The guarantee the lists rest on, tried on random displacements: while no rebuild is
    /// due, every fluid pair within h now, and every fluid particle within h of a wall point,
    /// was within h (1 + skin) at the rebuild.
    #[test]
    fn no_neighbour_escapes_the_lists_while_no_rebuild_is_due() {
        let (h, skin) = (0.1f64, 0.1f64);
        let reach = skin_reach::<f64>(skin, h);
        let lists = h * (1.0 + skin);
        let mut seed = 12345u64;
        let mut random = move || {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        let walls: Vec<V3<f64>> = (0..40).map(|k| V3([k as f64 * 0.01, -0.05, 0.1])).collect();
        let (mut tried, mut kept) = (0, 0);
        for _ in 0..400 {
            let at: Vec<V3<f64>> = (0..30).map(|_| V3([random() * 0.4, random() * 0.15 - 0.1, random() * 0.2])).collect();
            // A shared drift (up to 0.9 s h) and a spread (up to 0.6 s h).
            let drift = V3([random() - 0.5, random() - 0.5, random() - 0.5]) * (1.8 * skin * h);
            let moved: Vec<V3<f64>> = at.iter().map(|x| *x + drift + V3([random() - 0.5, random() - 0.5, random() - 0.5]) * (0.6 * skin * h)).collect();
            tried += 1;
            if check_skin(&moved, &at, reach).rebuild_due(reach) {
                continue;
            }
            kept += 1;
            for i in 0..at.len() {
                for j in 0..at.len() {
                    if (moved[i] - moved[j]).length() < h {
                        assert!((at[i] - at[j]).length() < lists, "pair {i}, {j} escaped the lists");
                    }
                }
                for w in &walls {
                    if (moved[i] - *w).length() < h {
                        assert!((at[i] - *w).length() < lists, "particle {i} met a wall point from beyond the lists");
                    }
                }
            }
        }
        // Both outcomes occur, so the test exercises the guarantee.
        assert!(kept > 20 && kept < tried, "{kept} of {tried} kept their lists");
    }
}
