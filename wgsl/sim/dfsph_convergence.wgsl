// When a DFSPH solve stops, decided on the GPU without a host round trip: after each Jacobi
// step one thread compares the error sum with the tolerance, between the minimum and maximum
// iteration counts, and writes the dispatch sizes of the next iteration's passes: the full size
// while the solve goes on, zero workgroups once it has ended, so that the iterations recorded
// after the last are empty dispatches. Twin of src/solver/cpu/dfsph_convergence.rs.

//! include shared/common.wgsl
//! array status: u32, atomic, whole
// Words 0-2: the dispatch size of the next iteration's passes; 4-6: the full size.
//! array solve_dispatch: u32, read_write, whole

// Which solve: 0 the divergence solve, 1 the constant-density solve.
override SOLVE: u32 = 1u;
// Whether the solve starts from a warm start, whose velocity change is its first iteration.
override WARM_START: bool = true;

// Before the first error: the warm start is the first iteration; the passes run.
@compute @workgroup_size(1)
fn begin_solve() {
    atomicStore(&status[STATUS_DFSPH_ITERATION], select(0u, 1u, WARM_START));
    atomicStore(&status[STATUS_DFSPH_SOLVING], 1u);
    atomicStore(&status[STATUS_DFSPH_ERROR_LO], 0u);
    atomicStore(&status[STATUS_DFSPH_ERROR_HI], 0u);
    for (var k = 0u; k < 3u; k++) {
        solve_dispatch[k] = solve_dispatch[4u + k];
    }
}

// After an error sum: the solve ends once at least the minimum of iterations is done and the
// error meets the tolerance, or at the maximum; its statistics go into the status words (an
// iteration count, the most and the last, the average error, unconverged when it stopped at the
// limit above the tolerance), and the next passes become empty. Otherwise one more iteration.
// The error sum starts again from 0. A solve that has ended stays ended.
@compute @workgroup_size(1)
fn check_convergence() {
    if (atomicLoad(&status[STATUS_DFSPH_SOLVING]) == 0u) {
        return;
    }
    let lo = atomicLoad(&status[STATUS_DFSPH_ERROR_LO]);
    let hi = atomicLoad(&status[STATUS_DFSPH_ERROR_HI]);
    atomicStore(&status[STATUS_DFSPH_ERROR_LO], 0u);
    atomicStore(&status[STATUS_DFSPH_ERROR_HI], 0u);
    var threshold = params.density_threshold;
    var min_iterations = params.min_iterations;
    var max_iterations = params.max_iterations;
    var total = STATUS_PRESSURE_ITERATIONS;
    if (SOLVE == 0u) {
        threshold = params.divergence_threshold;
        min_iterations = params.min_divergence_iterations;
        max_iterations = params.max_divergence_iterations;
        total = STATUS_DIVERGENCE_ITERATIONS;
    }
    // 64-bit comparison of (hi, lo) with the threshold's (y, x).
    let met = hi < threshold.y || (hi == threshold.y && lo <= threshold.x);
    let k = atomicLoad(&status[STATUS_DFSPH_ITERATION]);
    if ((k >= min_iterations && met) || k >= max_iterations) {
        atomicStore(&status[STATUS_DFSPH_SOLVING], 0u);
        // The words after `total`: the most, the last, the error and the unconverged steps.
        atomicAdd(&status[total], k);
        atomicMax(&status[total + 1u], k);
        atomicStore(&status[total + 2u], k);
        let sum = f32(hi) * 4294967296.0 + f32(lo);
        atomicStore(&status[total + 3u], bitcast<u32>(sum / (f32(params.fluid_count) * 1073741824.0)));
        if (!met) {
            atomicAdd(&status[total + 4u], 1u);
        }
        for (var j = 0u; j < 3u; j++) {
            solve_dispatch[j] = 0u;
        }
    } else {
        atomicStore(&status[STATUS_DFSPH_ITERATION], k + 1u);
    }
}
