// Each fluid particle's surface normal n_i = h sum_j (m_j / rho_j) grad W_ij over its fluid
// neighbours (Akinci, Akinci & Teschner 2013), for the curvature term of surface tension
// in the forces. Runs after the density stage, only in a scene with physics.surface_tension > 0;
// one invocation per fluid particle. Twin of src/solver/cpu/surface_normals.rs, which explains
// the normal.

//! include shared/common.wgsl
//! array positions: vec4<f32>, read
//! array densities: f32, read
//! array starts: u32, read
// xyz: the normal (w unused).
//! array normals: vec4<f32>, read_write, optional

// The normal of fluid particle i.
fn surface_normal(i: u32) -> vec3<f32> {
    let xi = positions_at(i).xyz;
    let c = cell_coords(xi);
    var sum = vec3<f32>(0.0);
    for (var run = 0u; run < stencil_span_count(); run++) {
        let cells = stencil_run(c, run);
        for (var j = starts_at(cells.x); j < starts_at(cells.y); j++) {
            let rij = xi - positions_at(j).xyz;
            let r2 = dot(rij, rij);
            if (r2 >= params.h2) {
                continue;
            }
            sum += kernel_grad(rij, sqrt(r2)) * (1.0 / densities_at(j));
        }
    }
    return sum * (params.h * params.fluid_mass);
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn surface_normals(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = thread_index(gid, groups);
    if (i < params.fluid_count) {
        normals_set(i, vec4<f32>(surface_normal(i), 0.0));
    }
}
