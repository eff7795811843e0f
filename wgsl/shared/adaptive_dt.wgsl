// The adaptive step's pieces that the weakly compressible step (sim/integrate.wgsl) and DFSPH
// (sim/dfsph_predict.wgsl) share: the largest |v| and |a| reduced into the status words, and dt
// chosen from them, with the simulated time and the dt range that the host reads. The including
// stage declares the status words (`//! array status: u32, atomic, whole`) and includes
// shared/reduce.wgsl. Twin: AdaptiveDt::dt in src/model/params.rs.

// Offers a particle's |v| and |a| to the workgroup's maxima (between reduce_begin and
// publish_speed_and_acceleration). Non-negative floats order like their bits; a non-finite
// value is left out (the health check reports it).
fn offer_speed_and_acceleration(speed: f32, accel: f32) {
    if (is_finite_f32(speed)) {
        reduce_offer(0u, bitcast<u32>(speed));
    }
    if (is_finite_f32(accel)) {
        reduce_offer(1u, bitcast<u32>(accel));
    }
}

// Passes the workgroup's maxima on to the status words (every invocation calls it).
fn publish_speed_and_acceleration(lid: u32) {
    reduce_end();
    if (lid == 0u) {
        atomicMax(&status[STATUS_MAX_SPEED], reduce_result(0u));
        atomicMax(&status[STATUS_MAX_ACCELERATION], reduce_result(1u));
    }
}

// The step's largest |v| and |a|, the words reset for the next step (one thread).
fn take_speed_and_acceleration() -> vec2<f32> {
    let speed = bitcast<f32>(atomicLoad(&status[STATUS_MAX_SPEED]));
    let accel = bitcast<f32>(atomicLoad(&status[STATUS_MAX_ACCELERATION]));
    atomicStore(&status[STATUS_MAX_SPEED], 0u);
    atomicStore(&status[STATUS_MAX_ACCELERATION], 0u);
    return vec2<f32>(speed, accel);
}

// dt = clamp(min(cfl_dt, C_f sqrt(h / |a|max), C_visc h^2 / nu), dt_min, dt_max) (Monaghan
// 1992; Morris et al. 1997), a condition whose quantity is zero left out; then the dt, the
// simulated time (a Kahan-compensated sum; a compiler that reassociates floating point, as
// Mesa's lavapipe does, drops the compensation: docs/scenes.md) and the dt
// range go to the status words (one thread).
fn choose_and_record_dt(cfl_dt: f32, accel: f32) {
    var dt = cfl_dt;
    if (accel > 0.0) {
        dt = min(dt, params.force_number * sqrt(params.h / accel));
    }
    if (VISCOSITY && params.viscosity > 0.0) {
        dt = min(dt, params.viscous_number * params.h2 / params.viscosity);
    }
    dt = clamp(dt, params.dt_min, params.dt_max);
    atomicStore(&status[STATUS_DT], bitcast<u32>(dt));
    let sum = bitcast<f32>(atomicLoad(&status[STATUS_TIME]));
    let compensation = bitcast<f32>(atomicLoad(&status[STATUS_TIME_COMPENSATION]));
    let y = dt - compensation;
    let t = sum + y;
    atomicStore(&status[STATUS_TIME_COMPENSATION], bitcast<u32>((t - sum) - y));
    atomicStore(&status[STATUS_TIME], bitcast<u32>(t));
    atomicStore(&status[STATUS_DT_MIN], bitcast<u32>(min(bitcast<f32>(atomicLoad(&status[STATUS_DT_MIN])), dt)));
    atomicStore(&status[STATUS_DT_MAX], bitcast<u32>(max(bitcast<f32>(atomicLoad(&status[STATUS_DT_MAX])), dt)));
}
