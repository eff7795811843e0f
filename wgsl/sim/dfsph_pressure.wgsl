// DFSPH's constant-density solve: Jacobi steps on the predicted density, so that the density the
// velocities would give after dt is the rest density (Bender & Koschier 2017, Sec. 4.3). Twin of
// src/solver/cpu/dfsph_pressure.rs. The velocities are the predicted ones (the other buffer of
// the state pair), changed in place.

//! include shared/common.wgsl
//! include shared/dfsph.wgsl
//! array velocities: vec4<f32>, read_write
//! array densities: f32, read
//! array factors: f32, read
//! array stiffness: f32, read_write
//! array pressure_sum: f32, read_write
// The last step's constant-density stiffness sums, by particle id.
//! array warm_pressure: f32, read
// The error sum of the solve; STATUS_DT, this step's dt (adaptive dt).
//! array status: u32, atomic, whole

fn step_dt() -> f32 {
    if (ADAPTIVE_DT) {
        return bitcast<f32>(atomicLoad(&status[STATUS_DT]));
    }
    return params.dt;
}

// rho_i / rho0 + dt D_i: the density the velocities give after dt, from the rate D_i.
fn predicted_density(i: u32, rate: f32) -> f32 {
    return densities_at(i) / params.rest_density + step_dt() * rate;
}

// The stiffness the solve starts from: a share of the last step's (by particle id) where the
// predicted density is above rest density, none elsewhere.
@compute @workgroup_size(WORKGROUP_SIZE)
fn pressure_warm_start(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = thread_index(gid, groups);
    if (i < params.fluid_count) {
        let p = positions_at(i);
        let rate = density_rate(i, p.xyz, velocities_at(i).xyz);
        stiffness_set(i, select(0.0, params.warm_start_share * warm_pressure_at(particle_id(p.w)), predicted_density(i, rate) > 1.0));
    }
}

// rho*_i = max(rho_i / rho0 + dt D_i, 1), K_i = (rho*_i - 1) alpha_i, and the error rho*_i - 1
// into the solve's sum.
@compute @workgroup_size(WORKGROUP_SIZE)
fn predict_density(
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
    let error = max(predicted_density(i, rate), 1.0) - 1.0;
    stiffness_set(i, error * factors_at(i));
    // A ghost's error is its owner's to count (across ranks).
    if (!is_ghost(w)) {
        error_offer(error);
    }
}

// One Jacobi step: v_i -= (V sum_j (K_i + K_j) grad W_ij + K_i g_i^w) / dt; K_i added to the sum.
@compute @workgroup_size(WORKGROUP_SIZE)
fn pressure_apply(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = thread_index(gid, groups);
    if (i < params.fluid_count) {
        apply_stiffness_push(i, stiffness_push(i, positions_at(i).xyz, stiffness_at(i)));
    }
}

fn apply_stiffness_push(i: u32, push: vec3<f32>) {
    let v = velocities_at(i);
    velocities_set(i, vec4<f32>(v.xyz - push * (1.0 / step_dt()), v.w));
    pressure_sum_set(i, pressure_sum_at(i) + stiffness_at(i));
}
