//! Controlled image synthesis (Zelinka & Garland 2004, §7.2): the pixel-based
//! algorithm run on the output image treated as a quad mesh, with a user
//! orientation field and scale field over the output.
//!
//! Each output pixel has an "up" direction (where the texture's up points, in
//! output pixel axes, y down) and a scale (exemplar pixels per output pixel,
//! the inter-pixel distance in texture space). Moving from pixel `q` to its
//! neighbour `p = q + e` moves the texture address by the edge offset of §6.3,
//! specialised to the plane: the endpoint up vectors are averaged and
//! renormalised to `u_e`, the right vector `r_e` is `u_e` turned a quarter
//! clockwise, the scales are averaged to `s_e`, and the offset is
//! `s_e · (e·r_e, −e·u_e)`. Addresses are therefore floating point, and jump
//! lists are read with the floating-point look-up of §6.4
//! ([`JumpMap::jumps_at_float`]). A jump lands on a "virtual source" as in §5;
//! the pixel gets that address plus the edge offset.
//!
//! Jump frequency: as §5.1, with the random range divided by `s²` at the
//! pixel, so a patch covers the same exemplar area whatever the scale.
//! Boundary avoidance (§5.2) applies to inset maps; an address that would
//! still leave the source region takes a forced jump to a valid destination
//! (§6.6), or a random address when none is valid.
//!
//! Filtering (§7.2: "a particular output pixel must be a filtered combination
//! of all the input pixels mapped into it"): an output pixel covers about
//! `s × s` exemplar pixels, so its colour is a trilinear sample of the
//! exemplar's Gaussian pyramid at level `log2 s` (bilinear within a level,
//! linear between levels; level 0 when `s <= 1`).

use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64Mcg;

use super::neighbourhoods::wrap_for;
use super::synth_pixel::{base_range, boundary_ramp, validate_common};
use super::{Boundary, FloatJump, JumpMap, JumpMapError, PixelOrder};
use crate::image::{Image, pyramid::gaussian_pyramid};
use crate::progress::Progress;

/// Largest scale a field may hold (exemplar pixels per output pixel).
pub const MAX_SCALE: f32 = 1024.0;

/// Orientation and scale per output pixel (§6.1, §7.2).
#[derive(Clone, Debug, PartialEq)]
pub struct ControlField {
    /// Output width in pixels.
    pub width: u32,
    /// Output height in pixels.
    pub height: u32,
    /// Per pixel, row-major: the unit direction, in output pixel axes (x
    /// right, y down), that the texture's up direction points to. `[0, -1]` is
    /// the ordinary upright texture. A zero vector means "undefined" (a
    /// singularity) and is treated as upright.
    pub up: Vec<[f32; 2]>,
    /// Per pixel, row-major: exemplar pixels per output pixel (> 0). 1 copies
    /// at the exemplar's resolution; 2 shows the texture at half size.
    pub scale: Vec<f32>,
}

impl ControlField {
    /// The same orientation and scale everywhere: the texture turned by
    /// `angle` radians clockwise (so up points to `(sin a, −cos a)`).
    pub fn uniform(width: u32, height: u32, angle: f32, scale: f32) -> Self {
        let n = width as usize * height as usize;
        let (s, c) = angle.sin_cos();
        Self {
            width,
            height,
            up: vec![[s, -c]; n],
            scale: vec![scale; n],
        }
    }

    /// Simulated perspective (Fig. 24, left): upright texture whose
    /// inter-pixel distance grows towards the top, as on a ground plane seen
    /// at a grazing angle: the inverse scale (texture magnification) varies
    /// linearly from `1 / scale_bottom` on the bottom row to `1 / scale_top`
    /// on the top row, as screen y varies linearly with inverse depth.
    pub fn perspective(width: u32, height: u32, scale_bottom: f32, scale_top: f32) -> Self {
        let mut f = Self::uniform(width, height, 0.0, 1.0);
        let (ib, it) = (1.0 / scale_bottom, 1.0 / scale_top);
        for y in 0..height {
            let t = if height > 1 {
                y as f32 / (height - 1) as f32
            } else {
                0.0
            };
            let s = 1.0 / (it + (ib - it) * t);
            f.scale[(y * width) as usize..][..width as usize].fill(s);
        }
        f
    }

    /// A radial field (Fig. 24, right): every pixel's up points toward the
    /// image centre, and the inter-pixel distance grows toward the centre,
    /// linearly in the distance from it, from `scale_edge` at the corners to
    /// `scale_centre` at the centre. The centre itself is a singularity.
    pub fn radial(width: u32, height: u32, scale_edge: f32, scale_centre: f32) -> Self {
        let mut f = Self::uniform(width, height, 0.0, 1.0);
        let (cx, cy) = ((width as f32 - 1.0) * 0.5, (height as f32 - 1.0) * 0.5);
        let rmax = (cx * cx + cy * cy).sqrt().max(1e-6);
        for y in 0..height {
            for x in 0..width {
                let i = (y * width + x) as usize;
                let (dx, dy) = (cx - x as f32, cy - y as f32);
                let r = (dx * dx + dy * dy).sqrt();
                f.up[i] = if r > 1e-6 {
                    [dx / r, dy / r]
                } else {
                    [0.0, 0.0]
                };
                f.scale[i] = scale_centre + (scale_edge - scale_centre) * (r / rmax);
            }
        }
        f
    }

    /// Checks sizes and values.
    ///
    /// # Errors
    /// [`JumpMapError::InvalidSetting`] for a non-finite up vector or a scale
    /// outside `(0, MAX_SCALE]`, or wrong array lengths.
    pub fn validate(&self) -> Result<(), JumpMapError> {
        let n = self.width as usize * self.height as usize;
        if self.up.len() != n || self.scale.len() != n {
            return Err(JumpMapError::InvalidSetting {
                name: "control_field",
                value: format!(
                    "{} up vectors and {} scales for {}x{} pixels",
                    self.up.len(),
                    self.scale.len(),
                    self.width,
                    self.height
                ),
                expected: "one up vector and one scale per output pixel",
            });
        }
        if let Some(s) = self
            .scale
            .iter()
            .find(|s| !(s.is_finite() && **s > 0.0 && **s <= MAX_SCALE))
        {
            return Err(JumpMapError::InvalidSetting {
                name: "control_field.scale",
                value: format!("{s}"),
                expected: "(0, 1024] exemplar pixels per output pixel",
            });
        }
        if let Some(u) = self
            .up
            .iter()
            .find(|u| !(u[0].is_finite() && u[1].is_finite()))
        {
            return Err(JumpMapError::InvalidSetting {
                name: "control_field.up",
                value: format!("{u:?}"),
                expected: "finite vectors",
            });
        }
        Ok(())
    }

    #[inline]
    fn up_at(&self, i: usize) -> [f32; 2] {
        let u = self.up[i];
        let l = (u[0] * u[0] + u[1] * u[1]).sqrt();
        if l > 1e-6 {
            [u[0] / l, u[1] / l]
        } else {
            [0.0, -1.0]
        }
    }

    /// Texture-space offset for the output step from pixel `q` to its
    /// 4-neighbour `p = q + e` (§6.3 in the plane).
    #[inline]
    pub fn edge_offset(&self, q: (u32, u32), e: (i32, i32)) -> [f32; 2] {
        let iq = (q.1 * self.width + q.0) as usize;
        let p = (
            (q.0 as i64 + e.0 as i64) as u32,
            (q.1 as i64 + e.1 as i64) as u32,
        );
        let ip = (p.1 * self.width + p.0) as usize;
        let (a, b) = (self.up_at(iq), self.up_at(ip));
        let mut u = [a[0] + b[0], a[1] + b[1]];
        let l = (u[0] * u[0] + u[1] * u[1]).sqrt();
        u = if l > 1e-6 { [u[0] / l, u[1] / l] } else { a };
        let r = [-u[1], u[0]];
        let s = 0.5 * (self.scale[iq] + self.scale[ip]);
        let (ex, ey) = (e.0 as f32, e.1 as f32);
        [s * (ex * r[0] + ey * r[1]), -s * (ex * u[0] + ey * u[1])]
    }
}

/// Parameters of controlled synthesis (§7.2).
#[derive(Clone, Debug, PartialEq)]
pub struct ControlledSynthesisSettings {
    /// Pixel order (§5.3). Default [`PixelOrder::Hilbert`].
    pub order: PixelOrder,
    /// Desired patch size as a fraction of the exemplar's side, as
    /// [`super::PixelSynthesisSettings::patch_fraction`]. Default 0.5. Range `(0, 16]`.
    pub patch_fraction: f32,
    /// Boundary-avoidance band (§5.2), as
    /// [`super::PixelSynthesisSettings::boundary_fraction`]. Default 0.2. Range `[0, 0.5]`.
    pub boundary_fraction: f32,
    /// Seed of the synthesis RNG. Default 0.
    pub seed: u64,
}

impl Default for ControlledSynthesisSettings {
    fn default() -> Self {
        Self {
            order: PixelOrder::Hilbert,
            patch_fraction: 0.5,
            boundary_fraction: 0.2,
            seed: 0,
        }
    }
}

/// What controlled synthesis returns.
#[derive(Clone, Debug, PartialEq)]
pub struct ControlledOutput {
    /// The filtered output image (the exemplar's channel count).
    pub image: Image,
    /// Per output pixel, row-major, its exemplar address in pixels (pixel
    /// centres at integers).
    pub sources: Vec<[f32; 2]>,
}

impl ControlledOutput {
    /// Patch visualisation as [`super::SourceMap::patch_visualisation`]: red =
    /// address x / (exemplar width − 1), green = y / (exemplar height − 1).
    pub fn patch_visualisation(&self, exemplar_width: u32, exemplar_height: u32) -> Image {
        let sx = 1.0 / (exemplar_width.max(2) - 1) as f32;
        let sy = 1.0 / (exemplar_height.max(2) - 1) as f32;
        let mut out = Image::new(self.image.width, self.image.height, 3);
        for (o, a) in out.data.chunks_exact_mut(3).zip(&self.sources) {
            o[0] = a[0] * sx;
            o[1] = a[1] * sy;
        }
        out
    }
}

/// Synthesizes an image of the field's size from `exemplar` and its `map`,
/// following `field` (§7.2).
///
/// # Errors
/// [`JumpMapError::InvalidSetting`] for bad settings or field values,
/// [`JumpMapError::ExemplarMismatch`] when `exemplar` is not the size `map`
/// was built for.
pub fn synthesize_controlled(
    exemplar: &Image,
    map: &JumpMap,
    field: &ControlField,
    settings: &ControlledSynthesisSettings,
) -> Result<ControlledOutput, JumpMapError> {
    synthesize_controlled_with_progress(exemplar, map, field, settings, &Progress::hidden())
}

/// [`synthesize_controlled`], advancing `progress` (its length set to the
/// pixel count) every 16,384 pixels.
///
/// # Errors
/// As [`synthesize_controlled`].
pub fn synthesize_controlled_with_progress(
    exemplar: &Image,
    map: &JumpMap,
    field: &ControlField,
    settings: &ControlledSynthesisSettings,
    progress: &Progress,
) -> Result<ControlledOutput, JumpMapError> {
    validate_common(
        field.width,
        field.height,
        settings.patch_fraction,
        settings.boundary_fraction,
    )?;
    field.validate()?;
    if exemplar.width != map.width() || exemplar.height != map.height() {
        return Err(JumpMapError::ExemplarMismatch {
            map_width: map.width(),
            map_height: map.height(),
            width: exemplar.width,
            height: exemplar.height,
        });
    }
    let _span = tracing::info_span!(
        "jump_map_synthesize_controlled",
        w = field.width,
        h = field.height
    )
    .entered();
    let (w, h) = (field.width, field.height);
    let region = map.sources();
    let toroidal = map.boundary() == Boundary::Toroidal;
    let (ew, eh) = (map.width() as f32, map.height() as f32);
    let r0 = base_range(region, settings.patch_fraction);
    let (lo_x, hi_x) = (region.x0 as f32, (region.x1 - 1) as f32);
    let (lo_y, hi_y) = (region.y0 as f32, (region.y1 - 1) as f32);
    let dest = map.destinations();
    let fix = |a: [f32; 2]| -> Option<[f32; 2]> {
        if toroidal {
            Some([a[0].rem_euclid(ew), a[1].rem_euclid(eh)])
        } else {
            (a[0] >= lo_x && a[0] <= hi_x && a[1] >= lo_y && a[1] <= hi_y).then_some(a)
        }
    };
    let mut src: Vec<Option<[f32; 2]>> = vec![None; w as usize * h as usize];
    let mut rng = Pcg64Mcg::seed_from_u64(settings.seed);
    let mut jumps: Vec<FloatJump> = Vec::new();
    let mut valid: Vec<([f32; 2], f32)> = Vec::new();
    progress.set_length(u64::from(w) * u64::from(h));
    let mut done = 0u64;
    for (x, y) in settings.order.iter(w, h) {
        done += 1;
        if done.is_multiple_of(1 << 14) {
            progress.inc(1 << 14);
        }
        let mut cands = [((0u32, 0u32), (0i32, 0i32)); 4];
        let mut n = 0;
        for (dx, dy) in [(-1i32, 0i32), (1, 0), (0, -1), (0, 1)] {
            let (qx, qy) = (x as i64 + dx as i64, y as i64 + dy as i64);
            if qx < 0 || qy < 0 || qx >= w as i64 || qy >= h as i64 {
                continue;
            }
            if src[(qy as u32 * w + qx as u32) as usize].is_some() {
                cands[n] = ((qx as u32, qy as u32), (-dx, -dy));
                n += 1;
            }
        }
        let addr = if n == 0 {
            [
                rng.random_range(dest.x0..dest.x1) as f32,
                rng.random_range(dest.y0..dest.y1) as f32,
            ]
        } else {
            let (q, e) = cands[rng.random_range(0..n)];
            let a = src[(q.1 * w + q.0) as usize].expect("synthesized neighbour");
            let o = field.edge_offset(q, e);
            map.jumps_at_float(a[0], a[1], &mut jumps);
            let sum: f32 = jumps.iter().map(|j| j.weight).sum();
            let s = field.scale[(y * w + x) as usize];
            let ramp = if toroidal {
                1.0
            } else {
                boundary_ramp(region, settings.boundary_fraction, a[0], a[1])
            };
            let range =
                sum as f64 + ramp as f64 * ((r0 / (s as f64 * s as f64)) - sum as f64).max(0.0);
            let r = rng.random::<f64>() * range;
            let mut virt = a;
            let mut cum = 0.0f64;
            for j in &jumps {
                cum += j.weight as f64;
                if r < cum {
                    virt = j.to;
                    break;
                }
            }
            match fix([virt[0] + o[0], virt[1] + o[1]]) {
                Some(b) => b,
                None => {
                    // Forced jump among the valid destinations (§6.6).
                    valid.clear();
                    valid.extend(jumps.iter().filter_map(|j| {
                        fix([j.to[0] + o[0], j.to[1] + o[1]]).map(|b| (b, j.weight))
                    }));
                    let total: f32 = valid.iter().map(|v| v.1).sum();
                    if total > 0.0 {
                        let r = rng.random::<f32>() * total;
                        let mut cum = 0.0;
                        let mut pick = valid[valid.len() - 1].0;
                        for &(b, wt) in &valid {
                            cum += wt;
                            if r < cum {
                                pick = b;
                                break;
                            }
                        }
                        pick
                    } else {
                        [
                            rng.random_range(dest.x0..dest.x1) as f32,
                            rng.random_range(dest.y0..dest.y1) as f32,
                        ]
                    }
                }
            }
        };
        src[(y * w + x) as usize] = Some(addr);
    }
    let sources: Vec<[f32; 2]> = src.into_iter().map(|a| a.unwrap_or([0.0, 0.0])).collect();

    // Filtered colours: trilinear in the exemplar's Gaussian pyramid.
    let max_scale = field.scale.iter().copied().fold(1.0f32, f32::max);
    let levels = (max_scale.log2().ceil().max(0.0) as usize + 1).min(16);
    let wrap = wrap_for(map.boundary());
    let pyramid = gaussian_pyramid(exemplar, levels, wrap);
    let c = exemplar.channels as usize;
    let mut image = Image::new(w, h, exemplar.channels);
    let mut a0 = vec![0.0f32; c];
    let mut a1 = vec![0.0f32; c];
    for (i, (o, a)) in image.data.chunks_exact_mut(c).zip(&sources).enumerate() {
        let lambda = field.scale[i].max(1.0).log2().min((levels - 1) as f32);
        let l0 = lambda.floor() as usize;
        let l1 = (l0 + 1).min(levels - 1);
        let t = lambda - l0 as f32;
        let sample = |l: usize, out: &mut [f32]| {
            let k = (1u32 << l) as f32;
            pyramid[l].sample_bilinear(a[0] / k + 0.5, a[1] / k + 0.5, wrap, out);
        };
        sample(l0, &mut a0);
        if t > 0.0 && l1 != l0 {
            sample(l1, &mut a1);
            for ((o, x), y) in o.iter_mut().zip(&a0).zip(&a1) {
                *o = x + (y - x) * t;
            }
        } else {
            o.copy_from_slice(&a0);
        }
    }
    Ok(ControlledOutput { image, sources })
}
