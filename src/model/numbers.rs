//! Numbers in messages: short enough to read, whatever their size.

/// A number for a message: plain where that is short, otherwise in scientific notation
/// (1e300, not three hundred digits); six significant digits, or all of a number written with
/// up to a dozen (a value as a user writes it: a limit of 1 exceeded by 1.0000001 must not read
/// "is 1"). A computed number's 17 digits are rounded to six.
pub fn short(v: f64) -> String {
    let trim = |t: String| if t.contains('.') { t.trim_end_matches('0').trim_end_matches('.').to_string() } else { t };
    if v == 0.0 || !v.is_finite() {
        return format!("{v}");
    }
    let plain = (1e-4..1e7).contains(&v.abs());
    let six = if plain {
        let decimals = (5 - v.abs().log10().floor() as i32).max(0) as usize;
        trim(format!("{v:.decimals$}"))
    } else {
        let e = format!("{v:.5e}");
        let (m, x) = e.split_once('e').expect("scientific notation");
        format!("{}e{x}", trim(m.to_string()))
    };
    // The significant digits of the shortest text that reads back as v.
    let exact = format!("{v:e}");
    let digits = exact.split_once('e').map_or(0, |(m, _)| m.bytes().filter(u8::is_ascii_digit).count());
    match six.parse::<f64>() {
        Ok(back) if back == v => six,
        _ if digits > 12 => six,
        _ if plain => format!("{v}"),
        _ => exact,
    }
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

#[cfg(test)]
mod tests {
    use super::short;

    #[test]
    fn a_short_number_is_short_and_never_another_number() {
        for (v, text) in [(1.5, "1.5"), (0.0, "0"), (1e300, "1e300"), (1e-300, "1e-300"), (123456.0, "123456"), (2.5e-7, "2.5e-7")] {
            assert_eq!(short(v), text);
        }
        // Where six digits would round onto a limit, the value is shown whole.
        for (v, text) in [(1.0000001, "1.0000001"), (100.00001, "100.00001"), (0.5000001, "0.5000001"), (1.00000001e-20, "1.00000001e-20"), (-7.123456789e-9, "-7.123456789e-9")] {
            assert_eq!(short(v), text);
        }
        // A computed number (all 17 digits) is rounded to six.
        for (v, text) in [(1.0 / 3.0, "0.333333"), (0.1 * 1.25, "0.125"), (10f64.powf(148.5), "3.16228e148")] {
            assert_eq!(short(v), text);
        }
    }
}
