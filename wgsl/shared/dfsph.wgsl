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
            let xj = positions_at(j).xyz;
            let rij = xi - xj;
            if (dot(rij, rij) >= params.h2) {
                continue;
            }
            sum += rate_pair(xi, vi, xj, velocities_at(j).xyz, true);
        }
    }
    return sum * params.fluid_volume + dot(vi, wall_gradients_at(i).xyz);
}

// The pair terms of density_rate and stiffness_push: (v_i - v_j) . grad W_ij and
// (K_i + K_j) grad W_ij, where `counted` (a tile's candidate in the own span) and j is closer than
// h (NaN distances included).
fn rate_pair(xi: vec3<f32>, vi: vec3<f32>, xj: vec3<f32>, vj: vec3<f32>, counted: bool) -> f32 {
    let rij = xi - xj;
    let r2 = dot(rij, rij);
    return select(0.0, dot(vi - vj, kernel_grad(rij, sqrt(r2))), counted && !(r2 >= params.h2));
}

fn push_pair(xi: vec3<f32>, ki: f32, xj: vec3<f32>, kj: f32, counted: bool) -> vec3<f32> {
    let rij = xi - xj;
    let r2 = dot(rij, rij);
    return select(vec3<f32>(0.0), kernel_grad(rij, sqrt(r2)) * (ki + kj), counted && !(r2 >= params.h2));
}

// V sum_j (K_i + K_j) grad W_ij + K_i g_i^w: the velocity change of the stiffness K, before its
// sign and scale.
fn stiffness_push(i: u32, xi: vec3<f32>, ki: f32) -> vec3<f32> {
    let c = cell_coords(xi);
    var sum = vec3<f32>(0.0);
    for (var run = 0u; run < stencil_span_count(); run++) {
        let cells = stencil_run(c, run);
        for (var j = starts_at(cells.x); j < starts_at(cells.y); j++) {
            let xj = positions_at(j).xyz;
            let rij = xi - xj;
            if (dot(rij, rij) >= params.h2) {
                continue;
            }
            sum += push_pair(xi, ki, xj, stiffness_at(j), true);
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
