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

// The simulated time is the sum of the steps' dt, kept exactly: time = M 2^E, with M a 64-bit
// integer (STATUS_TIME_LO, STATUS_TIME_HI) held at most 2^62 and E an i32 (STATUS_TIME_EXPONENT).
// Each dt is an f32, m 2^e with a 24-bit integer m, so it adds as m shifted by e - E, exactly
// whenever e >= E; E grows only when M passes 2^62 (or a dt so large that m would shift past
// it arrives), so a sum is exact as long as each dt's last bit is above time / 2^62. A Kahan
// sum in f32 would need the compiler to keep (t - sum) - y as written; integer arithmetic has
// no such licence to reassociate (Mesa's lavapipe dropped the compensation). Twin: TimeSum in
// src/model/params.rs.
const TIME_SIGNIFICAND_LIMIT_HI: u32 = 0x40000000u;   // 2^62 as the high word
const TIME_SHIFT_ROOM: i32 = 38;                      // a 24-bit m shifted by up to 38 stays below 2^62

// v << k and v >> k for a 64-bit (low, high) pair; 0 when k >= 64. (WGSL's u32 shifts take k
// modulo 32, hence the cases.)
fn shift_left_64(v: vec2<u32>, k: u32) -> vec2<u32> {
    if (k == 0u) {
        return v;
    }
    if (k < 32u) {
        return vec2<u32>(v.x << k, (v.y << k) | (v.x >> (32u - k)));
    }
    if (k < 64u) {
        return vec2<u32>(0u, v.x << (k - 32u));
    }
    return vec2<u32>(0u);
}

fn shift_right_64(v: vec2<u32>, k: u32) -> vec2<u32> {
    if (k == 0u) {
        return v;
    }
    if (k < 32u) {
        return vec2<u32>((v.x >> k) | (v.y << (32u - k)), v.y >> k);
    }
    if (k < 64u) {
        return vec2<u32>(v.y >> (k - 32u), 0u);
    }
    return vec2<u32>(0u);
}

fn add_64(a: vec2<u32>, b: vec2<u32>) -> vec2<u32> {
    let lo = a.x + b.x;
    return vec2<u32>(lo, a.y + b.y + select(0u, 1u, lo < a.x));
}

// v / 2^k rounded to nearest, ties up (v < 2^63, so adding 2^(k-1) does not overflow; and
// v / 2^64 rounds to 0).
fn shift_right_rounded_64(v: vec2<u32>, k: u32) -> vec2<u32> {
    if (k == 0u) {
        return v;
    }
    if (k >= 64u) {
        return vec2<u32>(0u);
    }
    return shift_right_64(add_64(v, shift_left_64(vec2<u32>(1u, 0u), k - 1u)), k);
}

// Adds dt (> 0, finite) to the time words (one thread).
fn add_to_time(dt: f32) {
    let bits = bitcast<u32>(dt);
    let biased = i32((bits >> 23u) & 0xffu);
    // dt = m 2^e (a subnormal has no hidden bit and the exponent of the smallest normal).
    let m = (bits & 0x7fffffu) | select(0x800000u, 0u, biased == 0);
    let e = max(biased, 1) - 150;
    var sum = vec2<u32>(atomicLoad(&status[STATUS_TIME_LO]), atomicLoad(&status[STATUS_TIME_HI]));
    var exponent = bitcast<i32>(atomicLoad(&status[STATUS_TIME_EXPONENT]));
    if (e - exponent > TIME_SHIFT_ROOM) {
        sum = shift_right_rounded_64(sum, u32(e - TIME_SHIFT_ROOM - exponent));
        exponent = e - TIME_SHIFT_ROOM;
    }
    if (e >= exponent) {
        sum = add_64(sum, shift_left_64(vec2<u32>(m, 0u), u32(e - exponent)));
    } else {
        sum = add_64(sum, shift_right_rounded_64(vec2<u32>(m, 0u), u32(exponent - e)));
    }
    if (sum.y > TIME_SIGNIFICAND_LIMIT_HI || (sum.y == TIME_SIGNIFICAND_LIMIT_HI && sum.x > 0u)) {
        sum = shift_right_rounded_64(sum, 1u);
        exponent += 1;
    }
    atomicStore(&status[STATUS_TIME_LO], sum.x);
    atomicStore(&status[STATUS_TIME_HI], sum.y);
    atomicStore(&status[STATUS_TIME_EXPONENT], bitcast<u32>(exponent));
}

// The simulated time in f32 (for the record of a bad step; the host reads the words).
fn simulated_time() -> f32 {
    let lo = atomicLoad(&status[STATUS_TIME_LO]);
    let hi = atomicLoad(&status[STATUS_TIME_HI]);
    let exponent = bitcast<i32>(atomicLoad(&status[STATUS_TIME_EXPONENT]));
    // In two halves, so that neither power of two leaves the f32 range on its own.
    let half = exponent / 2;
    return ldexp(ldexp(f32(hi) * 4294967296.0 + f32(lo), half), exponent - half);
}

// dt = clamp(min(cfl_dt, C_f sqrt(h / |a|max), C_visc h^2 / nu), dt_min, dt_max) (Monaghan
// 1992; Morris et al. 1997), a condition whose quantity is zero left out; then the dt, the
// simulated time and the dt range go to the status words (one thread).
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
    add_to_time(dt);
    atomicStore(&status[STATUS_DT_MIN], bitcast<u32>(min(bitcast<f32>(atomicLoad(&status[STATUS_DT_MIN])), dt)));
    atomicStore(&status[STATUS_DT_MAX], bitcast<u32>(max(bitcast<f32>(atomicLoad(&status[STATUS_DT_MAX])), dt)));
}
