// DFSPH, the end of a step: the positions advanced with the final velocities (x += dt v), the
// analytic planes, the health counters and the step's largest speed, and the stiffness sums kept by particle id for the next
// step's warm start. The new positions go to the other buffer of the state pair, whose
// velocities the solve has already changed in place. Twin of src/solver/cpu/dfsph_integrate.rs
// (the step's bookkeeping is wgsl/sim/integrate.wgsl `finish_step`).

//! include shared/common.wgsl
//! include shared/reduce.wgsl
//! array positions: vec4<f32>, read
//! array velocities: vec4<f32>, read_write
//! array positions_out: vec4<f32>, read_write
//! array pressure_sum: f32, read
//! array divergence_sum: f32, read
//! array warm_pressure: f32, read_write
//! array warm_divergence: f32, read_write
// The velocities after the divergence solve (the state's own) and the accelerations array
// `step_accelerations` fills.
//! array velocities_start: vec4<f32>, read
//! array accelerations: vec4<f32>, read_write
//! array status: u32, atomic, whole

fn step_dt() -> f32 {
    if (ADAPTIVE_DT) {
        return bitcast<f32>(atomicLoad(&status[STATUS_DT]));
    }
    return params.dt;
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn integrate(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    reduce_begin(lid);
    let i = thread_index(gid, groups);
    if (i < params.fluid_count) {
        let old = positions_at(i);
        var v = velocities_at(i).xyz;
        var x = old.xyz + v * step_dt();
        // The speed the solves gave the particle, before a plane takes the velocity into it
        // away (as wgsl/sim/integrate.wgsl advance_particle).
        let speed = length(v);
        let kept = backstop(x, v);
        x = kept.x;
        v = kept.v;
        positions_out_set(i, vec4<f32>(x, old.w));
        velocities_set(i, vec4<f32>(v, 0.0));
        let id = particle_id(old.w);
        warm_pressure_set(id, pressure_sum_at(i));
        warm_divergence_set(id, divergence_sum_at(i));
        let finite = is_finite_vec3(x) && is_finite_vec3(v);
        if (!finite) {
            atomicAdd(&status[STATUS_NON_FINITE], 1u);
        } else {
            // Non-negative floats order like their bits; a non-finite particle offers nothing.
            reduce_offer(0u, bitcast<u32>(speed));
            if (any(x < params.domain_min.xyz) || any(x > params.domain_max.xyz)) {
                atomicAdd(&status[STATUS_ESCAPED], 1u);
            }
        }
    }
    reduce_end();
    if (lid == 0u) {
        atomicMax(&status[STATUS_STEP_MAX_SPEED], reduce_result(0u));
    }
}

// The acceleration the step applied after its divergence solve, (v_end - v_start) / dt, for the
// step's fields (on request only).
@compute @workgroup_size(WORKGROUP_SIZE)
fn step_accelerations(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = thread_index(gid, groups);
    if (i < params.fluid_count) {
        accelerations_set(i, vec4<f32>((velocities_at(i).xyz - velocities_start_at(i).xyz) / step_dt(), 0.0));
    }
}
