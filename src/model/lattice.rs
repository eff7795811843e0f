//! Regular lattices of points filling a box: the fluid blocks and the walls are sampled on
//! them, and a scene's particle count is known from their sizes before any particle exists.
//!
//! A side that is a whole number of spacings long (to one part in a million) holds that many
//! points at `min + (i + 1/2) s`. Otherwise:
//! - fluid keeps its spacing, so that it starts at its rest density (a lattice stretched by a
//!   few per cent would start a few per cent over or under it, and the Tait equation of state
//!   turns 2 % into a seventh of its stiffness of pressure). A side holds the nearest whole
//!   number of spacings, so that it is at most half a spacing longer or shorter than stated,
//!   without ever bringing a particle nearer than half a spacing to a wall at one of its ends
//!   (which would start it well over its rest density): against a wall at one end the
//!   lattice starts there, against walls at both ends it holds the whole spacings that fit,
//!   centred, and free at both ends it is centred ([`fluid_axis`]);
//! - walls are stretched to fill the stated side exactly, and each wall particle's mass follows
//!   its lattice cell, so that the wall keeps its rest density ([`wall_axis`]).

/// The points of a lattice along one axis: `origin + (i + 1/2) spacing` for `i < count`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AxisLattice {
    pub origin: f64,
    pub spacing: f64,
    pub count: u64,
}

impl AxisLattice {
    pub fn point(&self, i: u64) -> f64 {
        self.origin + (i as f64 + 0.5) * self.spacing
    }
    /// The length the points fill (`count` spacings).
    pub fn length(&self) -> f64 {
        self.count as f64 * self.spacing
    }
}

/// The points of a lattice with `counts` points along each axis, saturating at `u64::MAX`
/// (a spacing of 1e-100 asks for more than any count holds: the limits then refuse it).
pub fn lattice_size(counts: impl IntoIterator<Item = u64>) -> u64 {
    counts.into_iter().fold(1u64, |size, count| size.saturating_mul(count))
}

/// Spacings in `length` when it is a whole number of them (to one part in a million).
pub fn whole_spacings(length: f64, s: f64) -> Option<u64> {
    let q = length / s;
    let n = (q + 1e-6).floor();
    (q - n < 1e-6 && n >= 0.0).then_some(n as u64)
}

/// A fluid block's side from `min` to `max` in spacings of `s`; `walls`: whether a wall lies
/// against its min and its max end (see the module's text). `count` is 0 where the side holds
/// no whole spacing.
pub fn fluid_axis(min: f64, max: f64, s: f64, walls: (bool, bool)) -> AxisLattice {
    let length = max - min;
    if let Some(n) = whole_spacings(length, s) {
        return AxisLattice { origin: min, spacing: s, count: n };
    }
    let n = if walls.0 && walls.1 { (length / s).floor() } else { (length / s).round() }.max(0.0);
    let origin = match walls {
        (true, false) => min,
        (false, true) => max - n * s,
        _ => min + 0.5 * (length - n * s),
    };
    AxisLattice { origin, spacing: s, count: n as u64 }
}

/// A wall's side from `min` to `max`: at least one point, stretched to fill the side exactly.
pub fn wall_axis(min: f64, max: f64, s: f64) -> AxisLattice {
    let length = max - min;
    if let Some(n) = whole_spacings(length, s).filter(|&n| n > 0) {
        return AxisLattice { origin: min, spacing: s, count: n };
    }
    let n = (length / s).round().max(1.0);
    AxisLattice { origin: min, spacing: length / n, count: n as u64 }
}

/// The first index in `lo..hi` where `past` holds, `hi` where it holds nowhere; `past` must
/// hold on a tail of the range (false, then true).
pub fn first_index(lo: u64, hi: u64, past: impl Fn(u64) -> bool) -> u64 {
    let (mut lo, mut hi) = (lo, hi);
    while lo < hi {
        let mid = lo + (hi - lo) / 2;
        if past(mid) {
            hi = mid;
        } else {
            lo = mid + 1;
        }
    }
    lo
}

/// The points of three axis lattices; x runs fastest.
pub fn points(axes: [AxisLattice; 3]) -> impl Iterator<Item = [f64; 3]> {
    (0..axes[2].count).flat_map(move |k| (0..axes[1].count).flat_map(move |j| (0..axes[0].count).map(move |i| [axes[0].point(i), axes[1].point(j), axes[2].point(k)])))
}
