//! Numbers as `trajectory.csv` writes them: exactly the bytes of Rust's
//! `Display` for `f64` (the shortest digits that read back to the same bits,
//! laid out without an exponent: `0.0000001`, `100`, `-0`), found faster.
//!
//! Formatting a 200-body pour's rows each step with `write!` took 3 % of the
//! process's time; its writer thread shares the cores with the ranks, which
//! poll while they wait, so under `mpirun` every row costs a rank its core.
//! `zmij` finds the same shortest digits (both choose the closest of the
//! shortest strings that round-trip) in a fraction of the time; only its
//! layout differs (`1e-7`, `100.0`), and is redone here.

/// Appends `v` to `out` as `format!("{v}")` would.
pub fn push_f64(out: &mut Vec<u8>, digits: &mut zmij::Buffer, v: f64) {
    use std::io::Write as _;
    if !v.is_finite() {
        // NaN and the infinities: rare, and their spelling is std's.
        let _ = write!(out, "{v}");
        return;
    }
    let whole = digits.format_finite(v).as_bytes();
    let (negative, printed) = match whole.split_first() {
        Some((b'-', rest)) => (true, rest),
        _ => (false, whole),
    };
    // Most numbers: `123.456`, `-0.000015`, std's bytes already, unless
    // they are an integer (`100.0`) or a tie (see below).
    if let Some(dot) = printed.iter().position(|&c| c == b'.') {
        if !printed.ends_with(b".0") && !printed.contains(&b'e') {
            let q = -((printed.len() - dot - 1) as i32);
            if odd_part(v).1 + 1 != q {
                out.extend_from_slice(whole);
                return;
            }
        }
    }
    // zmij writes `mantissa[e±exponent]`, the mantissa with at most one
    // point: the value is the mantissa's digits with the point `point`
    // places from their start.
    let (mantissa, exponent) = match printed.iter().position(|&c| c == b'e') {
        Some(e) => (&printed[..e], parse_exponent(&printed[e + 1..])),
        None => (printed, 0),
    };
    let mut all = [0u8; 32];
    let mut n = 0;
    let mut point = None;
    for &c in mantissa {
        if c == b'.' {
            point = Some(n);
        } else {
            all[n] = c;
            n += 1;
        }
    }
    let mut point = point.unwrap_or(n) as i32 + exponent;
    // Significant digits only: leading zeros move the point, trailing
    // zeros are the point's business.
    let mut first = 0;
    while first < n && all[first] == b'0' {
        first += 1;
        point -= 1;
    }
    let mut last = n;
    while last > first && all[last - 1] == b'0' {
        last -= 1;
    }
    let significant = &all[first..last];
    if significant.is_empty() {
        out.extend_from_slice(if negative { b"-0" } else { b"0" });
        return;
    }
    let len = significant.len() as i32;
    if halfway_between_neighbours(v, significant, point - len) {
        // Two shortest strings equally close: std takes the one of larger
        // magnitude, zmij the even one. Rare; std's own answer.
        let _ = write!(out, "{v}");
        return;
    }
    if negative {
        out.push(b'-');
    }
    if point <= 0 {
        out.extend_from_slice(b"0.");
        out.resize(out.len() + (-point) as usize, b'0');
        out.extend_from_slice(significant);
    } else if point < len {
        let (whole, fraction) = significant.split_at(point as usize);
        out.extend_from_slice(whole);
        out.push(b'.');
        out.extend_from_slice(fraction);
    } else {
        out.extend_from_slice(significant);
        out.resize(out.len() + (point - len) as usize, b'0');
    }
}

/// Whether |v| lies exactly halfway between the decimal `digits` × 10^`q`
/// and a neighbour one unit of the last digit away: 2|v| = (2·digits ± 1)
/// × 10^q, checked in integers. Writing |v| = m·2^e with m odd, the odd
/// parts and the powers of two must agree on both sides.
fn halfway_between_neighbours(v: f64, digits: &[u8], q: i32) -> bool {
    let (m, e) = odd_part(v);
    // 2|v| = m·2^(e+1) and (2d ± 1)·10^q = (2d ± 1)·5^q·2^q with m and
    // (2d ± 1)·5^q odd (for q < 0 move 5^-q over: m·5^-q = (2d ± 1)·2^(q-e-1)):
    // the powers of two agree only where e + 1 = q, which is rare.
    if e + 1 != q {
        return false;
    }
    let d = digits
        .iter()
        .fold(0u128, |acc, &c| acc * 10 + u128::from(c - b'0'));
    let fives = |k: u32| 5u128.checked_pow(k);
    for odd in [2 * d + 1, 2 * d - 1] {
        let matches = if q >= 0 {
            // m = (2d ± 1)·5^q.
            fives(q as u32).and_then(|f| f.checked_mul(odd)) == Some(u128::from(m))
        } else {
            // m·5^-q = 2d ± 1.
            fives((-q) as u32).and_then(|f| f.checked_mul(u128::from(m))) == Some(odd)
        };
        if matches {
            return true;
        }
    }
    false
}

/// |v| = m·2^e with m odd (v finite, not zero).
fn odd_part(v: f64) -> (u64, i32) {
    let bits = v.to_bits();
    let fraction = bits & ((1u64 << 52) - 1);
    let biased = ((bits >> 52) & 0x7ff) as i32;
    let (m, e) = if biased == 0 {
        (fraction, -1074)
    } else {
        (fraction | (1u64 << 52), biased - 1075)
    };
    let zeros = m.trailing_zeros();
    (m >> zeros, e + zeros as i32)
}

/// `+21`, `-7`, `308`: zmij's exponent.
fn parse_exponent(e: &[u8]) -> i32 {
    let (sign, digits) = match e.split_first() {
        Some((b'-', rest)) => (-1, rest),
        Some((b'+', rest)) => (1, rest),
        _ => (1, e),
    };
    sign * digits
        .iter()
        .fold(0i32, |acc, &d| acc * 10 + i32::from(d - b'0'))
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};

    fn check(v: f64) {
        let mut out = Vec::new();
        push_f64(&mut out, &mut zmij::Buffer::new(), v);
        assert_eq!(
            String::from_utf8(out).unwrap(),
            format!("{v}"),
            "bits {:#018x}",
            v.to_bits()
        );
    }

    #[test]
    fn special_values_are_written_as_std_writes_them() {
        for v in [
            0.0,
            -0.0,
            1.0,
            -1.0,
            100.0,
            0.1,
            1e-7,
            1e15,
            1e16,
            1e17,
            1e21,
            1e22,
            123.456,
            0.000015,
            12345678.0,
            -2.5e-300,
            5e-324,
            f64::MIN_POSITIVE,
            f64::MAX,
            f64::MIN,
            f64::EPSILON,
            9.81,
            -9.81,
            f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
        ] {
            check(v);
        }
        for e in -330..=310 {
            check(10f64.powi(e));
            check(-1.5 * 10f64.powi(e));
        }
    }

    /// Values exactly halfway between two shortest strings, where std and
    /// zmij choose differently: few significant bits, or 2^50 and above.
    #[test]
    fn ties_are_broken_as_std_breaks_them() {
        check(f64::from_bits(0x431d_a7e6_898b_0aed));
        check(1.0 + 2f64.powi(-17));
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        for _ in 0..500_000 {
            let m = rng.random_range(1u64..1 << 24) as f64;
            let v = m * 2f64.powi(rng.random_range(-80..80));
            check(v);
            check(-v);
            check(1.0 + v * 2f64.powi(-40));
        }
    }

    #[test]
    fn random_bit_patterns_are_written_as_std_writes_them() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        for _ in 0..500_000 {
            check(f64::from_bits(rng.random::<u64>()));
        }
        // Numbers of a simulation's size: positions, quaternions, speeds.
        for _ in 0..500_000 {
            let scale = 10f64.powi(rng.random_range(-12..4));
            check(scale * (rng.random::<f64>() - 0.5));
        }
    }
}
