// Density by kernel summation over fluid and wall neighbours (report Eq. 5) and pressure from
// the equation of state (Eq. 8 or 9). Twin of src/solver/cpu/density.rs. One invocation walks
// one particle's stencil; density_tiled.wgsl walks a subgroup's together.

//! include shared/common.wgsl
//! include shared/reduce.wgsl
//! include shared/density_write.wgsl
//! array positions: vec4<f32>, read
//! array starts: u32, read
//! array wall_positions: vec4<f32>, read
//! array wall_starts: u32, read
//! array densities: f32, read_write
//! array pressures: f32, read_write
// STATUS_MAX_DENSITY: the largest density so far; STATUS_STEP_MAX_DENSITY: of this step.
//! array status: u32, atomic, whole

@compute @workgroup_size(WORKGROUP_SIZE)
fn density(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    reduce_begin(lid);
    let i = thread_index(gid, groups);
    if (i < params.fluid_count) {
        let xi = positions_at(i).xyz;
        let c = cell_coords(xi);
        var fluid_sum = 0.0;
        var wall_sum = 0.0;
        for (var run = 0u; run < stencil_span_count(); run++) {
            let cells = stencil_run(c, run);
            for (var j = starts_at(cells.x); j < starts_at(cells.y); j++) {
                let d = xi - positions_at(j).xyz;
                fluid_sum += kernel_w(dot(d, d));
            }
            if (WALLS) {
                for (var j = wall_starts_at(cells.x); j < wall_starts_at(cells.y); j++) {
                    let w = wall_positions_at(j);  // w: mass
                    let d = xi - w.xyz;
                    wall_sum += w.w * kernel_w(dot(d, d));
                }
            }
        }
        set_density(i, params.fluid_mass * fluid_sum + wall_sum);
    }
    finish_densities(lid);
}
