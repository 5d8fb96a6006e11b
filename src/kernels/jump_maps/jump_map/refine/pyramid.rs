//! [`refine_seams`] coarse to fine: the source map and the exemplar halved,
//! refined, and the moves carried down to the finer level.

use super::super::map::TexelCoord;
use super::super::sources::SourceMap;
use super::{SeamRefineReport, refine_seams};
use crate::image::Image;
use crate::progress::Progress;

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
