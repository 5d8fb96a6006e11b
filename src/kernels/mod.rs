//! Pure algorithms over slices and `u32` indices. Nothing here imports
//! `bevy_ecs`, touches disk or reads the environment.
//!
//! One wing per method — [`jump_maps`] (Zelinka & Garland), [`wei_levoy`],
//! [`bangay_morkel`], [`lapped`] (Praun et al.), [`coherent`] — and the
//! shared wings: [`surface`] (frames, flattening, resampling), [`atlas`]
//! (charts, baking, rasterising, material channels) and [`metrics`].

pub mod atlas;
pub mod bangay_morkel;
pub mod coherent;
pub mod jump_maps;
pub mod knn;
pub mod lapped;
pub mod metrics;
pub mod simd_state;
pub mod surface;
pub mod wei_levoy;

/// SplitMix64-style mixing of three words into one seed: every random
/// stream (per stage, level, vertex, pass) derives its seed with it, so
/// results never depend on thread count or scheduling.
pub fn mix(a: u64, b: u64, c: u64) -> u64 {
    let mut z = a
        .wrapping_add(b.wrapping_mul(0x9E37_79B9_7F4A_7C15))
        .wrapping_add(c.wrapping_mul(0xD1B5_4A32_D192_ED03));
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// `⌊x⌋` by a truncating cast, saturating at the `i32` range: without
/// SSE4.1 in the baseline target `f32::floor` is a library call, which
/// costs more than the rest of a small loop body (template rasterisation).
#[inline]
pub(crate) fn floor_i(x: f32) -> i32 {
    let t = x as i32;
    if (t as f32) > x { t - 1 } else { t }
}

/// `x.floor()` without the library call: lives with the image sampler,
/// which is below the kernels.
pub use crate::image::sample::floor_f32;

/// `⌈x⌉`, like [`floor_i`].
#[inline]
pub(crate) fn ceil_i(x: f32) -> i32 {
    let t = x as i32;
    if (t as f32) < x { t + 1 } else { t }
}

/// [`floor_i`] in `i64`: the same value as `x.floor() as i64` for every
/// `f32`, NaN included (the coherent kernel's pixel lookup, run for every
/// compared neighbour).
#[inline]
pub(crate) fn floor_i64(x: f32) -> i64 {
    let t = x as i64;
    if (t as f32) > x { t - 1 } else { t }
}

/// Squared Euclidean distance of two equal-length vectors, with eight
/// independent accumulators so it vectorises (a plain `.sum()` of squared
/// differences does not). The summation order is part of the result: the
/// jump-map and Wei–Levoy searches depend on it.
#[inline]
pub fn dist2(a: &[f32], b: &[f32]) -> f32 {
    let mut acc = [0.0f32; 8];
    let mut ca = a.chunks_exact(8);
    let mut cb = b.chunks_exact(8);
    for (x, y) in (&mut ca).zip(&mut cb) {
        for i in 0..8 {
            let d = x[i] - y[i];
            acc[i] += d * d;
        }
    }
    let mut s: f32 = acc.iter().sum();
    for (x, y) in ca.remainder().iter().zip(cb.remainder()) {
        let d = x - y;
        s += d * d;
    }
    s
}

#[cfg(test)]
mod tests {
    use super::floor_f32;

    #[test]
    fn floor_f32_is_the_library_floor_bit_for_bit() {
        let check = |x: f32| {
            let (ours, std) = (floor_f32(x), x.floor());
            assert!(
                ours.to_bits() == std.to_bits() || (ours.is_nan() && std.is_nan()),
                "floor({x:e}) = {ours:e}, library {std:e}"
            );
        };
        for x in [
            0.0,
            -0.0,
            0.5,
            -0.5,
            -1.0,
            8_388_607.5,
            -8_388_607.5,
            8_388_608.0,
            f32::MIN_POSITIVE,
            -f32::MIN_POSITIVE,
            f32::MAX,
            f32::MIN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NAN,
        ] {
            check(x);
        }
        // Every 977th bit pattern: both signs, every exponent.
        let mut bits = 0u32;
        while let Some(next) = bits.checked_add(977) {
            check(f32::from_bits(bits));
            bits = next;
        }
    }
}
