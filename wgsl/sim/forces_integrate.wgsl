// The forces and the integration in one pass, for fixed dt: each particle's acceleration stays in
// registers instead of going through a 16-byte-per-particle array, and the state is read once
// instead of twice; it binds the arrays of forces.wgsl and integrate.wgsl (but no
// accelerations). Twin of src/solver/cpu/forces_integrate.rs. Adaptive dt cannot be fused: it
// needs every particle's acceleration before it can choose the step.

//! include sim/forces.wgsl
//! include sim/integrate.wgsl

@compute @workgroup_size(WORKGROUP_SIZE)
fn forces_and_integrate(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    reduce_begin(lid);
    let i = thread_index(gid, groups);
    var speed = 0.0;
    if (i < params.fluid_count) {
        speed = advance_particle(i, particle_acceleration(i), params.dt);
    }
    reduce_speed(speed);
    if (lid == 0u) {
        atomicMax(&status[STATUS_STEP_MAX_SPEED], reduce_result(0u));
    }
}
