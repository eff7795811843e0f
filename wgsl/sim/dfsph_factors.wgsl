// DFSPH, stage 1 of a step (after the binning): density by kernel summation over fluid and wall
// particles, the factor alpha (Bender & Koschier 2017, Eq. 11, in rest-density units), the
// wall gradient g^w = sum_b (m_b / rho0) grad W_ib, and the output pressure of the last step's
// constant-density solve, p = rho^2 K / (rho0 dt^2). Twin of src/solver/cpu/dfsph_factors.rs.

//! include shared/common.wgsl
//! include shared/reduce.wgsl
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
        var fluid_sum = 0.0;
        var wall_sum = 0.0;
        var fluid_gradient = vec3<f32>(0.0);
        var gradient_squares = 0.0;
        var wall_gradient = vec3<f32>(0.0);
        for (var run = 0u; run < stencil_span_count(); run++) {
            let cells = stencil_run(c, run);
            for (var j = starts_at(cells.x); j < starts_at(cells.y); j++) {
                let rij = xi - positions_at(j).xyz;
                let r2 = dot(rij, rij);
                if (r2 >= params.h2) {
                    continue;
                }
                fluid_sum += kernel_w(r2);
                let grad = kernel_grad(rij, sqrt(r2));
                fluid_gradient += grad;
                gradient_squares += dot(grad, grad);
            }
            if (WALLS) {
                for (var j = wall_starts_at(cells.x); j < wall_starts_at(cells.y); j++) {
                    let w = wall_positions_at(j);  // w: mass
                    let rij = xi - w.xyz;
                    let r2 = dot(rij, rij);
                    if (r2 >= params.h2) {
                        continue;
                    }
                    wall_sum += w.w * kernel_w(r2);
                    wall_gradient += kernel_grad(rij, sqrt(r2)) * w.w;
                }
            }
        }
        let volume = params.fluid_volume;
        let g_wall = wall_gradient / params.rest_density;
        let total = fluid_gradient * volume + g_wall;
        let denominator = dot(total, total) + volume * volume * gradient_squares;
        let factor = select(0.0, 1.0 / denominator, denominator > params.factor_epsilon);
        let rho = params.fluid_mass * fluid_sum + wall_sum;
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
        if (is_finite_f32(rho) && rho > 0.0) {
            reduce_offer(0u, bitcast<u32>(rho));
        }
    }
    reduce_end();
    if (lid == 0u) {
        atomicMax(&status[STATUS_MAX_DENSITY], reduce_result(0u));
        atomicMax(&status[STATUS_STEP_MAX_DENSITY], reduce_result(0u));
    }
}
