// Symplectic Euler (v += dt a, then x += dt v), the analytic planes, and the health counters;
// with adaptive dt also the reduction of the largest speed and acceleration and the choice of dt.
// Twin of src/solver/cpu/integrate.rs (a function for every entry point). The new state goes to the other buffer of the pair (the one
// the binning read from), so that a stage fused with the forces (forces_integrate.wgsl) can
// write it while other threads still read the neighbours' old state.

//! include shared/common.wgsl
//! include shared/reduce.wgsl
//! include shared/adaptive_dt.wgsl
//! array positions: vec4<f32>, read
//! array velocities: vec4<f32>, read
//! array accelerations: vec4<f32>, read
//! array positions_out: vec4<f32>, read_write
//! array velocities_out: vec4<f32>, read_write
// The status words: STATUS_* in shared/common.wgsl.
//! array status: u32, atomic, whole

fn step_dt() -> f32 {
    if (ADAPTIVE_DT) {
        return bitcast<f32>(atomicLoad(&status[STATUS_DT]));
    }
    return params.dt;
}

// Advances fluid particle i with acceleration a over dt into the output arrays and returns the
// speed the forces gave it, before a plane took the velocity into it away (0 for a particle
// that is not finite; a finite velocity whose length overflows counts as infinitely fast, which
// orders above every finite speed). The w component of the position (the particle's original
// index, as bits) is carried over untouched. The w of the velocity gets the density of this
// step (a4.w): with CONTINUITY the next step's continuity stage advances it; otherwise it is
// where the outputs read the density the step used.
fn advance_particle(i: u32, a4: vec4<f32>, dt: f32) -> f32 {
    let a = a4.xyz;
    let old = positions_at(i);
    var v = velocities_at(i).xyz;
    var x = old.xyz;
    v += a * dt;
    x += v * dt;
    let speed = length(v);
    let kept = backstop(x, v);
    x = kept.x;
    v = kept.v;
    positions_out_set(i, vec4<f32>(x, old.w));
    velocities_out_set(i, vec4<f32>(v, a4.w));
    let finite = is_finite_vec3(x) && is_finite_vec3(v) && (!CONTINUITY || is_finite_f32(a4.w));
    if (!finite) {
        atomicAdd(&status[STATUS_NON_FINITE], 1u);
        return 0.0;
    } else if (any(x < params.domain_min.xyz) || any(x > params.domain_max.xyz)) {
        atomicAdd(&status[STATUS_ESCAPED], 1u);
    }
    return speed;
}

// The largest new speed of the workgroup into STATUS_STEP_MAX_SPEED: call from every invocation
// after reduce_begin, with 0 for invocations past the last particle.
fn reduce_speed(speed: f32) {
    reduce_offer(0u, bitcast<u32>(speed));
    reduce_end();
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn integrate(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    reduce_begin(lid);
    let i = thread_index(gid, groups);
    var speed = 0.0;
    if (i < params.fluid_count) {
        speed = advance_particle(i, accelerations_at(i), step_dt());
    }
    reduce_speed(speed);
    if (lid == 0u) {
        atomicMax(&status[STATUS_STEP_MAX_SPEED], reduce_result(0u));
    }
}

// Adaptive dt, 1 of 2: the largest |v| (at the start of the step) and |a| (of this step),
// reduced per workgroup, then once per workgroup into the status buffer (across ranks, of the
// rank's own particles; shared/adaptive_dt.wgsl).
@compute @workgroup_size(WORKGROUP_SIZE)
fn reduce_maxima(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    reduce_begin(lid);
    let i = thread_index(gid, groups);
    // A ghost is its own rank's to count: each rank offers its own particles, and the host
    // takes the largest over the ranks before choose_dt.
    if (i < params.fluid_count && !is_ghost(positions_at(i).w)) {
        offer_speed_and_acceleration(length(velocities_at(i).xyz), length(accelerations_at(i).xyz));
    }
    publish_speed_and_acceleration(lid);
}

// Adaptive dt, 2 of 2 (one thread): the CFL condition on the speed of sound and the largest
// flow speed, C_cfl h / (c0 + |v|max), with the force and viscous conditions (shared/adaptive_dt.wgsl).
@compute @workgroup_size(1)
fn choose_dt() {
    let maxima = take_speed_and_acceleration();
    choose_and_record_dt(params.cfl_number * params.h / (params.speed_of_sound + maxima.x), maxima.y);
}

// One thread after every step: counts the step, keeps the largest speed so far, and at the
// first step that went wrong (a particle non-finite or outside the domain, or the step's
// largest density or speed past its stop level) sets the marker and records, in the same
// thread and at the same moment, what that step measured. Then resets the step's maxima.
@compute @workgroup_size(1)
fn finish_step() {
    let step = atomicLoad(&status[STATUS_STEPS]) + 1u;
    atomicStore(&status[STATUS_STEPS], step);
    let non_finite = atomicLoad(&status[STATUS_NON_FINITE]);
    let escaped = atomicLoad(&status[STATUS_ESCAPED]);
    let density = atomicLoad(&status[STATUS_STEP_MAX_DENSITY]);
    let speed = atomicLoad(&status[STATUS_STEP_MAX_SPEED]);
    atomicStore(&status[STATUS_STEP_MAX_DENSITY], 0u);
    atomicStore(&status[STATUS_STEP_MAX_SPEED], 0u);
    atomicMax(&status[STATUS_TOP_SPEED], speed);
    var causes = 0u;
    if (non_finite > 0u) {
        causes |= CAUSE_NON_FINITE;
    }
    if (escaped > 0u) {
        causes |= CAUSE_ESCAPED;
    }
    if (bitcast<f32>(density) > params.stop_density) {
        causes |= CAUSE_TOO_DENSE;
    }
    if (bitcast<f32>(speed) > params.stop_speed) {
        causes |= CAUSE_TOO_FAST;
    }
    if (causes != 0u && atomicLoad(&status[STATUS_FIRST_BAD_STEP]) == STATUS_NO_BAD_STEP) {
        atomicStore(&status[STATUS_FIRST_BAD_STEP], step);
        atomicStore(&status[STATUS_BAD_CAUSES], causes);
        atomicStore(&status[STATUS_BAD_NON_FINITE], non_finite);
        atomicStore(&status[STATUS_BAD_ESCAPED], escaped);
        atomicStore(&status[STATUS_BAD_MAX_DENSITY], density);
        atomicStore(&status[STATUS_BAD_MAX_SPEED], speed);
        atomicStore(&status[STATUS_BAD_DT], bitcast<u32>(step_dt()));
        if (ADAPTIVE_DT) {
            atomicStore(&status[STATUS_BAD_TIME], bitcast<u32>(simulated_time()));
        }
    }
}
