// DFSPH's divergence solve: Jacobi steps that make the velocity field divergence-free, so that
// the density stops changing (Bender & Koschier 2017, Sec. 4.2). Twin of
// src/solver/cpu/dfsph_divergence.rs. The velocities are the state's own, changed in place.

//! include shared/common.wgsl
//! include shared/dfsph.wgsl
//! array velocities: vec4<f32>, read_write
//! array factors: f32, read
//! array stiffness: f32, read_write
//! array divergence_sum: f32, read_write
// The last step's divergence stiffness sums, by particle id.
//! array warm_divergence: f32, read
// The error sum of the solve; STATUS_DT, the last dt (adaptive dt).
//! array status: u32, atomic, whole

// The dt the solve judges its error with: the step's own with a fixed dt; with adaptive dt the
// last step's (the new one is chosen after the solve), dt_max before any.
fn divergence_dt() -> f32 {
    if (ADAPTIVE_DT) {
        let last = bitcast<f32>(atomicLoad(&status[STATUS_DT]));
        return select(params.dt_max, last, last > 0.0);
    }
    return params.dt;
}

// The stiffness the solve starts from: a share of the last step's (by particle id) where the
// particle is being compressed, none elsewhere.
@compute @workgroup_size(WORKGROUP_SIZE)
fn divergence_warm_start(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = thread_index(gid, groups);
    if (i < params.fluid_count) {
        let p = positions_at(i);
        let d = density_rate(i, p.xyz, velocities_at(i).xyz);
        stiffness_set(i, select(0.0, params.warm_start_share * warm_divergence_at(particle_id(p.w)), d > 0.0));
    }
}

// The rate of compression D_i = max(Drho^_i/Dt, 0), the stiffness K_i = D_i alpha_i, and the
// error dt D_i into the solve's sum.
@compute @workgroup_size(WORKGROUP_SIZE)
fn divergence_rate(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    error_begin(lid);
    let i = thread_index(gid, groups);
    if (i < params.fluid_count) {
        let p = positions_at(i);
        set_stiffness_from_rate(i, p.w, density_rate(i, p.xyz, velocities_at(i).xyz));
    }
    error_end(lid);
}

// K_i and the error of particle i (w: its position's w) from its rate of density change.
fn set_stiffness_from_rate(i: u32, w: f32, rate: f32) {
    let d = max(rate, 0.0);
    stiffness_set(i, d * factors_at(i));
    // A ghost's error is its owner's to count (across ranks).
    if (!is_ghost(w)) {
        error_offer(d * divergence_dt());
    }
}

// One Jacobi step: v_i -= V sum_j (K_i + K_j) grad W_ij + K_i g_i^w; K_i added to the step's sum.
@compute @workgroup_size(WORKGROUP_SIZE)
fn divergence_apply(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = thread_index(gid, groups);
    if (i < params.fluid_count) {
        apply_stiffness_push(i, stiffness_push(i, positions_at(i).xyz, stiffness_at(i)));
    }
}

fn apply_stiffness_push(i: u32, push: vec3<f32>) {
    let v = velocities_at(i);
    velocities_set(i, vec4<f32>(v.xyz - push, v.w));
    divergence_sum_set(i, divergence_sum_at(i) + stiffness_at(i));
}
