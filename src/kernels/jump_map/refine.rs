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
}
