//! The neighbour skin (wgsl/sim/neighbour_skin.wgsl): the grid, the particles' order and the
//! neighbour lists kept from one rebuild to the next, rebuilt only once a particle has moved
//! half the skin. What it may be used with, the check's stage and its arrays, and whether the
//! next step rebuilds.

use std::cell::Cell;

use super::shaders::Stage;
use crate::model::params::Params;

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
    /// One word: 1 once a particle has moved half the skin (cleared before each step).
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
