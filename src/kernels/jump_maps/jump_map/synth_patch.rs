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
//! uniformly random valid address. That is [`PatchSeams::Straight`].
//!
//! The default, [`PatchSeams::Cut`], is an extension: image quilting
//! (Efros & Freeman 2001) with the jump map as its candidate source.
//! Patches overlap their left and upper neighbours (raster order), the
//! jump map's suggestions from the overlap are scored by the colour
//! difference there, and the patch meets its neighbours along the
//! minimum-error paths through the overlap instead of a straight edge. On
//! the planar benchmark (256² from the 128² photos) this removes the grid
//! of straight seams: coherence p90 0.53–1.00 → 0.43–0.75 × the peer's and
//! completeness at or below the peer's on every shared texture (ARCHITECTURE.md,
//! "Jump-map patches without straight seams").

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
    /// How neighbouring patches meet. Default [`PatchSeams::Cut`].
    pub seams: PatchSeams,
}

/// How neighbouring patches of [`synthesize_patches`] meet.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum PatchSeams {
    /// The paper (§7.1): patches tile the output edge to edge, each
    /// centred where a jump from its border suggests, one drawn by weight.
    Straight,
    /// An extension (image quilting, Efros & Freeman 2001): patches overlap
    /// their left and upper neighbours by [`OVERLAP_DIVISOR`]ths of their
    /// side; among the centres the jump map suggests from the overlap (and
    /// [`RANDOM_CANDIDATES`] random ones; never the overlap's own
    /// continuation, which would copy the exemplar whole), those whose
    /// colour difference over the overlap is within [`CUT_TOLERANCE`] of
    /// the least, or below [`SEAM_STEPS`] of the exemplar's pixel steps,
    /// are acceptable; the one whose source has been copied least wins, and
    /// the patch meets its neighbours along the minimum-error paths through
    /// the overlap.
    #[default]
    Cut,
}

/// A patch overlaps its neighbours by its side over this (Efros & Freeman
/// 2001 use a sixth).
pub const OVERLAP_DIVISOR: u32 = 6;

/// Candidates within this fraction above the least overlap error are
/// acceptable (Efros & Freeman 2001 draw among those, with 0.1).
pub const CUT_TOLERANCE: f64 = 0.1;

/// Uniformly random valid centres added to the jump map's candidates of
/// every patch, so a patch can also start anew.
pub const RANDOM_CANDIDATES: usize = 16;

/// A candidate is also acceptable when its overlap error per pixel is at
/// most this many times the exemplar's mean squared step between adjacent
/// pixels ([`neighbour_step_error`]): a seam about as visible as the
/// texture's own pixel steps. Among acceptable candidates the least copied
/// source wins, which spreads the result over the exemplar. Measured on the
/// planar benchmark: 1.0 left brick's completeness 1.05 × the peer's, 2.0
/// raised planks' coherence p90 to 1.14 × the peer's; 1.5 meets both.
pub const SEAM_STEPS: f64 = 1.5;

impl Default for PatchSynthesisSettings {
    fn default() -> Self {
        Self {
            width: 256,
            height: 256,
            patch_fraction: 0.3,
            seed: 0,
            seams: PatchSeams::default(),
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

/// The valid patch centres of a jump map for patch side `p`: any address
/// when toroidal (wrapped), else those whose whole patch lies in the
/// source region.
struct Centres {
    toroidal: bool,
    size: (i64, i64),
    x: (i64, i64),
    y: (i64, i64),
}

impl Centres {
    fn of(map: &JumpMap, p: u32) -> Self {
        let region = map.sources();
        Self {
            toroidal: map.boundary() == Boundary::Toroidal,
            size: (map.width() as i64, map.height() as i64),
            x: centre_range(region.x0, region.x1, p),
            y: centre_range(region.y0, region.y1, p),
        }
    }

    /// `(x, y)` as a valid centre, or `None`.
    fn valid(&self, x: i64, y: i64) -> Option<(i64, i64)> {
        if self.toroidal {
            Some((x.rem_euclid(self.size.0), y.rem_euclid(self.size.1)))
        } else {
            (x >= self.x.0 && x <= self.x.1 && y >= self.y.0 && y <= self.y.1).then_some((x, y))
        }
    }

    /// The exemplar address `(dx, dy)` from `centre` (wrapped when
    /// toroidal; inside the source region for a valid centre otherwise).
    fn address(&self, centre: (i64, i64), dx: i64, dy: i64) -> (i64, i64) {
        let (x, y) = (centre.0 + dx, centre.1 + dy);
        if self.toroidal {
            (x.rem_euclid(self.size.0), y.rem_euclid(self.size.1))
        } else {
            (x, y)
        }
    }

    /// The source map of a filled `grid` of `settings`' size.
    fn source_map(
        &self,
        settings: &PatchSynthesisSettings,
        grid: Vec<Option<TexelCoord>>,
    ) -> SourceMap {
        SourceMap {
            width: settings.width,
            height: settings.height,
            exemplar_width: self.size.0 as u32,
            exemplar_height: self.size.1 as u32,
            texels: grid.into_iter().map(|t| t.unwrap_or_default()).collect(),
        }
    }

    /// A uniformly random valid centre.
    fn random(&self, rng: &mut Pcg64Mcg) -> (i64, i64) {
        if self.toroidal {
            (
                rng.random_range(0..self.size.0),
                rng.random_range(0..self.size.1),
            )
        } else {
            (
                rng.random_range(self.x.0..=self.x.1),
                rng.random_range(self.y.0..=self.y.1),
            )
        }
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
    let centres = Centres::of(map, p);
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
                if let Some(c) = centres.valid(j.to.x as i64 + ox, j.to.y as i64 + oy) {
                    table.push((c, j.weight as f64));
                }
            }
            if continuation.is_none() {
                continuation = centres.valid(a.x as i64 + ox, a.y as i64 + oy);
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
        } else {
            centres.random(&mut rng)
        };
        for y in y0..y1 {
            for x in x0..x1 {
                let (ax, ay) = centres.address(centre, x as i64 - cx, y as i64 - cy);
                grid[(y * w + x) as usize] = Some(TexelCoord::new(ax as u32, ay as u32));
            }
        }
    }
    Ok(centres.source_map(settings, grid))
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
    let sources = match settings.seams {
        PatchSeams::Straight => synthesize_patch_sources_with_progress(map, settings, progress)?,
        PatchSeams::Cut => quilt_sources(exemplar, map, settings, progress)?,
    };
    let image = sources.gather(exemplar)?;
    Ok(SynthesisOutput { image, sources })
}

/// The source map of [`PatchSeams::Cut`]: overlapping patches in raster
/// order, chosen by their overlap error and cut along its minimum-error
/// paths (module docs of [`PatchSeams::Cut`]).
fn quilt_sources(
    exemplar: &Image,
    map: &JumpMap,
    settings: &PatchSynthesisSettings,
    progress: &Progress,
) -> Result<SourceMap, JumpMapError> {
    settings.validate()?;
    let _span = tracing::info_span!(
        "jump_map_quilt_patches",
        w = settings.width,
        h = settings.height
    )
    .entered();
    let (w, h) = (settings.width as usize, settings.height as usize);
    let p = settings.patch_side(map) as usize;
    let o = (p / OVERLAP_DIVISOR as usize)
        .max(1)
        .min(p.saturating_sub(1));
    let step = (p - o).max(1);
    let centres = Centres::of(map, p as u32);
    let toroidal = centres.toroidal;
    let (ew, eh) = centres.size;
    let ch = exemplar.channels as usize;
    let colour = |(x, y): (i64, i64)| -> &[f32] {
        let i = (y as usize * exemplar.width as usize + x as usize) * ch;
        &exemplar.data[i..i + ch]
    };
    // Squared colour difference between what output pixel `q` holds and
    // what a patch centred at `c` would put there.
    let change = |(qx, qy): (usize, usize), a: TexelCoord, c: (i64, i64), (cx, cy): (i64, i64)| {
        let new = colour(centres.address(c, qx as i64 - cx, qy as i64 - cy));
        squared_difference(colour((a.x as i64, a.y as i64)), new)
    };
    let mut grid: Vec<Option<TexelCoord>> = vec![None; w * h];
    let mut rng = Pcg64Mcg::seed_from_u64(settings.seed);
    let starts = |n: usize| {
        (0..)
            .map(move |k| k * step)
            .take_while(move |&x| x < n.max(1))
    };
    let (gw, gh) = (starts(w).count(), starts(h).count());
    progress.set_length((gw * gh) as u64);
    let mut candidates: Vec<(i64, i64)> = Vec::new();
    let mut continuations: Vec<(i64, i64)> = Vec::new();
    let mut near: Vec<(i64, i64)> = Vec::new();
    let mut overlap: Vec<(usize, usize)> = Vec::new();
    let mut errors: Vec<f64> = Vec::new();
    let mut cost: Vec<f64> = Vec::new();
    let mut new_side: Vec<bool> = Vec::new();
    // Output pixels copied from each exemplar pixel so far, and its
    // summed-area table.
    let mut usage = vec![0u32; (ew * eh) as usize];
    let step_error = neighbour_step_error(exemplar);
    let mut sat: Vec<u64> = Vec::new();
    for y0 in starts(h) {
        for x0 in starts(w) {
            progress.inc(1);
            let (x1, y1) = ((x0 + p).min(w), (y0 + p).min(h));
            let (bw, bh) = (x1 - x0, y1 - y0);
            let (cx, cy) = ((x0 + p / 2) as i64, (y0 + p / 2) as i64);
            // The patch's pixels already synthesised: its overlap.
            overlap.clear();
            for y in y0..y1 {
                for x in x0..x1 {
                    if grid[y * w + x].is_some() {
                        overlap.push((x, y));
                    }
                }
            }
            // Candidate centres: the jumps from the overlap (every other
            // pixel of it), and a few random ones. Not the overlap's own
            // continuations: they match it exactly, so they would always
            // win and the result would be the exemplar copied whole, shifted
            // where a continuation leaves it (as the paper, every patch
            // jumps).
            candidates.clear();
            continuations.clear();
            for &(qx, qy) in overlap.iter().step_by(2) {
                let a = grid[qy * w + qx].expect("overlap pixels are set");
                let (ox, oy) = (cx - qx as i64, cy - qy as i64);
                continuations.push(centres.address((a.x as i64, a.y as i64), ox, oy));
                for j in map.jumps_at(a.x, a.y) {
                    if let Some(c) = centres.valid(j.to.x as i64 + ox, j.to.y as i64 + oy) {
                        candidates.push(c);
                    }
                }
            }
            for _ in 0..RANDOM_CANDIDATES {
                candidates.push(centres.random(&mut rng));
            }
            candidates.sort_unstable();
            candidates.dedup();
            continuations.sort_unstable();
            continuations.dedup();
            if candidates.len() > 1 {
                candidates.retain(|c| continuations.binary_search(c).is_err());
            }
            // Overlap error of each candidate: the squared colour difference
            // between what is there and what the candidate would put there.
            errors.clear();
            errors.extend(candidates.iter().map(|&c| {
                overlap
                    .iter()
                    .map(|&q| {
                        let a = grid[q.1 * w + q.0].expect("overlap pixels are set");
                        change(q, a, c, (cx, cy))
                    })
                    .sum::<f64>()
            }));
            let best = errors.iter().copied().fold(f64::INFINITY, f64::min);
            // Acceptable: within CUT_TOLERANCE of the best, or no more
            // visible than SEAM_STEPS ordinary steps between exemplar
            // pixels per overlap pixel.
            let bound =
                (best * (1.0 + CUT_TOLERANCE)).max(SEAM_STEPS * step_error * overlap.len() as f64);
            // Among the acceptable ones, the one whose source block has
            // been copied least so far (ties: the first from a random
            // start), so the result spreads over the whole exemplar.
            near.clear();
            near.extend(
                candidates
                    .iter()
                    .zip(&errors)
                    .filter(|&(_, &e)| e <= bound)
                    .map(|(&c, _)| c),
            );
            build_sat(&usage, ew as usize, eh as usize, &mut sat);
            let first = rng.random_range(0..near.len().max(1));
            let mut centre = near.get(first).copied().unwrap_or(candidates[0]);
            let mut least = u64::MAX;
            for k in 0..near.len() {
                let c = near[(first + k) % near.len()];
                let u = block_usage(&sat, ew as usize, eh as usize, c, p, toroidal);
                if u < least {
                    least = u;
                    centre = c;
                }
            }
            // Per-pixel overlap error of the chosen patch, and the side of
            // the minimum-error paths each pixel falls on.
            cost.clear();
            cost.resize(bw * bh, 0.0);
            for &(qx, qy) in &overlap {
                let a = grid[qy * w + qx].expect("overlap pixels are set");
                cost[(qy - y0) * bw + (qx - x0)] = change((qx, qy), a, centre, (cx, cy));
            }
            new_side.clear();
            new_side.resize(bw * bh, true);
            let ow = o.min(bw);
            let oh = o.min(bh);
            if x0 > 0 && ow > 0 {
                // A top-to-bottom path through the left overlap: pixels left
                // of it keep what is there.
                let path = min_error_path(&cost, bw, bh, ow, false);
                for (y, &cut) in path.iter().enumerate() {
                    for x in 0..cut {
                        new_side[y * bw + x] = false;
                    }
                }
            }
            if y0 > 0 && oh > 0 {
                // A left-to-right path through the upper overlap: pixels
                // above it keep what is there.
                let path = min_error_path(&cost, bw, bh, oh, true);
                for (x, &cut) in path.iter().enumerate() {
                    for y in 0..cut {
                        new_side[y * bw + x] = false;
                    }
                }
            }
            for y in y0..y1 {
                for x in x0..x1 {
                    let g = &mut grid[y * w + x];
                    if g.is_none() || new_side[(y - y0) * bw + (x - x0)] {
                        let (ax, ay) = centres.address(centre, x as i64 - cx, y as i64 - cy);
                        *g = Some(TexelCoord::new(ax as u32, ay as u32));
                        usage[ay as usize * ew as usize + ax as usize] += 1;
                    }
                }
            }
        }
    }
    Ok(centres.source_map(settings, grid))
}

/// Sum of squared differences of two colours.
#[inline]
fn squared_difference(a: &[f32], b: &[f32]) -> f64 {
    a.iter().zip(b).map(|(u, v)| f64::from(u - v).powi(2)).sum()
}

/// Mean squared colour difference between horizontally and vertically
/// adjacent exemplar pixels: the error of a seam as visible as an ordinary
/// step between two pixels of the exemplar.
fn neighbour_step_error(ex: &Image) -> f64 {
    let (w, h, c) = (ex.width as usize, ex.height as usize, ex.channels as usize);
    let px = |x: usize, y: usize| &ex.data[(y * w + x) * c..(y * w + x + 1) * c];
    let (mut sum, mut n) = (0.0f64, 0usize);
    for y in 0..h {
        for x in 0..w {
            if x + 1 < w {
                sum += squared_difference(px(x, y), px(x + 1, y));
                n += 1;
            }
            if y + 1 < h {
                sum += squared_difference(px(x, y), px(x, y + 1));
                n += 1;
            }
        }
    }
    sum / n.max(1) as f64
}

/// Summed-area table of `usage` (`w × h`): entry `(y + 1)·(w + 1) + x + 1`
/// is the sum over `[0, x] × [0, y]`.
fn build_sat(usage: &[u32], w: usize, h: usize, sat: &mut Vec<u64>) {
    sat.clear();
    sat.resize((w + 1) * (h + 1), 0);
    for y in 0..h {
        let mut row = 0u64;
        for x in 0..w {
            row += u64::from(usage[y * w + x]);
            sat[(y + 1) * (w + 1) + x + 1] = sat[y * (w + 1) + x + 1] + row;
        }
    }
}

/// Copies so far from the `p × p` source block centred (as the patches
/// are) at `c`; wrapped blocks of a toroidal map are summed piecewise.
fn block_usage(sat: &[u64], w: usize, h: usize, c: (i64, i64), p: usize, toroidal: bool) -> u64 {
    let rect = |x0: usize, y0: usize, x1: usize, y1: usize| -> u64 {
        sat[y1 * (w + 1) + x1] + sat[y0 * (w + 1) + x0]
            - sat[y0 * (w + 1) + x1]
            - sat[y1 * (w + 1) + x0]
    };
    let x0 = c.0 - (p / 2) as i64;
    let y0 = c.1 - (p / 2) as i64;
    if !toroidal {
        let cl = |v: i64, n: usize| v.clamp(0, n as i64) as usize;
        return rect(
            cl(x0, w),
            cl(y0, h),
            cl(x0 + p as i64, w),
            cl(y0 + p as i64, h),
        );
    }
    // Split each axis at the wrap.
    let spans = |start: i64, n: usize| -> Vec<(usize, usize)> {
        let s = start.rem_euclid(n as i64) as usize;
        let len = p.min(n);
        if s + len <= n {
            vec![(s, s + len)]
        } else {
            vec![(s, n), (0, s + len - n)]
        }
    };
    let mut total = 0;
    for &(xa, xb) in &spans(x0, w) {
        for &(ya, yb) in &spans(y0, h) {
            total += rect(xa, ya, xb, yb);
        }
    }
    total
}

/// The minimum-cost 8-connected path through the first `band` columns of
/// the `bw × bh` row-major `cost` block, top to bottom (or, `transposed`,
/// through its first `band` rows, left to right): per row (column), the
/// index of the path's pixel within the band (dynamic programming, ties to
/// the lower index).
fn min_error_path(cost: &[f64], bw: usize, bh: usize, band: usize, transposed: bool) -> Vec<usize> {
    let (len, at) = if transposed { (bw, bh) } else { (bh, bw) };
    let band = band.min(at);
    let c = |i: usize, k: usize| {
        if transposed {
            cost[k * bw + i]
        } else {
            cost[i * bw + k]
        }
    };
    let mut acc = vec![0.0f64; len * band];
    for (k, a) in acc.iter_mut().take(band).enumerate() {
        *a = c(0, k);
    }
    for i in 1..len {
        for k in 0..band {
            let lo = k.saturating_sub(1);
            let hi = (k + 1).min(band - 1);
            let prev = (lo..=hi)
                .map(|j| acc[(i - 1) * band + j])
                .fold(f64::INFINITY, f64::min);
            acc[i * band + k] = c(i, k) + prev;
        }
    }
    let mut path = vec![0usize; len];
    let last = &acc[(len - 1) * band..len * band];
    let mut k = (0..band)
        .min_by(|&a, &b| last[a].total_cmp(&last[b]))
        .unwrap_or(0);
    path[len - 1] = k;
    for i in (0..len - 1).rev() {
        let lo = k.saturating_sub(1);
        let hi = (k + 1).min(band - 1);
        k = (lo..=hi)
            .min_by(|&a, &b| acc[i * band + a].total_cmp(&acc[i * band + b]))
            .unwrap_or(k);
        path[i] = k;
    }
    path
}
