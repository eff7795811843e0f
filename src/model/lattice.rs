//! Regular lattices of points filling a box: the fluid blocks and the walls are sampled on
//! them, and a scene's particle count is known from their sizes before any particle exists.

/// Points per axis of a lattice of spacing `s` filling [min, max].
pub fn lattice_counts(min: [f64; 3], max: [f64; 3], s: f64) -> [u64; 3] {
    // A small tolerance so that a block an exact multiple of s wide gets that many layers.
    let mut n = [0u64; 3];
    for a in 0..3 {
        n[a] = ((max[a] - min[a]) / s + 1e-6).floor().max(0.0) as u64;
    }
    n
}

/// Points at min + (i + 0.5) s, filling [min, max] on every axis; x runs fastest.
pub fn lattice(min: [f64; 3], max: [f64; 3], s: f64) -> impl Iterator<Item = [f64; 3]> {
    let n = lattice_counts(min, max, s);
    (0..n[2]).flat_map(move |k| {
        (0..n[1]).flat_map(move |j| {
            (0..n[0]).map(move |i| {
                [
                    min[0] + (i as f64 + 0.5) * s,
                    min[1] + (j as f64 + 0.5) * s,
                    min[2] + (k as f64 + 0.5) * s,
                ]
            })
        })
    })
}

