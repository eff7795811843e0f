// Density carried by the continuity equation (runs in place of density.wgsl when a scene sets
// physics.density = "continuity"): each particle's density of the last step is carried in the w
// of its velocity and advanced over dt with the rate at the current positions and velocities,
//   d rho_i / dt = sum_k m_k (u_i - u_k) . grad W_ik                         (walls at rest)
//                - delta h c0 sum_j m_j / rho_j (rho_j - rho_i - rho^H_ji) (x_ij . grad W_ij) / |x_ij|^2,
// the second line the delta-SPH diffusion (Molteni & Colagrossi 2009; Antuono et al. 2010) over
// fluid pairs, with the hydrostatic density difference rho^H_ji of Fourtakas et al. 2019 (Eq. 12)
// so that a still column's density gradient is not diffused away. The rate uses the velocities
// the last integration produced, so density and velocity advance alternately (symplectic
// Euler); a rate taken with the forces, from the velocities before their update, would make the
// pair an explicit Euler step that amplifies sound waves. Pressure from the equation of state
// (report Eq. 8 or 9). Twin of src/solver/cpu/continuity.rs.

//! include shared/common.wgsl
//! include shared/reduce.wgsl
//! array positions: vec4<f32>, read
//! array velocities: vec4<f32>, read
//! array starts: u32, read
//! array wall_positions: vec4<f32>, read
//! array wall_starts: u32, read
//! array densities: f32, read_write
//! array pressures: f32, read_write
// STATUS_MAX_DENSITY: the largest density so far; STATUS_STEP_MAX_DENSITY: of this step.
//! array status: u32, atomic, whole

// The density rate of fluid particle i.
fn density_rate(i: u32) -> f32 {
    let xi = positions_at(i).xyz;
    let vi = velocities_at(i);
    let ui = vi.xyz;
    let rho_i = vi.w;
    let c = cell_coords(xi);
    var fluid_rate = 0.0;
    var wall_rate = 0.0;
    var diffusive = 0.0;
    for (var run = 0u; run < stencil_span_count(); run++) {
        let cells = stencil_run(c, run);
        for (var j = starts_at(cells.x); j < starts_at(cells.y); j++) {
            let rij = xi - positions_at(j).xyz;
            let r2 = dot(rij, rij);
            if (r2 >= params.h2) {
                continue;
            }
            let grad = kernel_grad(rij, sqrt(r2));
            let vj = velocities_at(j);
            fluid_rate += dot(ui - vj.xyz, grad);
            // r2 = 0 only for i itself, whose gradient is zero.
            if (DENSITY_DIFFUSION && r2 > 0.0) {
                var drho = vj.w - rho_i;
                if (GRAVITY) {
                    drho -= density_above_rest(-params.rest_density * dot(params.gravity.xyz, rij));
                }
                diffusive += dot(rij, grad) * (drho / (vj.w * r2));
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
                wall_rate += dot(ui, kernel_grad(rij, sqrt(r2))) * w.w;
            }
        }
    }
    return (fluid_rate - params.diffusion_factor * diffusive) * params.fluid_mass + wall_rate;
}

// The dt the density advances by: the fixed dt, or with adaptive dt the last step's (the one
// that moved the particles to where the rate is taken; this step's is chosen after the
// forces), before any step the CFL condition of a fluid at rest. Twin: AdaptiveDt::continuity_dt.
fn continuity_dt() -> f32 {
    if (ADAPTIVE_DT) {
        let last = bitcast<f32>(atomicLoad(&status[STATUS_DT]));
        let at_rest = clamp(params.cfl_number * params.h / params.speed_of_sound, params.dt_min, params.dt_max);
        return select(at_rest, last, last > 0.0);
    }
    return params.dt;
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn continuity_density(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    reduce_begin(lid);
    let i = thread_index(gid, groups);
    if (i < params.fluid_count) {
        let rho = velocities_at(i).w + continuity_dt() * density_rate(i);
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
