//! The neighbour skin (wgsl/sim/neighbour_skin.wgsl): the grid, the particles' order and the
//! neighbour lists kept from one rebuild to the next, rebuilt only once they may miss a
//! neighbour. What it may be used with, the check's stage and its arrays, and how the host
//! reads the check.

use std::cell::Cell;

use super::shaders::Stage;
use crate::model::params::Params;
use super::buffers::storage;
use crate::solver::cpu::neighbour_skin::{skin_reach, SkinCheck};

/// The check's words (wgsl/sim/neighbour_skin.wgsl): the flag, then three keys of the smallest
/// displacement (negated) and three of the largest, in a buffer of 32 bytes.
pub const CHECK_BYTES: u64 = 32;

/// The float whose `order_key` (wgsl/sim/neighbour_skin.wgsl) is `key`.
fn from_order_key(key: u32) -> f32 {
    f32::from_bits(if key & 0x8000_0000 != 0 { key & 0x7fff_ffff } else { !key })
}

/// The check's words as the CPU twin gathers them (no extent where no particle offered one).
pub(super) fn read_check(bytes: &[u8]) -> SkinCheck<f32> {
    let words: Vec<u32> = bytemuck::pod_collect_to_vec(bytes);
    let keys = &words[1..7];
    let extent = keys.iter().all(|&k| k != 0).then(|| {
        let lo = [0, 1, 2].map(|axis| -from_order_key(keys[axis]));
        let hi = [0, 1, 2].map(|axis| from_order_key(keys[3 + axis]));
        (lo, hi)
    });
    SkinCheck { moved_far: words[0] != 0, extent }
}

/// The largest skin, as a fraction of h: the cells are then twice the kernel's support.
const MAX_SKIN: f64 = 1.0;

/// Why `skin` is no skin (the command line's check, and the solver's), or `None`.
pub fn out_of_range(skin: f64) -> Option<String> {
    (!(skin > 0.0 && skin <= MAX_SKIN)).then(|| format!("--neighbour-skin is {skin}; it must be above 0 and at most {MAX_SKIN} (a fraction of the kernel's support h, e.g. 0.1)"))
}

/// Why a scene cannot run with a neighbour skin of `skin` h, or `None`.
pub fn refusal(params: &Params, skin: f64, across_ranks: bool) -> Option<String> {
    if let Some(why) = out_of_range(skin) {
        return Some(why);
    }
    let why = if params.dfsph.is_some() {
        "the scene uses DFSPH (physics.solver = \"dfsph\"), whose factors record their own lists every step"
    } else if params.rebuild_every != 1 {
        "the scene rebuilds its grid every 2nd step (time.neighbour_rebuild_every = 2); the skin chooses when to rebuild"
    } else if across_ranks {
        "the run is split across ranks, which exchange particles at every rebuild"
    } else {
        return None;
    };
    Some(format!("--neighbour-skin {skin} cannot be used: {why}; it needs a weakly compressible scene on one device"))
}

/// The skin's state on the device and on the host.
pub(super) struct NeighbourSkin {
    /// The skin, a fraction of h.
    pub fraction: f64,
    /// Each fluid particle's position at the last rebuild, in the order of that rebuild.
    pub rebuild_positions: wgpu::Buffer,
    /// The check's distance: the skin, less its margin, times h.
    pub reach: f32,
    /// What the check gathers (cleared before each step): a word, 1 once a particle has moved
    /// `reach`, and the keys of the smallest and largest displacements (`read_check`).
    pub left: wgpu::Buffer,
    pub check: Stage,
    /// The check's bind groups, per phase of the state store.
    pub groups: Vec<wgpu::BindGroup>,
    /// Whether the next step (or the fields of a snapshot) rebuilds: before the first, after a
    /// particle left the skin, and after the state was saved or restored (a checkpoint, a
    /// restart), so that a run resumed from a saved state rebuilds where the run that saved it
    /// did. A snapshot does not make one: it leaves the run's bits as they were.
    pub rebuild_due: Cell<bool>,
    /// Rebuilds so far.
    pub rebuilds: Cell<u64>,
}

impl NeighbourSkin {
    /// The skin of `fraction` h for `n` fluid particles: the positions of the last rebuild, the
    /// check's words, and the `check` stage's bind group on each phase of the state store
    /// (`phases`: the buffer of each array name in that phase). The first step rebuilds.
    pub fn new(device: &wgpu::Device, uniform: &wgpu::Buffer, fraction: f64, h: f64, n: u64, check: Stage, phases: &[impl Fn(&str) -> wgpu::Buffer]) -> NeighbourSkin {
        let rebuild_positions = storage(device, "rebuild positions", n * 16);
        let left = storage(device, "skin check", CHECK_BYTES);
        let groups = phases
            .iter()
            .map(|buffers| {
                check.bind_group(device, "check_skin", uniform, &|name: &str| match name {
                    "rebuild_positions" => rebuild_positions.clone(),
                    "skin_left" => left.clone(),
                    other => buffers(other),
                })
            })
            .collect();
        NeighbourSkin {
            fraction,
            reach: skin_reach(fraction, h),
            rebuild_positions,
            left,
            check,
            groups,
            rebuild_due: Cell::new(true),
            rebuilds: Cell::new(0),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The shader's key, as wgsl/sim/neighbour_skin.wgsl computes it.
    fn order_key(v: f32) -> u32 {
        let b = v.to_bits();
        if b & 0x8000_0000 != 0 { !b } else { b | 0x8000_0000 }
    }

    #[test]
    fn keys_order_as_their_floats_and_read_back() {
        let values = [-3.5e3f32, -1.0, -1e-30, -0.0, 0.0, 1e-30, 2.0, 7.25e4];
        for pair in values.windows(2) {
            assert!(order_key(pair[0]) <= order_key(pair[1]), "{pair:?}");
        }
        for v in values {
            assert_eq!(from_order_key(order_key(v)).to_bits(), v.to_bits());
        }
        let mut words = [0u32; 8];
        words[1..4].copy_from_slice(&[order_key(0.5), order_key(-1.0), order_key(-0.25)]);
        words[4..7].copy_from_slice(&[order_key(2.0), order_key(3.0), order_key(4.0)]);
        let bytes: Vec<u8> = words.iter().flat_map(|w| w.to_le_bytes()).collect();
        let check = read_check(&bytes);
        assert_eq!(check, SkinCheck { moved_far: false, extent: Some(([-0.5, 1.0, 0.25], [2.0, 3.0, 4.0])) });
        assert_eq!(read_check(&[0u8; 32]), SkinCheck { moved_far: false, extent: None });
    }
}
