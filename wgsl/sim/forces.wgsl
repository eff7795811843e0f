// Accelerations: the symmetric pressure force (report Eq. 6), viscosity (Eq. 7 with the volumes
// m_k / rho_k of Eq. 4, in the symmetric form of Mueller et al. 2003 Eq. 14), Monaghan's
// artificial viscosity, wall particles and gravity.
// Twin of src/solver/cpu/forces.rs, which explains the wall and viscosity models.

//! include shared/common.wgsl
//! array positions: vec4<f32>, read
//! array velocities: vec4<f32>, read
//! array densities: f32, read
//! array pressures: f32, read
//! array starts: u32, read
//! array wall_positions: vec4<f32>, read
//! array wall_starts: u32, read
// With ADAMI_WALL_PRESSURE, each wall particle's pressure (x) and density (y) of this step
// (wall_pressure.wgsl); not bound otherwise.
//! array wall_fields: vec2<f32>, read, optional
//! array accelerations: vec4<f32>, read_write

// The acceleration of fluid particle i (xyz) and its density (w), which the integration keeps
// in the w of the velocity: with CONTINUITY the density the next step advances, otherwise the
// one the outputs of this step read there (src/solver/gpu/solver.rs, `array_places`).
fn particle_acceleration(i: u32) -> vec4<f32> {
    let cubic = KERNEL == 1u;
    let viscous = VISCOSITY && params.viscosity > 0.0;
    let eps = 0.01 * params.h2;
    let xi = positions_at(i).xyz;
    let ui = velocities_at(i).xyz;
    let rho_i = densities_at(i);
    let p_i = pressures_at(i);
    let pi_over = p_i / (rho_i * rho_i);
    // The wall pressure term's factor outside the sum over wall particles (Adami: inside).
    var wall_p_over = select(2.0 * max(p_i, 0.0) / (rho_i * rho_i), pi_over, CONSISTENT_WALL_PRESSURE);
    if (ADAMI_WALL_PRESSURE) {
        wall_p_over = 1.0;
    }
    let c = cell_coords(xi);
    // Sums without their constant factors, applied once at the end.
    var fluid_pressure = vec3<f32>(0.0);
    var fluid_visc = vec3<f32>(0.0);
    var wall_pressure = vec3<f32>(0.0);
    var wall_visc = vec3<f32>(0.0);
    var fluid_artificial = vec3<f32>(0.0);
    var wall_artificial = vec3<f32>(0.0);
    for (var run = 0u; run < stencil_span_count(); run++) {
        let cells = stencil_run(c, run);
        for (var j = starts_at(cells.x); j < starts_at(cells.y); j++) {
            let rij = xi - positions_at(j).xyz;
            let r2 = dot(rij, rij);
            if (r2 >= params.h2) {
                continue;
            }
            let r = sqrt(r2);
            let grad = kernel_grad(rij, r);
            let rho_j = densities_at(j);
            let pj_over = pressures_at(j) / (rho_j * rho_j);
            fluid_pressure -= grad * (pi_over + pj_over);
            if (viscous) {
                let inv_rho = 1.0 / rho_j;
                let uij = ui - velocities_at(j).xyz;
                if (cubic) {
                    fluid_visc += grad * (inv_rho * dot(uij, rij) / (r2 + eps));
                } else {
                    fluid_visc -= uij * (inv_rho * kernel_laplacian(r));
                }
            }
            if (ARTIFICIAL_VISCOSITY) {
                let uij = ui - velocities_at(j).xyz;
                let approach = dot(uij, rij);
                if (approach < 0.0) {
                    fluid_artificial += grad * (approach / ((r2 + eps) * (rho_i + rho_j)));
                }
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
                let grad = kernel_grad(rij, r);
                if (ADAMI_WALL_PRESSURE) {
                    let own = wall_fields_at(j);
                    wall_pressure -= grad * (w.w * (pi_over + own.x / (own.y * own.y)));
                } else {
                    wall_pressure -= grad * w.w;
                }
                if (viscous) {
                    if (cubic) {
                        wall_visc += grad * (w.w * dot(ui, rij) / (r2 + eps));
                    } else {
                        wall_visc -= ui * (w.w * kernel_laplacian(r));
                    }
                }
                if (ARTIFICIAL_VISCOSITY) {
                    let approach = dot(ui, rij);
                    if (approach < 0.0) {
                        wall_artificial += grad * (w.w * approach / ((r2 + eps) * rho_i));
                    }
                }
            }
        }
    }
    let nu = select(params.viscosity, 10.0 * params.viscosity, cubic);
    let visc = fluid_visc * (nu * params.rest_density * params.fluid_mass / rho_i) + wall_visc * (nu * params.boundary_friction / rho_i);
    var a = fluid_pressure * params.fluid_mass + wall_pressure * wall_p_over + visc;
    if (ARTIFICIAL_VISCOSITY) {
        let av = params.artificial_viscosity_factor;
        a += fluid_artificial * (2.0 * av * params.fluid_mass) + wall_artificial * (av * params.boundary_friction);
    }
    if (GRAVITY) {
        a += params.gravity.xyz;
    }
    return vec4<f32>(a, rho_i);
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn forces(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = thread_index(gid, groups);
    if (i < params.fluid_count) {
        accelerations_set(i, particle_acceleration(i));
    }
}
