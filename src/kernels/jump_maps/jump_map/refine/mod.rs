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
use crate::mesh::{union_find_join as join, union_find_root as find};
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

/// The exemplar address `t + d` in an `ew × eh` exemplar (wrapped when
/// `toroidal`), if it exists.
#[inline]
fn shifted_texel(
    t: TexelCoord,
    (dx, dy): (i64, i64),
    (ew, eh): (i64, i64),
    toroidal: bool,
) -> Option<TexelCoord> {
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
}

/// The copied regions of the `w × h` source map `src`: every pixel joined
/// to its right and lower neighbours where the neighbour's exemplar pixel
/// continues its own (the next one over, wrapped when `toroidal`), as a
/// union–find forest in `parent` with each root's pixel count in `area`
/// (both cleared and refilled). A root is its region's first pixel in
/// raster order.
fn copied_regions(
    src: &[TexelCoord],
    (w, h): (i64, i64),
    (ew, eh): (i64, i64),
    toroidal: bool,
    parent: &mut Vec<u32>,
    area: &mut Vec<u32>,
) {
    let n = (w * h) as usize;
    parent.clear();
    parent.extend(0..n as u32);
    area.clear();
    area.resize(n, 1);
    for y in 0..h {
        for x in 0..w {
            let i = (y * w + x) as usize;
            for (dx, dy) in [(1i64, 0i64), (0, 1)] {
                let (nx, ny) = (x + dx, y + dy);
                if nx < w && ny < h {
                    let j = (ny * w + nx) as usize;
                    if shifted_texel(src[i], (dx, dy), (ew, eh), toroidal) == Some(src[j]) {
                        join(parent, area, i as u32, j as u32);
                    }
                }
            }
        }
    }
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
    let shifted = |t: TexelCoord, dx: i64, dy: i64| shifted_texel(t, (dx, dy), (ew, eh), toroidal);
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
    // Copied regions of at least this area count as large in the
    // verbatim-copy measure: a move may not make one by joining regions.
    let large = ((ew * eh) as usize).div_ceil(3);
    let n = (w * h) as usize;
    // Regions, tracked through a pass: union-find over nodes with areas; a
    // pixel that moves gets a fresh node (its old region loses one pixel;
    // splits are not tracked, so areas only overestimate).
    let mut parent: Vec<u32> = Vec::with_capacity(2 * n);
    let mut area: Vec<u32> = Vec::with_capacity(2 * n);
    let mut node: Vec<u32> = Vec::with_capacity(n);
    let mut joined: Vec<u32> = Vec::with_capacity(4);
    let mut cover = vec![0u16; (ew * eh) as usize];
    let texel = |t: TexelCoord| (t.y as i64 * ew + t.x as i64) as usize;
    for _ in 0..passes {
        copied_regions(src, (w, h), (ew, eh), toroidal, &mut parent, &mut area);
        node.clear();
        node.extend(0..n as u32);
        // Per exemplar pixel, how many pixels of large regions copy it.
        cover.iter_mut().for_each(|c| *c = 0);
        for i in 0..n {
            if area[find(&mut parent, i as u32) as usize] as usize >= large {
                let t = src[i];
                cover[texel(t)] += 1;
            }
        }
        let mut next = vec![false; n];
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
                // The regions a candidate joins: the 4-neighbours that
                // continue it.
                let joins = |cand: TexelCoord,
                             parent: &mut Vec<u32>,
                             joined: &mut Vec<u32>,
                             node: &[u32],
                             src: &[TexelCoord]| {
                    joined.clear();
                    for (dx, dy) in [(1, 0), (-1, 0), (0, 1), (0, -1)] {
                        let (nx, ny) = (x + dx, y + dy);
                        if nx >= 0
                            && ny >= 0
                            && nx < w
                            && ny < h
                            && shifted(cand, dx, dy) == Some(src[at(nx, ny)])
                        {
                            let root = find(parent, node[at(nx, ny)]);
                            if !joined.contains(&root) {
                                joined.push(root);
                            }
                        }
                    }
                };
                let mut best = (cost(here, f32::INFINITY), here);
                for &cand in &cands[1..] {
                    let e = cost(cand, best.0);
                    if e < best.0 {
                        joins(cand, &mut parent, &mut joined, &node, src);
                        let total: usize = joined.iter().map(|&g| area[g as usize] as usize).sum();
                        // No join into a large region, no region grown to
                        // large, and no pixel added to a large region where
                        // two large regions copy its source already.
                        let allowed = total + 1 < large
                            || (joined.len() == 1 && total >= large && cover[texel(cand)] < 2);
                        if allowed {
                            best = (e, cand);
                        }
                    }
                }
                if best.1 != here {
                    src[at(x, y)] = best.1;
                    moved += 1;
                    // Track the move: out of its region, into the ones it
                    // continues.
                    let old = find(&mut parent, node[at(x, y)]);
                    if area[old as usize] as usize >= large {
                        cover[texel(here)] = cover[texel(here)].saturating_sub(1);
                    }
                    area[old as usize] = area[old as usize].saturating_sub(1);
                    let fresh = parent.len() as u32;
                    parent.push(fresh);
                    area.push(1);
                    node[at(x, y)] = fresh;
                    joins(best.1, &mut parent, &mut joined, &node, src);
                    let mut root = fresh;
                    for &g in &joined {
                        root = join(&mut parent, &mut area, root, g);
                    }
                    if area[root as usize] as usize >= large {
                        cover[texel(best.1)] += 1;
                    }
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

mod align;
mod pyramid;

pub use align::{
    ALIGN_DEPTH, ALIGN_MIN_PIXELS, ALIGN_SCREEN_DEPTH, ALIGN_SCREEN_KEEP, ALIGN_SEARCH_PAIRS,
    ALIGN_SHIFT, ALIGN_SWEEPS, AlignReport, align_regions,
};
pub use pyramid::refine_seams_pyramid;

#[cfg(test)]
mod tests;
