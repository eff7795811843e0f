// DFSPH, between the two solves: the accelerations of every force but pressure (viscosity,
// surface tension, adhesion and gravity), the step's dt (adaptive dt) and the predicted velocities v* = v + dt a, written to
// the other buffer of the state pair. Twin of src/solver/cpu/dfsph_predict.rs, one function per
// entry point.

//! include shared/common.wgsl
//! include shared/reduce.wgsl
//! include shared/adaptive_dt.wgsl
//! array positions: vec4<f32>, read
//! array velocities: vec4<f32>, read
//! array densities: f32, read
//! array starts: u32, read
//! array wall_positions: vec4<f32>, read
//! array wall_starts: u32, read
//! array accelerations: vec4<f32>, read_write
//! array velocities_out: vec4<f32>, read_write
//! array pressure_sum: f32, read_write
// Adaptive dt: the maxima, dt, time and dt range.
//! array status: u32, atomic, whole
// With SURFACE_TENSION, each fluid particle's normal (surface_normals.wgsl); not bound otherwise.
//! array normals: vec4<f32>, read, optional

// Viscosity, surface tension, adhesion and gravity on fluid particle i: the terms of
// wgsl/sim/forces.wgsl (the CPU twin, src/solver/cpu/forces.rs, explains them), without
// pressure.
fn non_pressure_acceleration(i: u32) -> vec3<f32> {
    var g = vec3<f32>(0.0);
    if (GRAVITY) {
        g = params.gravity.xyz;
    }
    let viscous = VISCOSITY && params.viscosity > 0.0;
    if (!(viscous || SURFACE_TENSION || WALL_ADHESION)) {
        return g;
    }
    let eps = 0.01 * params.h2;
    let xi = positions_at(i).xyz;
    let ui = velocities_at(i).xyz;
    let c = cell_coords(xi);
    var fluid_visc = vec3<f32>(0.0);
    var wall_visc = vec3<f32>(0.0);
    let rho_i = densities_at(i);
    var ni = vec3<f32>(0.0);
    if (SURFACE_TENSION) {
        ni = normals_at(i).xyz;
    }
    var tension = vec3<f32>(0.0);
    var adhesion = vec3<f32>(0.0);
    for (var run = 0u; run < stencil_span_count(); run++) {
        let cells = stencil_run(c, run);
        for (var j = starts_at(cells.x); j < starts_at(cells.y); j++) {
            let rij = xi - positions_at(j).xyz;
            let r2 = dot(rij, rij);
            if (r2 >= params.h2) {
                continue;
            }
            let r = sqrt(r2);
            if (viscous) {
                let inv_rho = 1.0 / densities_at(j);
                let uij = ui - velocities_at(j).xyz;
                if (gradient_viscosity()) {
                    fluid_visc += kernel_grad(rij, r) * (inv_rho * dot(uij, rij) / (r2 + eps));
                } else {
                    fluid_visc -= uij * (inv_rho * kernel_laplacian(r));
                }
            }
            if (SURFACE_TENSION) {
                tension += surface_tension_pair(rij, r, rho_i, densities_at(j), ni, normals_at(j).xyz);
            }
        }
        if (WALLS) {
            for (var j = wall_starts_at(cells.x); j < wall_starts_at(cells.y); j++) {
                let w = wall_positions_at(j);  // w: mass
                let rij = xi - w.xyz;
                let r2 = dot(rij, rij);
                if (r2 >= params.h2) {
                    continue;
                }
                let r = sqrt(r2);
                if (viscous) {
                    if (gradient_viscosity()) {
                        wall_visc += kernel_grad(rij, r) * (w.w * dot(ui, rij) / (r2 + eps));
                    } else {
                        wall_visc -= ui * (w.w * kernel_laplacian(r));
                    }
                }
                if (WALL_ADHESION) {
                    adhesion += adhesion_pair(rij, r, w.w);
                }
            }
        }
    }
    let nu = viscous_nu();
    var a = fluid_visc * (nu * params.rest_density * params.fluid_mass / rho_i) + wall_visc * (nu * params.boundary_friction / rho_i);
    if (SURFACE_TENSION) {
        a -= tension;
    }
    if (WALL_ADHESION) {
        a -= adhesion * params.adhesion_factor;
    }
    return a + g;
}

// Fixed dt: v*_i = v_i + dt a_i; the constant-density solve's stiffness sum starts at 0.
@compute @workgroup_size(WORKGROUP_SIZE)
fn predict_velocities(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = thread_index(gid, groups);
    if (i < params.fluid_count) {
        let v = velocities_at(i);
        velocities_out_set(i, vec4<f32>(v.xyz + non_pressure_acceleration(i) * params.dt, v.w));
        pressure_sum_set(i, 0.0);
    }
}

// Adaptive dt, 1 of 3: every particle's acceleration, and the largest |v| and |a| reduced per
// workgroup into the status words (a non-finite value left out).
@compute @workgroup_size(WORKGROUP_SIZE)
fn non_pressure_accelerations(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    reduce_begin(lid);
    let i = thread_index(gid, groups);
    if (i < params.fluid_count) {
        let a = non_pressure_acceleration(i);
        accelerations_set(i, vec4<f32>(a, 0.0));
        let speed = length(velocities_at(i).xyz);
        let accel = length(a);
        // A ghost is its own rank's to count; the host takes the largest over the ranks.
        if (!is_ghost(positions_at(i).w)) {
            offer_speed_and_acceleration(speed, accel);
        }
    }
    publish_speed_and_acceleration(lid);
}

// Adaptive dt, 2 of 3 (one thread): the CFL condition on the flow speed alone, C_cfl h / |v|max
// (an incompressible fluid has no speed of sound; none while nothing moves), with the force and
// viscous conditions (shared/adaptive_dt.wgsl). Twin of AdaptiveDt::dt in src/model/params.rs
// with c0 = 0.
@compute @workgroup_size(1)
fn choose_dt() {
    let maxima = take_speed_and_acceleration();
    var cfl_dt = params.dt_max;
    if (maxima.x > 0.0) {
        cfl_dt = min(cfl_dt, params.cfl_number * params.h / maxima.x);
    }
    choose_and_record_dt(cfl_dt, maxima.y);
}

// Adaptive dt, 3 of 3: v*_i = v_i + dt a_i; the stiffness sum starts at 0.
@compute @workgroup_size(WORKGROUP_SIZE)
fn predict_from_accelerations(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = thread_index(gid, groups);
    if (i < params.fluid_count) {
        let v = velocities_at(i);
        let dt = bitcast<f32>(atomicLoad(&status[STATUS_DT]));
        velocities_out_set(i, vec4<f32>(v.xyz + accelerations_at(i).xyz * dt, v.w));
        pressure_sum_set(i, 0.0);
    }
}
