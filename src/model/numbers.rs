//! Numbers in messages: short enough to read, whatever their size.

/// A number for a message: plain where that is short, otherwise in scientific notation
/// (1e300, not three hundred digits).
pub fn short(v: f64) -> String {
    let trim = |t: String| if t.contains('.') { t.trim_end_matches('0').trim_end_matches('.').to_string() } else { t };
    if v == 0.0 || !v.is_finite() {
        return format!("{v}");
    }
    if (1e-4..1e7).contains(&v.abs()) {
        // Six significant digits.
        let decimals = (5 - v.abs().log10().floor() as i32).max(0) as usize;
        return trim(format!("{v:.decimals$}"));
    }
    let e = format!("{v:.5e}");
    let (m, x) = e.split_once('e').expect("scientific notation");
    format!("{}e{x}", trim(m.to_string()))
}

/// A vector for a message, each component [`short`].
pub fn short3(v: [f64; 3]) -> String {
    format!("[{}, {}, {}]", short(v[0]), short(v[1]), short(v[2]))
}

/// A simulated time for a message: six decimals, or [`short`] where that would print more than
/// a dozen digits (a step of 1e300 s).
pub fn short_time(t: f64) -> String {
    if t.is_finite() && t.abs() < 1e7 {
        format!("{t:.6}")
    } else {
        short(t)
    }
}
