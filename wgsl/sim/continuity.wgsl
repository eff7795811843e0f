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
// (report Eq. 8 or 9). Twin of src/solver/cpu/continuity.rs. One invocation walks one
// particle's stencil; continuity_tiled.wgsl walks a subgroup's together, with the pair terms
// below.

//! include shared/common.wgsl
//! include shared/reduce.wgsl
//! include shared/density_write.wgsl
//! array positions: vec4<f32>, read
//! array velocities: vec4<f32>, read
//! array starts: u32, read
//! array wall_positions: vec4<f32>, read
//! array wall_starts: u32, read
//! array densities: f32, read_write
//! array pressures: f32, read_write
// STATUS_MAX_DENSITY: the largest density so far; STATUS_STEP_MAX_DENSITY: of this step.
//! array status: u32, atomic, whole

// What a fluid particle brings to its pairs: position, velocity and carried density.
struct RateOwn {
    x: vec3<f32>,
    u: vec3<f32>,
    rho: f32,
}

fn rate_own(i: u32) -> RateOwn {
    let v = velocities_at(i);
    return RateOwn(positions_at(i).xyz, v.xyz, v.w);
}

// The sums of the rate, without their constant factors (applied by finish_rate).
struct RateSums {
    fluid: f32,
    wall: f32,
    diffusive: f32,
}

// The terms of the fluid neighbour at xj with velocity and carried density vj, added where
// `counted` (its own stencil's candidate) and it is closer than h.
fn add_fluid_rate(sums: ptr<function, RateSums>, own: RateOwn, xj: vec3<f32>, vj: vec4<f32>, counted: bool) {
    let rij = own.x - xj;
    let r2 = dot(rij, rij);
    let counts = counted && !(r2 >= params.h2);
    let grad = kernel_grad(rij, sqrt(r2));
    (*sums).fluid += select(0.0, dot(own.u - vj.xyz, grad), counts);
    if (DENSITY_DIFFUSION) {
        var drho = vj.w - own.rho;
        if (GRAVITY) {
            drho -= density_above_rest(-params.rest_density * dot(params.gravity.xyz, rij));
        }
        // r2 = 0 only for i itself, whose gradient is zero.
        (*sums).diffusive += select(0.0, dot(rij, grad) * (drho / (vj.w * r2)), counts && r2 > 0.0);
    }
}

// The term of the wall neighbour w (position, mass), at rest.
fn add_wall_rate(sums: ptr<function, RateSums>, own: RateOwn, w: vec4<f32>, counted: bool) {
    let rij = own.x - w.xyz;
    let r2 = dot(rij, rij);
    (*sums).wall += select(0.0, dot(own.u, kernel_grad(rij, sqrt(r2))) * w.w, counted && !(r2 >= params.h2));
}

fn finish_rate(sums: RateSums) -> f32 {
    return (sums.fluid - params.diffusion_factor * sums.diffusive) * params.fluid_mass + sums.wall;
}

// The density rate of fluid particle i, one particle over its stencil.
fn density_rate(i: u32) -> f32 {
    let own = rate_own(i);
    let c = cell_coords(own.x);
    var sums = RateSums(0.0, 0.0, 0.0);
    for (var run = 0u; run < stencil_span_count(); run++) {
        let cells = stencil_run(c, run);
        for (var j = starts_at(cells.x); j < starts_at(cells.y); j++) {
            let xj = positions_at(j).xyz;
            let rij = own.x - xj;
            if (dot(rij, rij) >= params.h2) {
                continue;
            }
            add_fluid_rate(&sums, own, xj, velocities_at(j), true);
        }
        if (WALLS) {
            for (var j = wall_starts_at(cells.x); j < wall_starts_at(cells.y); j++) {
                let w = wall_positions_at(j);  // w: mass
                let rij = own.x - w.xyz;
                if (dot(rij, rij) >= params.h2) {
                    continue;
                }
                add_wall_rate(&sums, own, w, true);
            }
        }
    }
    return finish_rate(sums);
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
        set_carried_density(i, density_rate(i));
    }
    finish_densities(lid);
}

// The carried density advanced with `rate`, and its pressure.
fn set_carried_density(i: u32, rate: f32) {
    set_density(i, velocities_at(i).w + continuity_dt() * rate);
}
