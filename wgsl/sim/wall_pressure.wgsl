// Each wall particle's pressure and density extrapolated from the fluid around it (runs after
// the density stage, only in a scene with physics.boundary_pressure = "adami"): the generalised
// wall boundary of Adami, Hu & Adams 2012 (J. Comput. Phys. 231, Eq. 27 and 28),
//   p_w = (sum_f p_f W_wf + g . sum_f rho_f r_wf W_wf) / sum_f W_wf,   r_wf = x_w - x_f,
// over the fluid particles f within h (walls at rest: no wall acceleration term), and rho_w from
// the inverse equation of state. One invocation per wall particle. The forces (forces.wgsl)
// then push with p_i / rho_i^2 + p_w / rho_w^2. Twin of src/solver/cpu/wall_pressure.rs, which
// explains the terms.

//! include shared/common.wgsl
//! array positions: vec4<f32>, read
//! array densities: f32, read
//! array pressures: f32, read
//! array starts: u32, read
//! array wall_positions: vec4<f32>, read
// x: the wall particle's pressure, y: its density.
//! array wall_fields: vec2<f32>, read_write, optional

// The pressure and density of wall particle w.
fn wall_state(w: u32) -> vec2<f32> {
    let xw = wall_positions_at(w).xyz;
    let c = cell_coords(xw);
    var weights = 0.0;
    var pressure = 0.0;
    var hydrostatic = vec3<f32>(0.0);
    for (var run = 0u; run < stencil_span_count(); run++) {
        let cells = stencil_run(c, run);
        for (var f = starts_at(cells.x); f < starts_at(cells.y); f++) {
            let r_wf = xw - positions_at(f).xyz;
            let r2 = dot(r_wf, r_wf);
            if (r2 >= params.h2) {
                continue;
            }
            let weight = kernel_w(r2);
            weights += weight;
            pressure += pressures_at(f) * weight;
            if (GRAVITY) {
                hydrostatic += r_wf * (densities_at(f) * weight);
            }
        }
    }
    if (weights <= 0.0) {
        return vec2<f32>(0.0, params.rest_density);
    }
    var p = pressure;
    if (GRAVITY) {
        p += dot(params.gravity.xyz, hydrostatic);
    }
    p = p / weights;
    if (CLAMP_NEGATIVE_PRESSURE && p < 0.0) {
        p = 0.0;
    }
    return vec2<f32>(p, params.rest_density + density_above_rest(p));
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn wall_pressure(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let w = thread_index(gid, groups);
    if (w < params.wall_count) {
        wall_fields_set(w, wall_state(w));
    }
}
