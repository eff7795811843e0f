// The density and pressure of every particle into arrays of their own, for a program that reads
// them on the GPU (the renderer colours particles by them). The weakly compressible step keeps
// a summed density in the w of the velocities and computes the pressure from the density where
// it is read (src/solver/gpu/solver.rs, `array_places`), so these arrays exist only once asked
// for. Twin of src/solver/cpu/fields.rs.

//! include shared/common.wgsl
//! array densities: f32, read
//! array pressures: f32, read
//! array density_out: f32, read_write
//! array pressure_out: f32, read_write

@compute @workgroup_size(WORKGROUP_SIZE)
fn output_fields(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = thread_index(gid, groups);
    if (i >= params.fluid_count) {
        return;
    }
    density_out_set(i, densities_at(i));
    pressure_out_set(i, pressures_at(i));
}
