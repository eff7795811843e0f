//! Twin of wgsl/sim/neighbour_skin.wgsl: whether a particle has moved half the neighbour skin
//! since the last rebuild, so that the lists and cells of that rebuild may miss a neighbour.

use crate::model::real::{Real, V3};

/// `check_skin`: true where some particle of `positions` lies skin h / 2 or more from its
/// place in `rebuild_positions` (or is not finite).
pub fn check_skin<R: Real>(positions: &[V3<R>], rebuild_positions: &[V3<R>], skin: R, h: R) -> bool {
    let reach = R::of(0.5) * skin * h;
    positions.iter().zip(rebuild_positions).any(|(x, x0)| {
        let d = *x - *x0;
        !(d.dot(d) < reach * reach)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_particle_half_a_skin_away_leaves_it() {
        let at = [V3([0.0f64, 0.0, 0.0]), V3([1.0, 1.0, 1.0])];
        let h = 0.1;
        let moved = |dx: f64| [V3([0.0, 0.0, 0.0]), V3([1.0 + dx, 1.0, 1.0])];
        assert!(!check_skin(&moved(0.0049), &at, 0.1, h));
        assert!(check_skin(&moved(0.0051), &at, 0.1, h));
        assert!(check_skin(&moved(f64::NAN), &at, 0.1, h));
    }
}
