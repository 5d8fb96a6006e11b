//! Numbers as text, byte for byte as Rust's `Display` (`{}`) writes them,
//! at a fraction of its cost: the OBJ of a million-vertex mesh holds some
//! 20 million floats, and `core::fmt`'s float path (Grisu with a Dragon
//! fallback, then the formatter's padding machinery) was a fifth of a whole
//! run's CPU time.
//!
//! A float's shortest round-trip digits come from `zmij` (Schubfach, the
//! crate serde_json already uses); they are `Display`'s digits except at an
//! exact tie, where the value lies exactly halfway between two shortest
//! candidates: `zmij` then keeps the even one and `core` rounds up
//! (5.97265625 is `5.9726562` to `zmij`, `5.9726563` to `Display`). Such a
//! tie is detected exactly, in integer arithmetic on the float's binary
//! mantissa and exponent, and rounded up as `core` does; a value whose test
//! would overflow 128 bits (magnitudes beyond about 10²⁸ or below 10⁻¹⁹) is
//! written by `core` itself. The digits are then laid out as `Display` does:
//! positional, never an exponent, `-0` for negative zero.
//!
//! Why by hand: no crate writes `Display`'s exact text (`ryu` and `zmij`
//! round ties to even and use exponents), and the files must keep their
//! bytes. The tests compare against `format!("{}")` on millions of values
//! and on every tie class; an ignored test compares all 2³² bit patterns.

use std::io::Write as _;

/// Appends `x` as `format!("{x}")` writes it.
pub fn push_f32(out: &mut Vec<u8>, x: f32) {
    if !x.is_finite() || x == 0.0 {
        let _ = write!(out, "{x}");
        return;
    }
    let mut buffer = zmij::Buffer::new();
    let text = buffer.format_finite(x).as_bytes();
    // Most floats cannot be a tie (below) and `zmij` writes them as
    // `Display` does, positionally: copied as they are.
    if !may_tie(x) && !text.contains(&b'e') && !text.ends_with(b".0") {
        out.extend_from_slice(text);
        return;
    }
    let Some((mut digits, mut exp)) = parse_digits(text) else {
        let _ = write!(out, "{x}");
        return;
    };
    match is_upper_tie(x.abs(), digits, exp) {
        Some(false) => {}
        Some(true) => {
            digits += 1;
            while digits.is_multiple_of(10) {
                digits /= 10;
                exp += 1;
            }
        }
        None => {
            let _ = write!(out, "{x}");
            return;
        }
    }
    if x.is_sign_negative() {
        out.push(b'-');
    }
    push_positional(out, digits, exp);
}

/// Appends an unsigned integer as `Display` writes it.
#[inline]
pub fn push_u64(out: &mut Vec<u8>, v: u64) {
    let mut b = itoa::Buffer::new();
    out.extend_from_slice(b.format(v).as_bytes());
}

/// The significant digits of `zmij`'s text (`[-]d[.ddd][e±x]`) as an
/// integer without trailing zeros and the power of ten of its last digit.
fn parse_digits(text: &[u8]) -> Option<(u64, i32)> {
    let mut digits: u64 = 0;
    let mut count = 0u32;
    let mut after_point = 0i32;
    let mut seen_point = false;
    let mut exp = 0i32;
    let mut i = usize::from(text.first() == Some(&b'-'));
    while i < text.len() {
        let c = text[i];
        match c {
            b'0'..=b'9' => {
                if count < 19 {
                    digits = digits * 10 + u64::from(c - b'0');
                    if digits > 0 {
                        count += 1;
                    }
                } else {
                    return None;
                }
                if seen_point {
                    after_point += 1;
                }
            }
            b'.' => seen_point = true,
            b'e' | b'E' => {
                let rest = std::str::from_utf8(&text[i + 1..]).ok()?;
                exp = rest.trim_start_matches('+').parse().ok()?;
                break;
            }
            _ => return None,
        }
        i += 1;
    }
    if digits == 0 {
        return None;
    }
    let mut e = exp - after_point;
    while digits.is_multiple_of(10) {
        digits /= 10;
        e += 1;
    }
    Some((digits, e))
}

/// Whether the finite, non-zero `x` can lie exactly halfway between two
/// shortest candidates of at most 9 digits. With `|x| = m·2^q`, `m` odd, a
/// tie `2|x| = (2D + 1)·10^e` with `q + 1 < 0` needs `e = q + 1` and
/// `2D + 1 = m·5^(−q−1)`, which is below 2·10⁹ only when `q ≥ −14`; so a
/// float with `q < −14` (most coordinates: a long mantissa, a small
/// exponent) never ties.
#[inline]
fn may_tie(x: f32) -> bool {
    let (m, q) = mantissa_exponent(x);
    q + m.trailing_zeros() as i32 >= -14
}

/// `|x| = m·2^q` exactly, `m` the integer significand (with the implicit
/// bit for a normal float).
#[inline]
fn mantissa_exponent(x: f32) -> (u32, i32) {
    let bits = x.to_bits() & 0x7FFF_FFFF;
    let biased = (bits >> 23) as i32;
    let fraction = bits & 0x7F_FFFF;
    if biased == 0 {
        (fraction, -149)
    } else {
        (fraction | 0x80_0000, biased - 150)
    }
}

/// Whether `v` (positive, finite) is exactly `(digits + ½)·10^exp`, the tie
/// `core` rounds up and `zmij` down; `None` when the exact test would
/// overflow 128 bits.
fn is_upper_tie(v: f32, digits: u64, exp: i32) -> Option<bool> {
    let (m, q) = mantissa_exponent(v);
    let (m, t) = (u128::from(m), u128::from(2 * digits + 1));
    // 2v = t·10^exp  ⇔  m·2^(q+1) = t·5^exp·2^exp.
    let pow5 = |k: u32| 5u128.checked_pow(k);
    let (lhs, rhs) = if exp >= 0 {
        (m, t.checked_mul(pow5(exp as u32)?)?)
    } else {
        (m.checked_mul(pow5((-exp) as u32)?)?, t)
    };
    // Compare lhs·2^(q + 1 − exp) with rhs.
    let shift = q + 1 - exp;
    let (a, b) = if shift >= 0 {
        (shl_checked(lhs, shift as u32)?, rhs)
    } else {
        (lhs, shl_checked(rhs, (-shift) as u32)?)
    };
    Some(a == b)
}

fn shl_checked(x: u128, s: u32) -> Option<u128> {
    if x == 0 {
        return Some(0);
    }
    if s >= 128 || x.leading_zeros() < s {
        return None;
    }
    Some(x << s)
}

/// `digits·10^exp` written out without an exponent.
fn push_positional(out: &mut Vec<u8>, digits: u64, exp: i32) {
    let mut b = itoa::Buffer::new();
    let d = b.format(digits).as_bytes();
    let n = d.len() as i32;
    if exp >= 0 {
        out.extend_from_slice(d);
        out.resize(out.len() + exp as usize, b'0');
    } else if n + exp > 0 {
        let point = (n + exp) as usize;
        out.extend_from_slice(&d[..point]);
        out.push(b'.');
        out.extend_from_slice(&d[point..]);
    } else {
        out.extend_from_slice(b"0.");
        out.resize(out.len() + (-(n + exp)) as usize, b'0');
        out.extend_from_slice(d);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn check(x: f32) {
        let mut out = Vec::new();
        push_f32(&mut out, x);
        assert_eq!(
            std::str::from_utf8(&out).unwrap(),
            format!("{x}"),
            "bits {:#010x}",
            x.to_bits()
        );
    }

    #[test]
    fn equals_display_on_special_and_tie_values() {
        for x in [
            0.0f32,
            -0.0,
            1.0,
            -1.0,
            0.1,
            5.972_656_3,
            -5.972_656_3,
            1e-7,
            1e30,
            -1e30,
            f32::MAX,
            f32::MIN,
            f32::MIN_POSITIVE,
            f32::EPSILON,
            1e-45,
            3.4e-39,
            16_777_216.0,
            16_777_217.0,
            123_456_790.0,
            0.5,
            0.25,
            100.0,
            9.999_999,
            f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
        ] {
            check(x);
        }
        // Exact ties: dyadic values with more digits than the shortest
        // round trip needs (k/2^j for many j).
        for j in 0..40 {
            for k in 1..2000u32 {
                check(k as f32 / (1u64 << j) as f32);
                check(-(k as f32) * (1u64 << j.min(30)) as f32);
            }
        }
    }

    #[test]
    fn equals_display_on_random_bit_patterns_and_mesh_like_values() {
        let mut s = 0x9E37_79B9_7F4A_7C15u64;
        for _ in 0..2_000_000 {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            check(f32::from_bits(s as u32));
            // Coordinates and texture coordinates of typical size.
            check(((s >> 40) as f32 / (1u64 << 24) as f32 - 0.5) * 300.0);
            check((s >> 40) as f32 / (1u64 << 24) as f32);
        }
    }

    /// Every one of the 2³² bit patterns (a few minutes on 2 cores):
    /// `cargo test --release --lib decimal -- --ignored`.
    #[test]
    #[ignore]
    fn equals_display_on_every_f32() {
        use rayon::prelude::*;
        (0..=u32::MAX >> 16).into_par_iter().for_each(|hi| {
            let mut out = Vec::with_capacity(64);
            let mut std = String::with_capacity(64);
            for lo in 0..=u16::MAX as u32 {
                let x = f32::from_bits(hi << 16 | lo);
                out.clear();
                push_f32(&mut out, x);
                std.clear();
                use std::fmt::Write as _;
                let _ = write!(std, "{x}");
                assert_eq!(out, std.as_bytes(), "bits {:#010x}", x.to_bits());
            }
        });
    }

    #[test]
    fn integers_equal_display() {
        for v in [0u64, 1, 9, 10, 99, 12_345, u32::MAX as u64, u64::MAX] {
            let mut out = Vec::new();
            push_u64(&mut out, v);
            assert_eq!(out, v.to_string().as_bytes());
        }
    }
}
