// What the density stages (density.wgsl, continuity.wgsl and their tiled twins; DFSPH's factors
// the largest density only) write: a particle's density and its pressure from the equation of
// state, and the workgroup's largest density into the status words (STATUS_MAX_DENSITY: of the
// run; STATUS_STEP_MAX_DENSITY: of this step). The including stage declares `densities`,
// `pressures` and `status` and includes shared/reduce.wgsl; every invocation of a workgroup
// calls reduce_begin before and finish_densities after. The tiled stages take the largest over
// their subgroup instead, without a barrier (shared/density_write_tiled.wgsl).

fn set_density(i: u32, rho: f32) {
    densities_set(i, rho);
    pressures_set(i, eos_pressure(rho));
    offer_density(rho);
}

// The density this invocation offers to the largest, as a key that orders like it (a positive
// float's bits do); 0: none.
var<private> offered_density_key: u32 = 0u;

// Offers a density to the largest (finish_densities passes it on): a positive finite one only.
fn offer_density(rho: f32) {
    if (is_finite_f32(rho) && rho > 0.0) {
        offered_density_key = max(offered_density_key, bitcast<u32>(rho));
    }
}

fn finish_densities(lid: u32) {
    reduce_offer(0u, offered_density_key);
    reduce_end();
    if (lid == 0u) {
        let largest = reduce_result(0u);
        atomicMax(&status[STATUS_MAX_DENSITY], largest);
        atomicMax(&status[STATUS_STEP_MAX_DENSITY], largest);
    }
}
