//! Procedural exemplars (`builtin:checker`, `builtin:stripes`,
//! `builtin:bricks`, `builtin:noise`) so the program runs without any image
//! file, and a size check for exemplars of any origin.
//!
//! Every pattern is a function of normalised coordinates `(u, v)` in `[0, 1)²`
//! that is periodic with period 1 in both, sampled at pixel centres (with
//! supersampling for the patterns with sharp edges). The images are therefore
//! tileable: sampling with [`Wrap::Repeat`](super::sample::Wrap::Repeat) shows
//! no seam, which is what the toroidal exemplar search of the synthesis
//! methods assumes.

use rayon::prelude::*;

use super::{Image, ImageError};

/// The prefix that marks a builtin exemplar in an exemplar spec.
pub const BUILTIN_PREFIX: &str = "builtin:";

/// The builtin exemplars: `(name, description)`.
pub const BUILTIN_EXEMPLARS: &[(&str, &str)] = &[
    (
        "checker",
        "two-colour checkerboard, 2·cells squares across (not seeded)",
    ),
    (
        "stripes",
        "vertical three-colour stripes, cells periods across (not seeded)",
    ),
    (
        "bricks",
        "running-bond red bricks with mortar lines, cells bricks across and 2·cells rows, seeded colour variation",
    ),
    (
        "noise",
        "colourful smooth fractal value noise, base frequency cells, seeded",
    ),
];

/// Options of the procedural exemplars (the `[exemplar]` options of a config).
#[derive(Clone, Debug, PartialEq, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ExemplarOptions {
    /// Width and height in pixels; 8..=2048, default 64.
    pub size: u32,
    /// Seed of the random choices (brick colours, noise); any value, default 0.
    /// The checker and stripes do not use it.
    pub seed: u64,
    /// Periods across the image: checker square pairs, stripe periods, bricks
    /// per row (with twice as many rows) or the noise base frequency;
    /// 1..=size/4, default 4.
    pub cells: u32,
}

impl Default for ExemplarOptions {
    fn default() -> Self {
        Self {
            size: 64,
            seed: 0,
            cells: 4,
        }
    }
}

impl ExemplarOptions {
    /// Smallest allowed `size`.
    pub const MIN_SIZE: u32 = 8;
    /// Largest allowed `size`.
    pub const MAX_SIZE: u32 = 2048;

    /// Checks the ranges documented on the fields; `name` is the builtin the
    /// options are for, for the error message.
    pub fn validate(&self, name: &str) -> Result<(), ImageError> {
        let err = |message: String| ImageError::Builtin {
            name: name.to_string(),
            message,
        };
        if !(Self::MIN_SIZE..=Self::MAX_SIZE).contains(&self.size) {
            return Err(err(format!(
                "size {} is out of range; allowed {}..={}",
                self.size,
                Self::MIN_SIZE,
                Self::MAX_SIZE
            )));
        }
        let max_cells = self.size / 4;
        if !(1..=max_cells).contains(&self.cells) {
            return Err(err(format!(
                "cells {} is out of range; allowed 1..={max_cells} (size / 4) for size {}",
                self.cells, self.size
            )));
        }
        Ok(())
    }
}

/// Generates the builtin exemplar `name` (without the `builtin:` prefix), an
/// RGB image of `options.size`² pixels with values in `[0, 1]`, tileable.
///
/// # Errors
///
/// [`ImageError::Builtin`] for an unknown name (the message lists the allowed
/// names) or options out of range.
pub fn builtin_exemplar(name: &str, options: &ExemplarOptions) -> Result<Image, ImageError> {
    let Some(pattern) = Pattern::from_name(name) else {
        let allowed: Vec<&str> = BUILTIN_EXEMPLARS.iter().map(|(n, _)| *n).collect();
        return Err(ImageError::Builtin {
            name: name.to_string(),
            message: format!(
                "unknown builtin exemplar; allowed: {}",
                allowed
                    .iter()
                    .map(|n| format!("{BUILTIN_PREFIX}{n}"))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        });
    };
    options.validate(name)?;
    Ok(render(pattern, options))
}

/// The height map of the builtin exemplar `name` (without the `builtin:`
/// prefix): a one-channel image of the same size and layout as
/// [`builtin_exemplar`] with the same `options`, values in `[0, 1]`, tileable
/// (the `height_map = "derive:builtin"` channel of a config). Bricks stand
/// proud of recessed mortar with bevelled edges and a fine grain; the noise's
/// height is its large-scale fractal value; the checker's light squares and
/// the stripes' red band are raised.
///
/// # Errors
///
/// As [`builtin_exemplar`]: an unknown name or options out of range.
pub fn builtin_height(name: &str, options: &ExemplarOptions) -> Result<Image, ImageError> {
    // Same name check and message as the colour exemplar.
    let Some(pattern) = Pattern::from_name(name) else {
        return builtin_exemplar(name, options);
    };
    options.validate(name)?;
    let size = options.size;
    let ss: u32 = match pattern {
        Pattern::Noise => 1,
        _ if size <= 256 => 4,
        _ => 2,
    };
    let ctx = Context::new(options);
    let mut img = Image::new(size, size, 1);
    img.data
        .par_chunks_mut(size as usize)
        .enumerate()
        .for_each(|(y, row)| {
            for (x, out) in row.iter_mut().enumerate() {
                let mut acc = 0.0f32;
                for sy in 0..ss {
                    for sx in 0..ss {
                        let u = (x as f32 + (sx as f32 + 0.5) / ss as f32) / size as f32;
                        let v = (y as f32 + (sy as f32 + 0.5) / ss as f32) / size as f32;
                        acc += ctx.height(pattern, u, v);
                    }
                }
                *out = (acc / (ss * ss) as f32).clamp(0.0, 1.0);
            }
        });
    Ok(img)
}

/// Checks that `img` is at least `needed`×`needed` pixels, the size of a
/// neighbourhood or patch (`what`, e.g. "neighbourhood") some method needs.
///
/// # Errors
///
/// [`ImageError::TooSmall`] naming the exemplar (`name`), its size and the need.
pub fn check_exemplar_size(
    img: &Image,
    name: &str,
    what: &str,
    needed: u32,
) -> Result<(), ImageError> {
    if img.width < needed || img.height < needed {
        return Err(ImageError::TooSmall {
            name: name.to_string(),
            width: img.width,
            height: img.height,
            what: what.to_string(),
            needed,
        });
    }
    Ok(())
}

#[derive(Clone, Copy, Debug)]
enum Pattern {
    Checker,
    Stripes,
    Bricks,
    Noise,
}

impl Pattern {
    fn from_name(name: &str) -> Option<Self> {
        match name {
            "checker" => Some(Self::Checker),
            "stripes" => Some(Self::Stripes),
            "bricks" => Some(Self::Bricks),
            "noise" => Some(Self::Noise),
            _ => None,
        }
    }
}

type Rgb = [f32; 3];

fn render(pattern: Pattern, options: &ExemplarOptions) -> Image {
    let size = options.size;
    // Supersampling anti-aliases the sharp edges that do not fall on pixel
    // boundaries; the smooth noise does not need it.
    let ss: u32 = match pattern {
        Pattern::Noise => 1,
        _ if size <= 256 => 4,
        _ => 2,
    };
    let ctx = Context::new(options);
    let mut img = Image::new(size, size, 3);
    let row_len = size as usize * 3;
    img.data
        .par_chunks_mut(row_len)
        .enumerate()
        .for_each(|(y, row)| {
            for x in 0..size as usize {
                let mut acc = [0.0f32; 3];
                for sy in 0..ss {
                    for sx in 0..ss {
                        let u = (x as f32 + (sx as f32 + 0.5) / ss as f32) / size as f32;
                        let v = (y as f32 + (sy as f32 + 0.5) / ss as f32) / size as f32;
                        let c = ctx.eval(pattern, u, v);
                        for i in 0..3 {
                            acc[i] += c[i];
                        }
                    }
                }
                let n = (ss * ss) as f32;
                for i in 0..3 {
                    row[x * 3 + i] = (acc[i] / n).clamp(0.0, 1.0);
                }
            }
        });
    img
}

/// Everything a pattern function needs besides `(u, v)`.
struct Context {
    seed: u64,
    cells: u32,
    size: u32,
}

impl Context {
    fn new(options: &ExemplarOptions) -> Self {
        Self {
            seed: options.seed,
            cells: options.cells,
            size: options.size,
        }
    }

    fn eval(&self, pattern: Pattern, u: f32, v: f32) -> Rgb {
        match pattern {
            Pattern::Checker => self.checker(u, v),
            Pattern::Stripes => self.stripes(u, v),
            Pattern::Bricks => self.bricks(u, v),
            Pattern::Noise => self.noise(u, v),
        }
    }

    /// Height in `[0, 1]` of the pattern at `(u, v)` ([`builtin_height`]).
    fn height(&self, pattern: Pattern, u: f32, v: f32) -> f32 {
        match pattern {
            Pattern::Checker => {
                let c = self.checker(u, v);
                if c[0] > 0.5 { 1.0 } else { 0.0 }
            }
            Pattern::Stripes => {
                let phase = (u * self.cells as f32).rem_euclid(1.0);
                if phase < 0.45 {
                    1.0
                } else if phase < 0.6 {
                    0.5
                } else {
                    0.0
                }
            }
            Pattern::Bricks => self.brick_height(u, v),
            Pattern::Noise => fbm(u, v, self.cells, 5, self.size, self.seed, 1),
        }
    }

    /// Bricks at 0.7–1.0 with a bevel over about 1.5 pixels at their edges,
    /// mortar at 0–0.1; the same layout and grain as [`Self::bricks`].
    fn brick_height(&self, u: f32, v: f32) -> f32 {
        let cells = self.cells as f32;
        let rows = 2 * self.cells;
        let brick_h = self.size as f32 / rows as f32;
        let brick_w = 2.0 * brick_h;
        let mortar_px = (0.125 * brick_h).max(1.0);
        let y = v * rows as f32;
        let row = (y.floor() as i64).rem_euclid(rows as i64);
        let fy = y - y.floor();
        let x = u * cells + if row % 2 == 1 { 0.5 } else { 0.0 };
        let fx = x - x.floor();
        let grain = fbm(u, v, 4 * self.cells, 3, self.size, self.seed, 7);
        let px = fx * brick_w;
        let py = fy * brick_h;
        if px < mortar_px || py < mortar_px {
            return 0.1 * grain;
        }
        let edge = (px - mortar_px)
            .min(py - mortar_px)
            .min(brick_w - px)
            .min(brick_h - py);
        let bevel = 1.0 - (-edge / 1.5).exp();
        0.2 + 0.65 * bevel + 0.15 * grain
    }

    fn checker(&self, u: f32, v: f32) -> Rgb {
        let n = 2 * self.cells;
        let cx = ((u * n as f32).floor() as i64).rem_euclid(n as i64);
        let cy = ((v * n as f32).floor() as i64).rem_euclid(n as i64);
        if (cx + cy) % 2 == 0 {
            [0.93, 0.87, 0.72]
        } else {
            [0.16, 0.33, 0.45]
        }
    }

    fn stripes(&self, u: f32, _v: f32) -> Rgb {
        let phase = (u * self.cells as f32).rem_euclid(1.0);
        if phase < 0.45 {
            [0.75, 0.18, 0.20]
        } else if phase < 0.6 {
            [0.96, 0.92, 0.80]
        } else {
            [0.12, 0.20, 0.42]
        }
    }

    fn bricks(&self, u: f32, v: f32) -> Rgb {
        let cells = self.cells as f32;
        let rows = 2 * self.cells;
        // Brick sizes in pixels; the mortar is about an eighth of a brick's
        // height and at least one pixel.
        let brick_h = self.size as f32 / rows as f32;
        let brick_w = 2.0 * brick_h;
        let mortar_px = (0.125 * brick_h).max(1.0);

        let y = v * rows as f32;
        let row = (y.floor() as i64).rem_euclid(rows as i64);
        let fy = y - y.floor();
        // Running bond: odd rows are shifted by half a brick.
        let x = u * cells + if row % 2 == 1 { 0.5 } else { 0.0 };
        let col = (x.floor() as i64).rem_euclid(self.cells as i64);
        let fx = x - x.floor();

        let grain = fbm(u, v, 4 * self.cells, 3, self.size, self.seed, 7);
        // Pixel distances from the top-left mortar lines and the far edges.
        let px = fx * brick_w;
        let py = fy * brick_h;
        if px < mortar_px || py < mortar_px {
            let m = 0.9 + 0.12 * grain;
            return [0.80 * m, 0.78 * m, 0.73 * m];
        }
        let h = hash(self.seed, 11, col as u64, row as u64);
        let tone = unit(h);
        let hue = unit(hash(self.seed, 12, col as u64, row as u64)) - 0.5;
        let burnt = unit(hash(self.seed, 13, col as u64, row as u64)) < 0.12;
        let dark = [0.50, 0.19, 0.13];
        let light = [0.74, 0.36, 0.23];
        let mut c = [0.0; 3];
        for i in 0..3 {
            c[i] = dark[i] + (light[i] - dark[i]) * tone;
        }
        // A little hue shift per brick: redder or more orange.
        c[1] *= 1.0 + 0.25 * hue;
        if burnt {
            for ci in &mut c {
                *ci *= 0.7;
            }
        }
        // Fine grain inside the brick, and a soft shade along its edges.
        let edge = (px - mortar_px)
            .min(py - mortar_px)
            .min(brick_w - px)
            .min(brick_h - py);
        let shade = 1.0 - 0.18 * (-edge / 1.2).exp();
        let g = 0.88 + 0.24 * grain;
        c.map(|ci| ci * g * shade)
    }

    fn noise(&self, u: f32, v: f32) -> Rgb {
        let n1 = fbm(u, v, self.cells, 5, self.size, self.seed, 1);
        let n2 = fbm(u, v, 2 * self.cells, 3, self.size, self.seed, 2);
        // Fractal noise clusters around 0.5; stretch it before the palette.
        let t = ((n1 - 0.5) * 2.4 + 0.5).clamp(0.0, 1.0);
        let offset = unit(hash(self.seed, 3, 0, 0));
        let brightness = 0.7 + 0.5 * n2;
        // A cosine rainbow palette (phases a third apart per channel).
        std::array::from_fn(|i| {
            let phase = t + offset + i as f32 / 3.0;
            let c = 0.5 + 0.38 * (std::f32::consts::TAU * phase).cos();
            (c * brightness).clamp(0.0, 1.0)
        })
    }
}

/// SplitMix64 finaliser over a combination of the inputs.
fn hash(seed: u64, salt: u64, a: u64, b: u64) -> u64 {
    let mut z = seed
        ^ salt.wrapping_mul(0x9E37_79B9_7F4A_7C15)
        ^ a.wrapping_mul(0xC2B2_AE3D_27D4_EB4F)
        ^ b.wrapping_mul(0x1656_67B1_9E37_79F9);
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// A hash mapped to `[0, 1)`.
fn unit(h: u64) -> f32 {
    (h >> 40) as f32 / (1u64 << 24) as f32
}

/// Value noise with `freq` lattice cells per unit, periodic with period 1,
/// quintic interpolation; values in `[0, 1]`.
fn value_noise(u: f32, v: f32, freq: u32, seed: u64, salt: u64) -> f32 {
    let f = freq as i64;
    let x = u * freq as f32;
    let y = v * freq as f32;
    let (x0, y0) = (x.floor(), y.floor());
    let (fx, fy) = (x - x0, y - y0);
    let (ix, iy) = (x0 as i64, y0 as i64);
    let at = |i: i64, j: i64| {
        unit(hash(
            seed,
            salt,
            i.rem_euclid(f) as u64,
            j.rem_euclid(f) as u64,
        ))
    };
    let fade = |t: f32| t * t * t * (t * (t * 6.0 - 15.0) + 10.0);
    let (sx, sy) = (fade(fx), fade(fy));
    let top = at(ix, iy) + (at(ix + 1, iy) - at(ix, iy)) * sx;
    let bot = at(ix, iy + 1) + (at(ix + 1, iy + 1) - at(ix, iy + 1)) * sx;
    top + (bot - top) * sy
}

/// Fractal sum of `octaves` value-noise octaves starting at `base` lattice
/// cells, doubling the frequency and halving the amplitude each octave, and
/// stopping before the lattice gets finer than two pixels; values in `[0, 1]`.
fn fbm(u: f32, v: f32, base: u32, octaves: u32, size: u32, seed: u64, salt: u64) -> f32 {
    let mut sum = 0.0;
    let mut norm = 0.0;
    let mut amp = 1.0;
    let mut freq = base.max(1);
    for k in 0..octaves {
        if k > 0 && freq > size / 2 {
            break;
        }
        sum += amp * value_noise(u, v, freq, seed, salt * 64 + k as u64);
        norm += amp;
        amp *= 0.5;
        freq *= 2;
    }
    sum / norm
}

#[cfg(test)]
mod tests {
    use super::*;

    fn all(opts: &ExemplarOptions) -> Vec<(&'static str, Image)> {
        BUILTIN_EXEMPLARS
            .iter()
            .map(|(n, _)| (*n, builtin_exemplar(n, opts).unwrap()))
            .collect()
    }

    /// Largest squared difference between adjacent pixels across the wrap
    /// seam and inside the image, along x (or y when `vertical`).
    fn seam_vs_interior(img: &Image, vertical: bool) -> (f32, f32) {
        let (w, h) = (img.width, img.height);
        let d = |a: &[f32], b: &[f32]| a.iter().zip(b).map(|(x, y)| (x - y).powi(2)).sum::<f32>();
        let (mut seam, mut interior) = (0.0f32, 0.0f32);
        for a in 0..w {
            for b in 0..h {
                let (p, q) = if vertical {
                    (img.pixel(a, b), img.pixel(a, (b + 1) % h))
                } else {
                    (img.pixel(b, a), img.pixel((b + 1) % w, a))
                };
                if b + 1 == h {
                    seam = seam.max(d(p, q));
                } else {
                    interior = interior.max(d(p, q));
                }
            }
        }
        (seam, interior)
    }

    #[test]
    fn builtins_are_rgb_in_range_and_tileable() {
        for size in [64, 96] {
            let opts = ExemplarOptions {
                size,
                seed: 3,
                cells: 4,
            };
            for (name, img) in all(&opts) {
                assert_eq!(
                    (img.width, img.height, img.channels),
                    (size, size, 3),
                    "{name}"
                );
                assert!(img.data.iter().all(|v| (0.0..=1.0).contains(v)), "{name}");
                for vertical in [false, true] {
                    let (seam, interior) = seam_vs_interior(&img, vertical);
                    assert!(
                        seam <= 1.01 * interior + 1e-4,
                        "{name} size {size}: seam {seam} vs interior {interior} (vertical {vertical})"
                    );
                }
            }
        }
    }

    #[test]
    fn patterns_are_periodic_with_period_one() {
        let opts = ExemplarOptions {
            size: 50,
            seed: 5,
            cells: 3,
        };
        let ctx = Context::new(&opts);
        for pattern in [
            Pattern::Checker,
            Pattern::Stripes,
            Pattern::Bricks,
            Pattern::Noise,
        ] {
            let mut mismatches = 0;
            for i in 0..400 {
                let u = (i as f32 * 0.618_034).fract();
                let v = (i as f32 * 0.414_213_5).fract();
                let a = ctx.eval(pattern, u, v);
                for (du, dv) in [(1.0, 0.0), (0.0, 1.0), (-1.0, 2.0)] {
                    let b = ctx.eval(pattern, u + du, v + dv);
                    if a.iter().zip(&b).any(|(x, y)| (x - y).abs() > 1e-3) {
                        mismatches += 1;
                    }
                }
            }
            // Points within rounding error of a sharp edge may flip sides.
            assert!(mismatches <= 4, "{pattern:?}: {mismatches} mismatches");
        }
    }

    #[test]
    fn seed_changes_bricks_and_noise_only() {
        let a = ExemplarOptions::default();
        let b = ExemplarOptions {
            seed: 99,
            ..a.clone()
        };
        for (name, img) in all(&a) {
            let other = builtin_exemplar(name, &b).unwrap();
            let seeded = matches!(name, "bricks" | "noise");
            assert_eq!(img != other, seeded, "{name}");
            assert_eq!(
                img,
                builtin_exemplar(name, &a).unwrap(),
                "{name} is deterministic"
            );
        }
    }

    #[test]
    fn bricks_have_mortar_rows_and_brick_colour() {
        let img = builtin_exemplar("bricks", &ExemplarOptions::default()).unwrap();
        // Rows 0, 8, 16, ... are mortar (8-pixel brick rows at size 64, cells 4):
        // light grey. Row 4 is mostly brick: red dominates.
        let row_mean = |y: u32| {
            let mut m = [0.0f32; 3];
            for x in 0..img.width {
                for (c, v) in img.pixel(x, y).iter().enumerate() {
                    m[c] += v / img.width as f32;
                }
            }
            m
        };
        let mortar = row_mean(8);
        assert!(
            mortar[0] > 0.6 && (mortar[0] - mortar[2]).abs() < 0.15,
            "{mortar:?}"
        );
        let brick = row_mean(4);
        assert!(
            brick[0] > 1.5 * brick[2] && brick[0] < mortar[0],
            "{brick:?}"
        );
        // Running bond: the vertical mortar joints of rows 0 and 1 are offset.
        let joint_cols = |y: u32| {
            (0..img.width)
                .filter(|&x| img.pixel(x, y)[2] > 0.5)
                .collect::<Vec<_>>()
        };
        let (r0, r1) = (joint_cols(4), joint_cols(12));
        assert!(!r0.is_empty() && !r1.is_empty());
        assert!(r0.iter().all(|x| !r1.contains(x)), "{r0:?} {r1:?}");
    }

    #[test]
    fn bad_names_and_options_list_what_is_allowed() {
        let e = builtin_exemplar("marble", &ExemplarOptions::default())
            .unwrap_err()
            .to_string();
        for (n, _) in BUILTIN_EXEMPLARS {
            assert!(e.contains(n), "{e}");
        }
        let e = builtin_exemplar(
            "checker",
            &ExemplarOptions {
                size: 4,
                ..Default::default()
            },
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("8..=2048"), "{e}");
        let e = builtin_exemplar(
            "checker",
            &ExemplarOptions {
                cells: 0,
                ..Default::default()
            },
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("1..=16"), "{e}");
    }

    #[test]
    fn options_deserialize_with_defaults_and_reject_unknown_keys() {
        let o: ExemplarOptions = toml::from_str("size = 128").unwrap();
        assert_eq!(
            o,
            ExemplarOptions {
                size: 128,
                ..Default::default()
            }
        );
        assert!(toml::from_str::<ExemplarOptions>("colour = 1").is_err());
    }

    #[test]
    fn builtin_heights_match_the_colour_layout() {
        let opts = ExemplarOptions::default();
        for (name, _) in BUILTIN_EXEMPLARS {
            let h = builtin_height(name, &opts).unwrap();
            assert_eq!((h.width, h.height, h.channels), (64, 64, 1), "{name}");
            assert!(h.data.iter().all(|v| (0.0..=1.0).contains(v)), "{name}");
            let (lo, hi) = h
                .data
                .iter()
                .fold((1.0f32, 0.0f32), |(a, b), &v| (a.min(v), b.max(v)));
            assert!(hi - lo > 0.3, "{name}: height range {lo}..{hi} is flat");
        }
        // Bricks: mortar rows (y = 8) low, brick rows (y = 4) high.
        let h = builtin_height("bricks", &opts).unwrap();
        let row_mean = |y: u32| (0..64).map(|x| h.pixel(x, y)[0]).sum::<f32>() / 64.0;
        assert!(
            row_mean(8) < 0.2 && row_mean(4) > 0.5,
            "{} {}",
            row_mean(8),
            row_mean(4)
        );
        assert!(
            builtin_height("plaid", &opts)
                .unwrap_err()
                .to_string()
                .contains("bricks")
        );
    }

    #[test]
    fn size_check_reports_need() {
        let img = Image::new(16, 20, 3);
        assert!(check_exemplar_size(&img, "x", "patch", 16).is_ok());
        let e = check_exemplar_size(&img, "ex.png", "patch", 32)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("ex.png") && e.contains("16x20") && e.contains("32x32"),
            "{e}"
        );
    }
}
