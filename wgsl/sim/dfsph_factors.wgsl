// DFSPH, stage 1 of a step (after the binning): density by kernel summation over fluid and wall
// particles, the factor alpha (Bender & Koschier 2017, Eq. 11, in rest-density units), the
// wall gradient g^w = sum_b (m_b / rho0) grad W_ib, and the output pressure of the last step's
// constant-density solve, p = rho^2 K / (rho0 dt^2). Twin of src/solver/cpu/dfsph_factors.rs.

//! include shared/common.wgsl
//! include shared/reduce.wgsl
//! include shared/density_write.wgsl
//! array positions: vec4<f32>, read
//! array starts: u32, read
//! array wall_positions: vec4<f32>, read
//! array wall_starts: u32, read
//! array densities: f32, read_write
//! array pressures: f32, read_write
//! array factors: f32, read_write
//! array wall_gradients: vec4<f32>, read_write
//! array divergence_sum: f32, read_write
// The last step's constant-density stiffness sums, by particle id.
//! array warm_pressure: f32, read
// STATUS_MAX_DENSITY: the largest density so far; STATUS_STEP_MAX_DENSITY: of this step;
// STATUS_DT: the last dt (adaptive dt).
//! array status: u32, atomic, whole

// The sums over a particle's neighbours: kernel sums of the fluid and the walls (m W), the fluid
// gradient and its squares, and the walls' m grad W.
struct FactorSums {
    fluid: f32,
    walls: f32,
    fluid_gradient: vec3<f32>,
    gradient_squares: f32,
    wall_gradient: vec3<f32>,
}

fn no_factor_sums() -> FactorSums {
    return FactorSums(0.0, 0.0, vec3<f32>(0.0), 0.0, vec3<f32>(0.0));
}

// Fluid neighbour at xj of the particle at xi, added where `counted` (its own stencil's
// candidate) and closer than h.
fn add_factor_fluid(sums: ptr<function, FactorSums>, xi: vec3<f32>, xj: vec3<f32>, counted: bool) {
    let rij = xi - xj;
    let r2 = dot(rij, rij);
    let counts = counted && !(r2 >= params.h2);
    let grad = kernel_grad(rij, sqrt(r2));
    (*sums).fluid += select(0.0, kernel_w(r2), counts);
    (*sums).fluid_gradient += select(vec3<f32>(0.0), grad, counts);
    (*sums).gradient_squares += select(0.0, dot(grad, grad), counts);
}

// Wall neighbour w (its mass in w.w), as add_factor_fluid.
fn add_factor_wall(sums: ptr<function, FactorSums>, xi: vec3<f32>, w: vec4<f32>, counted: bool) {
    let rij = xi - w.xyz;
    let r2 = dot(rij, rij);
    let counts = counted && !(r2 >= params.h2);
    (*sums).walls += select(0.0, w.w * kernel_w(r2), counts);
    (*sums).wall_gradient += select(vec3<f32>(0.0), kernel_grad(rij, sqrt(r2)) * w.w, counts);
}

// Particle i's outputs (p: its position, w its id) from its sums.
fn finish_factors(i: u32, p: vec4<f32>, sums: FactorSums) {
    let volume = params.fluid_volume;
    let g_wall = sums.wall_gradient / params.rest_density;
    let total = sums.fluid_gradient * volume + g_wall;
    let denominator = dot(total, total) + volume * volume * sums.gradient_squares;
    let factor = select(0.0, 1.0 / denominator, denominator > params.factor_epsilon);
    let rho = params.fluid_mass * sums.fluid + sums.walls;
    densities_set(i, rho);
    factors_set(i, factor);
    wall_gradients_set(i, vec4<f32>(g_wall, 0.0));
    divergence_sum_set(i, 0.0);
    var dt = params.dt;
    if (ADAPTIVE_DT) {
        dt = bitcast<f32>(atomicLoad(&status[STATUS_DT]));
    }
    let scale = select(0.0, 1.0 / (params.rest_density * dt * dt), dt > 0.0);
    pressures_set(i, rho * rho * warm_pressure_at(particle_id(p.w)) * scale);
    offer_density(rho);
}

// One invocation walks one particle's stencil; dfsph_factors_tiled.wgsl walks a subgroup's
// together, with the pair terms above.
@compute @workgroup_size(WORKGROUP_SIZE)
fn density_and_factor(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    reduce_begin(lid);
    let i = thread_index(gid, groups);
    if (i < params.fluid_count) {
        let p = positions_at(i);
        let xi = p.xyz;
        let c = cell_coords(xi);
        var sums = no_factor_sums();
        for (var run = 0u; run < stencil_span_count(); run++) {
            let cells = stencil_run(c, run);
            for (var j = starts_at(cells.x); j < starts_at(cells.y); j++) {
                let xj = positions_at(j).xyz;
                let rij = xi - xj;
                if (dot(rij, rij) >= params.h2) {
                    continue;
                }
                add_factor_fluid(&sums, xi, xj, true);
            }
            if (WALLS) {
                for (var j = wall_starts_at(cells.x); j < wall_starts_at(cells.y); j++) {
                    let w = wall_positions_at(j);  // w: mass
                    let rij = xi - w.xyz;
                    if (dot(rij, rij) >= params.h2) {
                        continue;
                    }
                    add_factor_wall(&sums, xi, w, true);
                }
            }
        }
        finish_factors(i, p, sums);
    }
    finish_densities(lid);
}
