// Density carried by the continuity equation: each particle's density is the one its
// integration carries in the w of its velocity (advanced by the rate the forces stage computes,
// see forces.wgsl), and its pressure comes from the equation of state (report Eq. 8 or 9). Runs
// in place of density.wgsl when a scene sets physics.density = "continuity".
// Twin of src/solver/cpu/continuity.rs.

//! include shared/common.wgsl
//! include shared/reduce.wgsl
//! array velocities: vec4<f32>, read
//! array densities: f32, read_write
//! array pressures: f32, read_write
// STATUS_MAX_DENSITY: the largest density so far; STATUS_STEP_MAX_DENSITY: of this step.
//! array status: u32, atomic, whole

@compute @workgroup_size(WORKGROUP_SIZE)
fn continuity_density(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    reduce_begin(lid);
    let i = thread_index(gid, groups);
    if (i < params.fluid_count) {
        let rho = velocities_at(i).w;
        densities_set(i, rho);
        pressures_set(i, eos_pressure(rho));
        if (is_finite_f32(rho) && rho > 0.0) {
            reduce_offer(0u, bitcast<u32>(rho));
        }
    }
    reduce_end();
    if (lid == 0u) {
        let largest = reduce_result(0u);
        atomicMax(&status[STATUS_MAX_DENSITY], largest);
        atomicMax(&status[STATUS_STEP_MAX_DENSITY], largest);
    }
}
