//! DFSPH across ranks: the velocities a rank sends to its neighbours gathered from their slots,
//! and those it receives scattered onto its ghosts' slots. Twin of
//! wgsl/sim/ghost_velocities.wgsl (the GPU keeps a w beside each velocity, which stays).

use crate::model::real::{Real, V3};

/// The velocities of `slots`, in their order.
pub fn gather_ghost_velocities<R: Real>(velocities: &[V3<R>], slots: &[usize]) -> Vec<V3<R>> {
    slots.iter().map(|&i| velocities[i]).collect()
}

/// `values[k]` into the velocity of `slots[k]`.
pub fn scatter_ghost_velocities<R: Real>(velocities: &mut [V3<R>], slots: &[usize], values: &[V3<R>]) {
    for (&i, &v) in slots.iter().zip(values) {
        velocities[i] = v;
    }
}
