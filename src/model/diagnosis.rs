//! Why a run went bad: the message a failed run prints and writes into its summary.

use super::params::Params;
use super::state::Health;

/// Why a run went bad, with the likely cause in terms of the CFL condition.
pub fn diagnose(params: &Params, health: &Health, max_speed: f64) -> String {
    diagnose_at(params, health, max_speed, health.first_bad_step.unwrap_or(0) as f64 * params.dt)
}

/// `diagnose` for a run at simulated time `time` whose last step was `params.dt` (adaptive dt).
pub fn diagnose_at(params: &Params, health: &Health, max_speed: f64, time: f64) -> String {
    let step = health.first_bad_step.unwrap_or(0);
    let c0 = params.speed_of_sound();
    let cfl = params.dt * (c0 + max_speed) / params.h;
    let g = params.gravity.iter().map(|v| v * v).sum::<f64>().sqrt();
    let mut what = Vec::new();
    if health.non_finite > 0 {
        what.push(format!("{} particles became NaN or infinite", health.non_finite));
    }
    if health.escaped > 0 {
        what.push(format!("{} particles left the domain", health.escaped));
    }
    let mut msg = format!("step {step} (t = {time:.6}): {}.", what.join(" and "));
    if params.dfsph.is_some() {
        msg += &format!(
            " Likely cause: the time step is too large for the flow: the CFL number dt |v|max / h = {:.3} (dt = {}, |v|max = {:.4}, h = {}) should stay below about 0.25 with DFSPH, or a solve stopped at its iteration limit (see the summary's dfsph section): lower dt, use time.adaptive = true, or raise physics.dfsph.max_iterations.",
            cfl, params.dt, max_speed, params.h
        );
        return msg;
    }
    msg += &format!(
        " Likely cause: the time step is too large for the stiffness: the CFL number dt (c0 + |v|max) / h = {:.3} \
         (dt = {}, c0 = {:.4}, |v|max = {:.4}, h = {}); explicit WCSPH is stable below about 0.4",
        cfl, params.dt, c0, max_speed, params.h
    );
    if g > 0.0 {
        msg += &format!(", and the force condition dt sqrt(|g|/h) = {:.3} should stay below about 0.25", params.dt * (g / params.h).sqrt());
    }
    if let Some(a) = params.adaptive {
        msg += &format!(". With adaptive dt (dt_min = {}, dt_max = {}): lower time.cfl_number or time.force_number, or dt_min", a.dt_min, a.dt_max);
    }
    msg += ". Lower dt or the stiffness, or check the scene's boundaries.";
    msg
}

