//! Seam refinement of a pixel source map (an extension; the image analogue
//! of `jump_surface`'s `refine = "seams"`): a few passes of iterated
//! conditional modes over the pixels next to a seam, in the spirit of
//! texture optimisation (Kwatra et al. 2005) restricted to coherent
//! candidates.
//!
//! A seam is where two 4-neighbours' sources do not continue each other
//! (`src(n) − src(p) ≠ n − p`). A visited pixel `p` may take the
//! continuation of any of its 8 neighbours `n`, `src(n) − (n − p)`, and
//! keeps the one whose exemplar window best matches the current output
//! around `p` (sum of squared colour differences over the
//! `(2·radius + 1)²` window, the centre left out). It keeps its own source
//! on ties, so its error never grows. A pass visits the pixels in raster
//! order; the next pass visits those within `radius` of a pixel that moved.
//! Sequential, so the result does not depend on the thread count.

use super::map::TexelCoord;
use super::sources::SourceMap;
use crate::image::Image;
use crate::progress::Progress;

/// Passes of `jump_image`'s `refine = "seams"`: most pixels that move do
/// so in the first (planar benchmark, brick: 6 157, 5 194, 2 626 of
/// 65 536).
pub const SEAM_REFINE_PASSES: u32 = 3;

/// Window radius of `jump_image`'s `refine = "seams"`: 5 × 5 windows, as
/// the matched choice's.
pub const SEAM_REFINE_RADIUS: u32 = 2;

/// Halvings of `jump_image`'s `refine = "seams"` ([`refine_seams_pyramid`]):
/// one coarser level before the full-size passes. Planar benchmark, seeds
/// 1–3, five photos, ratio to the peer: 0 → 1 took the gate's failing
/// cells from 10 to 7 of 15 (brick coherence 1.47 → 1.23 × at seed 1,
/// stones p90 1.04 → 0.92 ×, water p90 at seed 2 1.12 → 1.05 ×) at about
/// the same time; 2 were worse than 1 (brick p90 1.41 ×, planks 1.86 ×).
/// Without the donor's parity a moved block could land a pixel off its
/// neighbours: planks p90 2.18 ×.
pub const SEAM_REFINE_LEVELS: u32 = 1;

/// What [`refine_seams`] did.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct SeamRefineReport {
    /// Pixels visited per pass.
    pub visited: Vec<usize>,
    /// Pixels that took another source, per pass.
    pub moved: Vec<usize>,
}

/// Refines `sources` in place over at most `passes` passes with windows of
/// `radius` pixels around each visited pixel. `toroidal`: the exemplar
/// tiles (continuations wrap); otherwise continuations outside it are not
/// candidates. `progress` advances by one per row and pass.
pub fn refine_seams(
    sources: &mut SourceMap,
    exemplar: &Image,
    toroidal: bool,
    passes: u32,
    radius: u32,
    progress: &Progress,
) -> SeamRefineReport {
    progress.set_length(u64::from(passes) * u64::from(sources.height));
    let (w, h) = (sources.width as i64, sources.height as i64);
    let (ew, eh) = (exemplar.width as i64, exemplar.height as i64);
    let c = (exemplar.channels as usize).min(4);
    let colour = |t: TexelCoord| -> [f32; 4] {
        let mut out = [0.0; 4];
        let s = (t.y as usize * ew as usize + t.x as usize) * exemplar.channels as usize;
        out[..c].copy_from_slice(&exemplar.data[s..s + c]);
        out
    };
    // The exemplar address `t + d`, if it exists.
    let shifted = |t: TexelCoord, dx: i64, dy: i64| -> Option<TexelCoord> {
        let (x, y) = (t.x as i64 + dx, t.y as i64 + dy);
        if toroidal {
            Some(TexelCoord {
                x: x.rem_euclid(ew) as u32,
                y: y.rem_euclid(eh) as u32,
            })
        } else {
            (x >= 0 && y >= 0 && x < ew && y < eh).then_some(TexelCoord {
                x: x as u32,
                y: y as u32,
            })
        }
    };
    let at = |x: i64, y: i64| (y * w + x) as usize;
    let src = &mut sources.texels;
    // Seams: pixels whose right or lower neighbour does not continue them.
    let mut visit = vec![false; (w * h) as usize];
    for y in 0..h {
        for x in 0..w {
            let p = src[at(x, y)];
            for (dx, dy) in [(1, 0), (0, 1)] {
                let (nx, ny) = (x + dx, y + dy);
                if nx < w && ny < h && shifted(p, dx, dy) != Some(src[at(nx, ny)]) {
                    visit[at(x, y)] = true;
                    visit[at(nx, ny)] = true;
                }
            }
        }
    }
    let r = radius as i64;
    let mut report = SeamRefineReport::default();
    let mut cands: Vec<TexelCoord> = Vec::with_capacity(9);
    for _ in 0..passes {
        let mut next = vec![false; (w * h) as usize];
        let (mut visited, mut moved) = (0, 0);
        for y in 0..h {
            progress.inc(1);
            for x in 0..w {
                if !visit[at(x, y)] {
                    continue;
                }
                visited += 1;
                let here = src[at(x, y)];
                cands.clear();
                cands.push(here);
                for (dx, dy) in [
                    (-1, -1),
                    (0, -1),
                    (1, -1),
                    (-1, 0),
                    (1, 0),
                    (-1, 1),
                    (0, 1),
                    (1, 1),
                ] {
                    let (nx, ny) = (x + dx, y + dy);
                    if nx < 0 || ny < 0 || nx >= w || ny >= h {
                        continue;
                    }
                    if let Some(cand) = shifted(src[at(nx, ny)], -dx, -dy)
                        && !cands.contains(&cand)
                    {
                        cands.push(cand);
                    }
                }
                if cands.len() == 1 {
                    continue;
                }
                let cost = |cand: TexelCoord, bound: f32| -> f32 {
                    let mut e = 0.0;
                    for dy in -r..=r {
                        for dx in -r..=r {
                            let (qx, qy) = (x + dx, y + dy);
                            if (dx == 0 && dy == 0) || qx < 0 || qy < 0 || qx >= w || qy >= h {
                                continue;
                            }
                            let Some(e_at) = shifted(cand, dx, dy) else {
                                continue;
                            };
                            let (a, b) = (colour(e_at), colour(src[at(qx, qy)]));
                            e += (0..c).map(|i| (a[i] - b[i]) * (a[i] - b[i])).sum::<f32>();
                            if e > bound {
                                return e;
                            }
                        }
                    }
                    e
                };
                let mut best = (cost(here, f32::INFINITY), here);
                for &cand in &cands[1..] {
                    let e = cost(cand, best.0);
                    if e < best.0 {
                        best = (e, cand);
                    }
                }
                if best.1 != here {
                    src[at(x, y)] = best.1;
                    moved += 1;
                    for qy in (y - r).max(0)..=(y + r).min(h - 1) {
                        for qx in (x - r).max(0)..=(x + r).min(w - 1) {
                            next[at(qx, qy)] = true;
                        }
                    }
                }
            }
        }
        report.visited.push(visited);
        report.moved.push(moved);
        visit = next;
        if moved == 0 {
            break;
        }
    }
    report
}

/// The exemplar halved by 2 × 2 box averaging (odd sizes drop their last
/// row or column; at least 1 × 1).
fn halve(ex: &Image) -> Image {
    let (w, h, c) = ((ex.width / 2).max(1), (ex.height / 2).max(1), ex.channels);
    let mut out = Image::new(w, h, c);
    for y in 0..h {
        for x in 0..w {
            for k in 0..c as usize {
                let mut sum = 0.0;
                for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                    let (sx, sy) = (
                        (2 * x + dx).min(ex.width - 1),
                        (2 * y + dy).min(ex.height - 1),
                    );
                    sum += ex.pixel(sx, sy)[k];
                }
                out.pixel_mut(x, y)[k] = sum / 4.0;
            }
        }
    }
    out
}

/// [`refine_seams`] coarse to fine over `levels` halvings (an extension,
/// in the spirit of multi-resolution texture optimisation): the source map
/// is halved (each 2 × 2 block takes its top-left pixel's source, halved)
/// and refined against the 2 × 2 box-averaged exemplar, where a window of
/// the same radius sees twice the structure; a coarse pixel that moved
/// sets its block's sources to the continuation of the coarse neighbour it
/// took (its source doubled, plus the donor block's parity, plus the
/// pixel's place in the block: fine lines stay continuous); then the finer
/// level is refined as before. `levels = 0` is [`refine_seams`]; outputs or
/// exemplars too small to halve (under 8 or 16 pixels) stop the descent.
/// Returns the finest level's report.
pub fn refine_seams_pyramid(
    sources: &mut SourceMap,
    exemplar: &Image,
    toroidal: bool,
    passes: u32,
    radius: u32,
    levels: u32,
    progress: &Progress,
) -> SeamRefineReport {
    if levels == 0
        || sources.width < 8
        || sources.height < 8
        || exemplar.width < 16
        || exemplar.height < 16
    {
        return refine_seams(sources, exemplar, toroidal, passes, radius, progress);
    }
    let coarse_ex = halve(exemplar);
    let (cw, ch) = (sources.width / 2, sources.height / 2);
    let half = |t: TexelCoord| TexelCoord {
        x: (t.x / 2).min(coarse_ex.width - 1),
        y: (t.y / 2).min(coarse_ex.height - 1),
    };
    let texels: Vec<TexelCoord> = (0..cw * ch)
        .map(|i| {
            let (x, y) = (i % cw, i / cw);
            half(sources.texels[(2 * y * sources.width + 2 * x) as usize])
        })
        .collect();
    let before = texels.clone();
    let mut coarse = SourceMap {
        width: cw,
        height: ch,
        exemplar_width: coarse_ex.width,
        exemplar_height: coarse_ex.height,
        texels,
    };
    refine_seams_pyramid(
        &mut coarse,
        &coarse_ex,
        toroidal,
        passes,
        radius,
        levels - 1,
        progress,
    );
    let (ew, eh) = (exemplar.width, exemplar.height);
    let original = sources.texels.clone();
    // The parity (source minus twice its halving) of the fine block whose
    // coarse pixel `n` continues to `t` at `p`: the moved block takes its
    // donor's sub-pixel phase, so fine lines stay continuous.
    let (cwi, chi) = (cw as i64, ch as i64);
    let (cew, ceh) = (coarse_ex.width as i64, coarse_ex.height as i64);
    let parity = |x: i64, y: i64, t: TexelCoord| -> (u32, u32) {
        for dy in -1i64..=1 {
            for dx in -1i64..=1 {
                let (nx, ny) = (x + dx, y + dy);
                if (dx, dy) == (0, 0) || nx < 0 || ny < 0 || nx >= cwi || ny >= chi {
                    continue;
                }
                let c = coarse.texels[(ny * cwi + nx) as usize];
                let (mut cx, mut cy) = (c.x as i64 - dx, c.y as i64 - dy);
                if toroidal {
                    cx = cx.rem_euclid(cew);
                    cy = cy.rem_euclid(ceh);
                }
                if (cx, cy) == (t.x as i64, t.y as i64) {
                    let f = original[((2 * ny) * i64::from(sources.width) + 2 * nx) as usize];
                    return (f.x & 1, f.y & 1);
                }
            }
        }
        (0, 0)
    };
    for y in 0..ch {
        for x in 0..cw {
            let i = (y * cw + x) as usize;
            if coarse.texels[i] == before[i] {
                continue;
            }
            let t = coarse.texels[i];
            let (px, py) = parity(x as i64, y as i64, t);
            for dy in 0..2 {
                for dx in 0..2 {
                    let (fx, fy) = (2 * x + dx, 2 * y + dy);
                    let (sx, sy) = (2 * t.x + dx + px, 2 * t.y + dy + py);
                    let (sx, sy) = if toroidal {
                        (sx % ew, sy % eh)
                    } else {
                        (sx.min(ew - 1), sy.min(eh - 1))
                    };
                    sources.texels[(fy * sources.width + fx) as usize] =
                        TexelCoord { x: sx, y: sy };
                }
            }
        }
    }
    refine_seams(sources, exemplar, toroidal, passes, radius, progress)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 32² exemplar of smooth, position-dependent colour (every window
    /// unique).
    fn exemplar() -> Image {
        let mut img = Image::new(32, 32, 3);
        for y in 0..32u32 {
            for x in 0..32u32 {
                let (fx, fy) = (x as f32 / 31.0, y as f32 / 31.0);
                img.pixel_mut(x, y).copy_from_slice(&[
                    fx,
                    fy,
                    0.5 + 0.5 * (6.0 * fx + 4.0 * fy).sin(),
                ]);
            }
        }
        img
    }

    /// The refinement's objective over every pixel: the squared colour
    /// differences between the exemplar window at each pixel's source and
    /// the output around it (5 × 5, centre left out).
    fn window_error(s: &SourceMap, ex: &Image) -> f32 {
        let (w, h) = (s.width as i64, s.height as i64);
        let mut e = 0.0;
        for y in 0..h {
            for x in 0..w {
                let p = s.texels[(y * w + x) as usize];
                for dy in -2i64..=2 {
                    for dx in -2i64..=2 {
                        let (qx, qy) = (x + dx, y + dy);
                        let (cx, cy) = (p.x as i64 + dx, p.y as i64 + dy);
                        if (dx, dy) == (0, 0)
                            || qx < 0
                            || qy < 0
                            || qx >= w
                            || qy >= h
                            || cx < 0
                            || cy < 0
                            || cx >= ex.width as i64
                            || cy >= ex.height as i64
                        {
                            continue;
                        }
                        let q = s.texels[(qy * w + qx) as usize];
                        let (a, b) = (ex.pixel(cx as u32, cy as u32), ex.pixel(q.x, q.y));
                        e += (0..3).map(|i| (a[i] - b[i]) * (a[i] - b[i])).sum::<f32>();
                    }
                }
            }
        }
        e
    }

    #[test]
    fn seam_pixels_take_a_neighbours_continuation_and_the_window_error_falls() {
        let ex = exemplar();
        // A 16² output: the left half copies from (2, 2), the right half
        // from (12, 9), so a vertical seam runs down the middle.
        let (w, h) = (16u32, 16u32);
        let origin = |x: u32| if x < 8 { (2, 2) } else { (12 - 8, 9) };
        let texels: Vec<TexelCoord> = (0..w * h)
            .map(|i| {
                let (x, y) = (i % w, i / w);
                let (ox, oy) = origin(x);
                TexelCoord {
                    x: ox + x,
                    y: oy + y,
                }
            })
            .collect();
        let mut s = SourceMap {
            width: w,
            height: h,
            exemplar_width: 32,
            exemplar_height: 32,
            texels,
        };
        let before = window_error(&s, &ex);
        let report = refine_seams(&mut s, &ex, false, 3, 2, &Progress::hidden());
        let after = window_error(&s, &ex);
        assert!(report.visited[0] > 0 && report.moved[0] > 0, "{report:?}");
        assert!(after < before, "window error {before} -> {after}");
        // Every source still continues one of the two patches.
        for (i, t) in s.texels.iter().enumerate() {
            let (x, y) = (i as u32 % w, i as u32 / w);
            let from_left = (t.x as i64 - x as i64, t.y as i64 - y as i64) == (2, 2);
            let from_right = (t.x as i64 - x as i64, t.y as i64 - y as i64) == (4, 9);
            assert!(from_left || from_right, "pixel ({x}, {y}) took {t:?}");
        }
        // Nothing to refine in one patch.
        let mut whole = s.clone();
        whole.texels = (0..w * h)
            .map(|i| TexelCoord {
                x: 2 + i % w,
                y: 2 + i / w,
            })
            .collect();
        let r = refine_seams(&mut whole, &ex, false, 3, 2, &Progress::hidden());
        assert_eq!(r.visited, vec![0]);
    }

    #[test]
    fn the_pyramid_keeps_every_source_in_the_exemplar_and_lowers_the_window_error() {
        let ex = exemplar();
        // A 32² output of four quadrants copied from different places.
        let (w, h) = (32u32, 32u32);
        let origin = |x: u32, y: u32| match (x < 16, y < 16) {
            (true, true) => (1, 2),
            (false, true) => (9, 3),
            (true, false) => (12, 11),
            (false, false) => (3, 14),
        };
        let texels: Vec<TexelCoord> = (0..w * h)
            .map(|i| {
                let (x, y) = (i % w, i / w);
                let (ox, oy) = origin(x, y);
                TexelCoord {
                    x: (ox + x % 16).min(31),
                    y: (oy + y % 16).min(31),
                }
            })
            .collect();
        let s0 = SourceMap {
            width: w,
            height: h,
            exemplar_width: 32,
            exemplar_height: 32,
            texels,
        };
        // No halving: exactly the single-scale refinement.
        let (mut a, mut b) = (s0.clone(), s0.clone());
        let ra = refine_seams(&mut a, &ex, false, 3, 2, &Progress::hidden());
        let rb = refine_seams_pyramid(&mut b, &ex, false, 3, 2, 0, &Progress::hidden());
        assert_eq!((a.texels.clone(), ra), (b.texels, rb));
        // One halving: valid sources, and no worse than before.
        let mut c = s0.clone();
        refine_seams_pyramid(&mut c, &ex, false, 3, 2, 1, &Progress::hidden());
        assert!(c.texels.iter().all(|t| t.x < 32 && t.y < 32));
        let (before, after) = (window_error(&s0, &ex), window_error(&c, &ex));
        assert!(after < before, "window error {before} -> {after}");
    }
}
