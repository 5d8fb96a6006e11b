//! Patch-based image synthesis with a jump map (Zelinka & Garland 2004, §7.1).
//!
//! The output is cut into regular `P × P` patches, synthesized in Hilbert
//! order over the patch grid. For each patch a selection table is built from
//! every already-synthesized output pixel `q` bordering the patch (§6.6): each
//! jump at `q`'s source address, destination `d` and weight `w`, suggests the
//! address `d + (c − q)` for the patch centre `c`, and is entered with weight
//! `w` if it is valid, that is if the whole patch then lies inside the jump
//! map's source region (always, when toroidal). One uniform random number over
//! the table's total weight picks the centre address; destinations suggested
//! by several neighbours are proportionally more likely, which is the
//! probabilistic matching of §6.6. Every pixel of the patch then copies the
//! exemplar pixel at the same offset from the centre address.
//!
//! Each patch takes a jump: the patch size plays the role the jump frequency
//! plays in the pixel algorithm. When no neighbour suggests a valid
//! destination (the first patch, or all suggestions invalid), the patch
//! continues a neighbour's address if that is valid, else it starts at a
//! uniformly random valid address.

use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64Mcg;

use super::order::HilbertIter;
use super::synth_pixel::validate_common;
use super::{Boundary, JumpMap, JumpMapError, SourceMap, SynthesisOutput, TexelCoord};
use crate::image::Image;
use crate::progress::Progress;

/// Parameters of patch-based synthesis (§7.1).
#[derive(Clone, Debug, PartialEq)]
pub struct PatchSynthesisSettings {
    /// Output width in pixels. Range `1..=32768`.
    pub width: u32,
    /// Output height in pixels. Range `1..=32768`.
    pub height: u32,
    /// Patch side as a fraction of the smaller side of the jump map's source
    /// region; the paper uses one-fifth to one-half, large enough to hold the
    /// largest texture features. The side is at least 2 pixels. Unit:
    /// fraction. Default 0.3. Range `(0, 1]`.
    pub patch_fraction: f32,
    /// Seed of the synthesis RNG. Default 0.
    pub seed: u64,
}

impl Default for PatchSynthesisSettings {
    fn default() -> Self {
        Self {
            width: 256,
            height: 256,
            patch_fraction: 0.3,
            seed: 0,
        }
    }
}

impl PatchSynthesisSettings {
    /// Checks every parameter against its documented range.
    ///
    /// # Errors
    /// [`JumpMapError::InvalidSetting`] naming the first bad parameter.
    pub fn validate(&self) -> Result<(), JumpMapError> {
        validate_common(self.width, self.height, 0.5, 0.0)?;
        let f = self.patch_fraction;
        if !(f.is_finite() && f > 0.0 && f <= 1.0) {
            return Err(JumpMapError::InvalidSetting {
                name: "patch_fraction",
                value: format!("{f:?}"),
                expected: "(0, 1]",
            });
        }
        Ok(())
    }

    /// The patch side in pixels for `map`.
    pub fn patch_side(&self, map: &JumpMap) -> u32 {
        let r = map.sources();
        let side = r.width().min(r.height());
        ((self.patch_fraction * side as f32).round() as u32).clamp(2.min(side), side)
    }
}

/// Where patch centres may map to along one axis: `[lo, hi]` for a source
/// interval `[s0, s1)` and patch side `p` whose centre is `p / 2` from its start.
#[inline]
fn centre_range(s0: u32, s1: u32, p: u32) -> (i64, i64) {
    (
        s0 as i64 + (p / 2) as i64,
        s1 as i64 - p as i64 + (p / 2) as i64,
    )
}

/// Synthesizes the source map of a `settings.width × settings.height` image
/// from `map` alone with the patch-based algorithm (§7.1).
///
/// # Errors
/// [`JumpMapError::InvalidSetting`] for a bad setting.
pub fn synthesize_patch_sources(
    map: &JumpMap,
    settings: &PatchSynthesisSettings,
) -> Result<SourceMap, JumpMapError> {
    synthesize_patch_sources_with_progress(map, settings, &Progress::hidden())
}

/// [`synthesize_patch_sources`], advancing `progress` by one step per patch
/// (its length set to the patch count).
///
/// # Errors
/// As [`synthesize_patch_sources`].
pub fn synthesize_patch_sources_with_progress(
    map: &JumpMap,
    settings: &PatchSynthesisSettings,
    progress: &Progress,
) -> Result<SourceMap, JumpMapError> {
    settings.validate()?;
    let _span = tracing::info_span!(
        "jump_map_synthesize_patches",
        w = settings.width,
        h = settings.height
    )
    .entered();
    let (w, h) = (settings.width, settings.height);
    let p = settings.patch_side(map);
    let region = map.sources();
    let toroidal = map.boundary() == Boundary::Toroidal;
    let (ew, eh) = (map.width() as i64, map.height() as i64);
    let (xlo, xhi) = centre_range(region.x0, region.x1, p);
    let (ylo, yhi) = centre_range(region.y0, region.y1, p);
    // Maps a proposed centre address to a valid one, or None.
    let valid = |x: i64, y: i64| -> Option<(i64, i64)> {
        if toroidal {
            Some((x.rem_euclid(ew), y.rem_euclid(eh)))
        } else {
            (x >= xlo && x <= xhi && y >= ylo && y <= yhi).then_some((x, y))
        }
    };
    let mut grid: Vec<Option<TexelCoord>> = vec![None; w as usize * h as usize];
    let mut rng = Pcg64Mcg::seed_from_u64(settings.seed);
    let mut table: Vec<((i64, i64), f64)> = Vec::new();
    let mut border: Vec<(u32, u32)> = Vec::new();
    let (gw, gh) = (w.div_ceil(p), h.div_ceil(p));
    progress.set_length(u64::from(gw) * u64::from(gh));
    for (gx, gy) in HilbertIter::new(gw, gh) {
        progress.inc(1);
        let (x0, y0) = (gx * p, gy * p);
        let (x1, y1) = ((x0 + p).min(w), (y0 + p).min(h));
        let (cx, cy) = ((x0 + p / 2) as i64, (y0 + p / 2) as i64);
        border.clear();
        if x0 > 0 {
            border.extend((y0..y1).map(|y| (x0 - 1, y)));
        }
        if x1 < w {
            border.extend((y0..y1).map(|y| (x1, y)));
        }
        if y0 > 0 {
            border.extend((x0..x1).map(|x| (x, y0 - 1)));
        }
        if y1 < h {
            border.extend((x0..x1).map(|x| (x, y1)));
        }
        table.clear();
        let mut continuation = None;
        for &(qx, qy) in &border {
            let Some(a) = grid[(qy * w + qx) as usize] else {
                continue;
            };
            let (ox, oy) = (cx - qx as i64, cy - qy as i64);
            for j in map.jumps_at(a.x, a.y) {
                if let Some(c) = valid(j.to.x as i64 + ox, j.to.y as i64 + oy) {
                    table.push((c, j.weight as f64));
                }
            }
            if continuation.is_none() {
                continuation = valid(a.x as i64 + ox, a.y as i64 + oy);
            }
        }
        let total: f64 = table.iter().map(|e| e.1).sum();
        let centre = if total > 0.0 {
            let r = rng.random::<f64>() * total;
            let mut cum = 0.0;
            let mut pick = table[table.len() - 1].0;
            for &(c, wt) in &table {
                cum += wt;
                if r < cum {
                    pick = c;
                    break;
                }
            }
            pick
        } else if let Some(c) = continuation {
            c
        } else if toroidal {
            (rng.random_range(0..ew), rng.random_range(0..eh))
        } else {
            (rng.random_range(xlo..=xhi), rng.random_range(ylo..=yhi))
        };
        for y in y0..y1 {
            for x in x0..x1 {
                let mut ax = centre.0 + x as i64 - cx;
                let mut ay = centre.1 + y as i64 - cy;
                if toroidal {
                    ax = ax.rem_euclid(ew);
                    ay = ay.rem_euclid(eh);
                }
                grid[(y * w + x) as usize] = Some(TexelCoord::new(ax as u32, ay as u32));
            }
        }
    }
    Ok(SourceMap {
        width: w,
        height: h,
        exemplar_width: map.width(),
        exemplar_height: map.height(),
        texels: grid.into_iter().map(|t| t.unwrap_or_default()).collect(),
    })
}

/// Patch-based synthesis (§7.1): the source map from
/// [`synthesize_patch_sources`] and the image gathered through it.
///
/// # Errors
/// [`JumpMapError::InvalidSetting`], or [`JumpMapError::ExemplarMismatch`]
/// when `exemplar` is not the size `map` was built for.
pub fn synthesize_patches(
    exemplar: &Image,
    map: &JumpMap,
    settings: &PatchSynthesisSettings,
) -> Result<SynthesisOutput, JumpMapError> {
    synthesize_patches_with_progress(exemplar, map, settings, &Progress::hidden())
}

/// [`synthesize_patches`], reporting to `progress` as
/// [`synthesize_patch_sources_with_progress`] does.
///
/// # Errors
/// As [`synthesize_patches`].
pub fn synthesize_patches_with_progress(
    exemplar: &Image,
    map: &JumpMap,
    settings: &PatchSynthesisSettings,
    progress: &Progress,
) -> Result<SynthesisOutput, JumpMapError> {
    if exemplar.width != map.width() || exemplar.height != map.height() {
        return Err(JumpMapError::ExemplarMismatch {
            map_width: map.width(),
            map_height: map.height(),
            width: exemplar.width,
            height: exemplar.height,
        });
    }
    let sources = synthesize_patch_sources_with_progress(map, settings, progress)?;
    let image = sources.gather(exemplar)?;
    Ok(SynthesisOutput { image, sources })
}
