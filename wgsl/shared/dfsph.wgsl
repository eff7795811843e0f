// What DFSPH's solves share: the rate of density change and the velocity change of a stiffness
// (in rest-density units; src/solver/cpu/dfsph_shared.rs, their twin, explains them), and the
// error sum in fixed point. Included by the stage files of the two solves.

//! array positions: vec4<f32>, read
//! array velocities: vec4<f32>, read
//! array starts: u32, read
//! array wall_gradients: vec4<f32>, read
//! array stiffness: f32, read

// D_i = V sum_j (v_i - v_j) . grad W_ij + v_i . g_i^w: the rate of change of rho_i / rho0.
fn density_rate(i: u32, xi: vec3<f32>, vi: vec3<f32>) -> f32 {
    let c = cell_coords(xi);
    var sum = 0.0;
    for (var run = 0u; run < stencil_span_count(); run++) {
        let cells = stencil_run(c, run);
        for (var j = starts_at(cells.x); j < starts_at(cells.y); j++) {
            let rij = xi - positions_at(j).xyz;
            let r2 = dot(rij, rij);
            if (r2 >= params.h2) {
                continue;
            }
            sum += dot(vi - velocities_at(j).xyz, kernel_grad(rij, sqrt(r2)));
        }
    }
    return sum * params.fluid_volume + dot(vi, wall_gradients_at(i).xyz);
}

// V sum_j (K_i + K_j) grad W_ij + K_i g_i^w: the velocity change of the stiffness K, before its
// sign and scale.
fn stiffness_push(i: u32, xi: vec3<f32>, ki: f32) -> vec3<f32> {
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
            sum += kernel_grad(rij, sqrt(r2)) * (ki + stiffness_at(j));
        }
    }
    return sum * params.fluid_volume + wall_gradients_at(i).xyz * ki;
}

// The error sum of a workgroup in fixed point (2^-30 units, each particle's error clamped to
// [0, 3]), a 64-bit sum kept as two words: integer sums do not depend on the order of the
// additions, so the sum, and the decision to stop, are those of the CPU's twin.
var<workgroup> error_lo: atomic<u32>;
var<workgroup> error_hi: atomic<u32>;

fn error_begin(lid: u32) {
    if (lid == 0u) {
        atomicStore(&error_lo, 0u);
        atomicStore(&error_hi, 0u);
    }
    workgroupBarrier();
}

// Adds units to a (low, high) pair of words: the carry out of the low word goes to the high one.
fn add_units(units: u32) {
    let old = atomicAdd(&error_lo, units);
    if (old + units < old) {
        atomicAdd(&error_hi, 1u);
    }
}

fn error_offer(e: f32) {
    // NaN offers nothing: the health check reports it.
    if (is_finite_f32(e)) {
        add_units(u32(clamp(e, 0.0, 3.0) * 1073741824.0));
    }
}

// Every invocation calls this; one per workgroup adds the workgroup's sum to the status words.
fn error_end(lid: u32) {
    workgroupBarrier();
    if (lid == 0u) {
        let lo = atomicLoad(&error_lo);
        let old = atomicAdd(&status[STATUS_DFSPH_ERROR_LO], lo);
        let carry = select(0u, 1u, old + lo < old);
        atomicAdd(&status[STATUS_DFSPH_ERROR_HI], atomicLoad(&error_hi) + carry);
    }
}
