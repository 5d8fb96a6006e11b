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

/// Largest shift, in exemplar pixels along each axis, [`align_regions`]
/// tries for a region. Planar benchmark (planks p90 over seeds 1–3, ratio
/// to the peer, one pass before the pixel passes): 3 → 1.01–1.13, 6 →
/// 0.98–1.08 (and 0.82–0.99 with a pass after them too).
pub const ALIGN_SHIFT: i64 = 6;

/// How deep, in pixels, [`align_regions`] compares each border pair's
/// continuations into the other side. Planks p90 (as above, one pass
/// before): 1 pixel 1.04–1.21, 3 pixels 0.99–1.13, 5 pixels 0.98–1.13.
pub const ALIGN_DEPTH: usize = 5;

/// Depth of [`align_regions`]' screening cost: every shift is first
/// compared this many pixels deep, and only the [`ALIGN_SCREEN_KEEP`]
/// cheapest are compared [`ALIGN_DEPTH`] pixels deep.
pub const ALIGN_SCREEN_DEPTH: usize = 2;

/// Shifts that pass [`align_regions`]' screening.
pub const ALIGN_SCREEN_KEEP: usize = 8;

/// Border pairs [`align_regions`] compares the shifts of a region on (spread
/// along its border; the winner is checked on the whole border).
pub const ALIGN_SEARCH_PAIRS: usize = 48;

/// The outside half of a border pair in [`align_regions`].
struct OutsideHalf {
    cq: [f32; 4],
    ahead: [Option<[f32; 4]>; ALIGN_DEPTH],
    behind: [Option<[f32; 4]>; ALIGN_DEPTH],
}

/// Sweeps of `jump_image`'s `refine = "aligned_seams"` per alignment.
pub const ALIGN_SWEEPS: u32 = 4;

/// Regions smaller than this many pixels are left to the pixel passes.
pub const ALIGN_MIN_PIXELS: usize = 16;

/// What [`align_regions`] did.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct AlignReport {
    /// Coherent regions (4-connected pixels whose sources continue each
    /// other) of at least [`ALIGN_MIN_PIXELS`].
    pub regions: usize,
    /// Regions shifted, per sweep.
    pub shifted: Vec<usize>,
}

/// Aligns whole coherent regions of a source map with their neighbours
/// (an extension): a region is a 4-connected set of pixels whose sources
/// continue each other, i.e. one copied piece of the exemplar. Each region
/// (in order of its first pixel) tries every shift of its sources by up to
/// [`ALIGN_SHIFT`] pixels along each axis and keeps the one with the least
/// seam cost along its border, `Σ_k ‖E[s(p) + (k + 1)(q − p)] −
/// E[s(q) + k(q − p)]‖² + ‖E[s(q) − (k + 1)(q − p)] − E[s(p) − k(q − p)]‖²`
/// over 4-adjacent pairs `p` inside, `q` outside and `k <` [`ALIGN_DEPTH`]
/// (each side's continuation into the other against what that side shows;
/// a continuation outside an inset exemplar counts the plain colour
/// difference of `p` and `q`). Shifts that take a source out of an inset
/// exemplar are not tried. A region keeps its sources unless a shift is
/// strictly cheaper, so the border cost never grows. Up to `sweeps`
/// sweeps, until none moves. Sequential and deterministic. `progress`
/// advances by one per region and sweep.
///
/// The pixel passes of [`refine_seams`] move one pixel at a time, so a
/// copied piece that landed a row or two off its neighbours (board edges
/// of planks, mortar courses) becomes a staircase of single-pixel
/// choices; moving the whole piece removes the offset where it arises.
pub fn align_regions(
    sources: &mut SourceMap,
    exemplar: &Image,
    toroidal: bool,
    sweeps: u32,
    progress: &Progress,
) -> AlignReport {
    let (w, h) = (sources.width as i64, sources.height as i64);
    let (ew, eh) = (exemplar.width as i64, exemplar.height as i64);
    let c = (exemplar.channels as usize).min(4);
    let n = (w * h) as usize;
    // Every shift but none, row by row.
    let shifts: Vec<(i64, i64)> = (-ALIGN_SHIFT..=ALIGN_SHIFT)
        .flat_map(|dy| (-ALIGN_SHIFT..=ALIGN_SHIFT).map(move |dx| (dx, dy)))
        .filter(|&d| d != (0, 0))
        .collect();
    let shift_index = |d: (i64, i64)| -> usize {
        ((d.1 + ALIGN_SHIFT) * (2 * ALIGN_SHIFT + 1) + d.0 + ALIGN_SHIFT) as usize
    };
    let mut nearest_first = shifts.clone();
    nearest_first.sort_by_key(|&(dx, dy)| (dx * dx + dy * dy, shift_index((dx, dy))));
    let mut order: Vec<(i64, i64)> = Vec::with_capacity(shifts.len());
    let mut tried = vec![false; shifts.len() + 1];
    let mut kept: Vec<(f32, usize, (i64, i64))> = Vec::with_capacity(ALIGN_SCREEN_KEEP + 1);
    let mut report = AlignReport::default();
    if n == 0 || ew == 0 || eh == 0 {
        return report;
    }
    // The exemplar's colours padded to four channels: fixed-size
    // differences in the shift search.
    let padded: Vec<[f32; 4]> = exemplar
        .data
        .chunks_exact(exemplar.channels.max(1) as usize)
        .map(|px| {
            let mut out = [0.0; 4];
            out[..c].copy_from_slice(&px[..c]);
            out
        })
        .collect();
    let colour = |x: i64, y: i64| -> [f32; 4] { padded[(y * ew + x) as usize] };
    // The exemplar address `t + d` (wrapped when toroidal), if it exists.
    let shifted = |tx: i64, ty: i64| -> Option<(i64, i64)> {
        if toroidal {
            Some((tx.rem_euclid(ew), ty.rem_euclid(eh)))
        } else {
            (tx >= 0 && ty >= 0 && tx < ew && ty < eh).then_some((tx, ty))
        }
    };
    let src = &mut sources.texels;
    let diff = |a: [f32; 4], b: [f32; 4]| -> f32 {
        (a[0] - b[0]) * (a[0] - b[0])
            + (a[1] - b[1]) * (a[1] - b[1])
            + (a[2] - b[2]) * (a[2] - b[2])
            + (a[3] - b[3]) * (a[3] - b[3])
    };
    // A border pair's outside half, which no shift of the region changes:
    // q's colour, and the colours k pixels on (ahead) and k + 1 back
    // (behind) from q's source, `None` outside an inset exemplar.
    let outside = |sq: TexelCoord, step: (i64, i64)| -> OutsideHalf {
        let (qx, qy) = (sq.x as i64, sq.y as i64);
        let mut half = OutsideHalf {
            cq: colour(qx, qy),
            ahead: [None; ALIGN_DEPTH],
            behind: [None; ALIGN_DEPTH],
        };
        for k in 0..ALIGN_DEPTH {
            let k1 = k as i64;
            half.ahead[k] = shifted(qx + k1 * step.0, qy + k1 * step.1).map(|(x, y)| colour(x, y));
            half.behind[k] =
                shifted(qx - (k1 + 1) * step.0, qy - (k1 + 1) * step.1).map(|(x, y)| colour(x, y));
        }
        half
    };
    // The seam cost of one pair with `p`'s source moved by `d`: p's
    // continuation k + 1 pixels on against q's source k on, and the other
    // way round, k < depth; the plain colour difference where a
    // continuation leaves an inset exemplar.
    let pair_cost =
        |sp: TexelCoord, q: &OutsideHalf, d: (i64, i64), step: (i64, i64), depth: usize| -> f32 {
            let (px, py) = (sp.x as i64 + d.0, sp.y as i64 + d.1);
            let (px, py) = match shifted(px, py) {
                Some(t) => t,
                None => return f32::INFINITY,
            };
            let cp = colour(px, py);
            let mut total = 0.0;
            for k in 0..depth {
                let k1 = k as i64;
                let ahead = match (
                    shifted(px + (k1 + 1) * step.0, py + (k1 + 1) * step.1),
                    q.ahead[k],
                ) {
                    (Some((x, y)), Some(b)) => diff(colour(x, y), b),
                    _ => diff(cp, q.cq),
                };
                let behind = match (q.behind[k], shifted(px - k1 * step.0, py - k1 * step.1)) {
                    (Some(a), Some((u, v))) => diff(a, colour(u, v)),
                    _ => diff(cp, q.cq),
                };
                total += ahead + behind;
            }
            total
        };
    let mut border: Vec<(u32, u32, (i64, i64))> = Vec::new();
    let mut halves: Vec<(u32, (i64, i64), OutsideHalf)> = Vec::new();
    let mut near: Vec<u32> = Vec::new();
    // Copied regions of at least this area count as large in the
    // verbatim-copy measure (`kernels::metrics::quality`): a shift may not
    // make one by joining its region to its neighbours.
    let large = ((ew * eh) as usize).div_ceil(3);
    // An offset (source minus pixel) moved by `d`, wrapped when toroidal.
    let moved_by = |o: (i64, i64), d: (i64, i64)| -> (i64, i64) {
        let (ox, oy) = (o.0 + d.0, o.1 + d.1);
        if toroidal {
            (ox.rem_euclid(ew), oy.rem_euclid(eh))
        } else {
            (ox, oy)
        }
    };
    let offset_of = |i: usize, t: TexelCoord| -> (i64, i64) {
        let (x, y) = ((i as i64) % w, (i as i64) / w);
        moved_by((t.x as i64 - x, t.y as i64 - y), (0, 0))
    };
    let mut dirty = vec![true; n];
    let mut cover = vec![0u16; (ew * eh) as usize];
    for _ in 0..sweeps {
        let mut moved = 0;
        let mut next_dirty = vec![false; n];
        // Regions by union-find over the right and lower continuations,
        // numbered by their first pixel.
        let (mut parent, mut sizes) = (Vec::new(), Vec::new());
        copied_regions(src, (w, h), (ew, eh), toroidal, &mut parent, &mut sizes);
        let label: Vec<u32> = (0..n as u32).map(|i| find(&mut parent, i)).collect();
        drop((parent, sizes));
        // Pixels of each region, in raster order (counting sort by label).
        let mut start = vec![0u32; n + 1];
        for &l in &label {
            start[l as usize + 1] += 1;
        }
        for i in 0..n {
            start[i + 1] += start[i];
        }
        let mut fill = start.clone();
        let mut pixels = vec![0u32; n];
        for (i, &l) in label.iter().enumerate() {
            pixels[fill[l as usize] as usize] = i as u32;
            fill[l as usize] += 1;
        }
        drop(fill);
        let roots: Vec<u32> = (0..n as u32)
            .filter(|&r| (start[r as usize + 1] - start[r as usize]) as usize >= ALIGN_MIN_PIXELS)
            .collect();
        report.regions = report.regions.max(roots.len());
        progress.set_length(u64::from(sweeps) * roots.len() as u64);
        progress.set_position(report.shifted.len() as u64 * roots.len() as u64);
        // Per exemplar pixel, how many pixels of large regions copy it.
        cover.iter_mut().for_each(|c| *c = 0);
        for (i, &l) in label.iter().enumerate() {
            if (start[l as usize + 1] - start[l as usize]) as usize >= large {
                let t = src[i];
                cover[(t.y as i64 * ew + t.x as i64) as usize] += 1;
            }
        }
        // Per region (by label) its offset and the group it has joined by
        // a shift in this sweep (union-find over labels, with areas).
        let mut group: Vec<u32> = (0..n as u32).collect();
        let mut area: Vec<u32> = (0..n).map(|l| start[l + 1] - start[l]).collect();
        let mut offset: Vec<(i64, i64)> = vec![(0, 0); n];
        for l in 0..n {
            if start[l + 1] > start[l] {
                let i = pixels[start[l] as usize] as usize;
                offset[l] = offset_of(i, src[i]);
            }
        }
        for &root in &roots {
            progress.inc(1);
            let region = &pixels[start[root as usize] as usize..start[root as usize + 1] as usize];
            // The region's border pairs (inside, outside, step).
            border.clear();
            for &i in region {
                let (x, y) = (i as i64 % w, i as i64 / w);
                for (dx, dy) in [(1i64, 0i64), (-1, 0), (0, 1), (0, -1)] {
                    let (qx, qy) = (x + dx, y + dy);
                    if qx >= 0 && qy >= 0 && qx < w && qy < h {
                        let j = (qy * w + qx) as u32;
                        if label[j as usize] != root {
                            border.push((i, j, (dx, dy)));
                        }
                    }
                }
            }
            if border.is_empty() {
                continue;
            }
            // Only regions that moved, or border a region that moved, in
            // the previous sweep can find a cheaper shift.
            if !region.iter().any(|&i| dirty[i as usize])
                && !border.iter().any(|&(_, j, _)| dirty[j as usize])
            {
                continue;
            }
            // The groups of the regions across the border.
            near.clear();
            let own_group = find(&mut group, root);
            for &(_, j, _) in &border {
                let g = find(&mut group, label[j as usize]);
                if g != own_group && !near.contains(&g) {
                    near.push(g);
                }
            }
            // The search compares shifts on at most `ALIGN_SEARCH_PAIRS`
            // pairs spread along the border; the winner must then be
            // cheaper than staying on the whole border.
            let stride = border.len().div_ceil(ALIGN_SEARCH_PAIRS).max(1);
            halves.clear();
            halves.extend(
                border
                    .iter()
                    .step_by(stride)
                    .map(|&(i, j, step)| (i, step, outside(src[j as usize], step))),
            );
            // The cost on every `every`-th search pair, given up above `bound`.
            let cost_on = |every: usize, depth: usize, d: (i64, i64), bound: f32| -> f32 {
                let mut e = 0.0f32;
                for (i, step, q) in halves.iter().step_by(every) {
                    e += pair_cost(src[*i as usize], q, d, *step, depth);
                    if e > bound {
                        return e;
                    }
                }
                e
            };
            let whole_border = |d: (i64, i64)| -> f32 {
                let mut e = 0.0f32;
                for &(i, j, step) in &border {
                    e += pair_cost(
                        src[i as usize],
                        &outside(src[j as usize], step),
                        d,
                        step,
                        ALIGN_DEPTH,
                    );
                }
                e
            };
            let cost = |d: (i64, i64), bound: f32| cost_on(1, ALIGN_DEPTH, d, bound);
            let screen = |d: (i64, i64), bound: f32| cost_on(2, ALIGN_SCREEN_DEPTH, d, bound);
            // Shifts that keep every source of the region inside an inset
            // exemplar.
            let (mut lo, mut hi) = ((i64::MAX, i64::MAX), (i64::MIN, i64::MIN));
            for &i in region {
                let t = src[i as usize];
                lo = (lo.0.min(t.x as i64), lo.1.min(t.y as i64));
                hi = (hi.0.max(t.x as i64), hi.1.max(t.y as i64));
            }
            let mut best = (cost((0, 0), f32::INFINITY), (0i64, 0i64));
            let own = area[own_group as usize] as usize;
            // Shifts that join a neighbouring group first, then the rest
            // nearest first: a cheap shift found early bounds the others'
            // sums sooner. Ties go to the shift first in raster order, so
            // the order does not change the result.
            order.clear();
            kept.clear();
            tried.iter_mut().for_each(|t| *t = false);
            tried[shift_index((0, 0))] = true;
            for &g in &near {
                let (ox, oy) = offset[g as usize];
                let (rx, ry) = offset[root as usize];
                let mut d = (ox - rx, oy - ry);
                if toroidal {
                    // The nearest representative of the wrapped difference.
                    d.0 = (d.0 + ew / 2).rem_euclid(ew) - ew / 2;
                    d.1 = (d.1 + eh / 2).rem_euclid(eh) - eh / 2;
                }
                if d.0.abs() <= ALIGN_SHIFT && d.1.abs() <= ALIGN_SHIFT && !tried[shift_index(d)] {
                    tried[shift_index(d)] = true;
                    order.push(d);
                }
            }
            order.extend(nearest_first.iter().filter(|&&d| !tried[shift_index(d)]));
            for &(dx, dy) in &order {
                if !toroidal
                    && (lo.0 + dx < 0 || lo.1 + dy < 0 || hi.0 + dx >= ew || hi.1 + dy >= eh)
                {
                    continue;
                }
                let shifted_offset = moved_by(offset[root as usize], (dx, dy));
                let joined: usize = near
                    .iter()
                    .filter(|&&g| offset[g as usize] == shifted_offset)
                    .map(|&g| area[g as usize] as usize)
                    .sum();
                if joined > 0 && own + joined >= large {
                    continue;
                }
                // Screened on the shallow cost: the `ALIGN_SCREEN_KEEP`
                // cheapest (ties to the first in raster order) go on.
                let bound = if kept.len() == ALIGN_SCREEN_KEEP {
                    kept[ALIGN_SCREEN_KEEP - 1].0
                } else {
                    f32::INFINITY
                };
                let e = screen((dx, dy), bound);
                let key = (e, shift_index((dx, dy)));
                if e <= bound {
                    let at = kept.partition_point(|&(f, k, _)| (f, k) < key);
                    if at < ALIGN_SCREEN_KEEP {
                        kept.insert(at, (e, key.1, (dx, dy)));
                        kept.truncate(ALIGN_SCREEN_KEEP);
                    }
                }
            }
            for &(_, _, d) in &kept {
                let e = cost(d, best.0);
                if e < best.0
                    || (e == best.0 && best.1 != (0, 0) && shift_index(d) < shift_index(best.1))
                {
                    best = (e, d);
                }
            }
            if best.1 != (0, 0) && stride > 1 && whole_border(best.1) >= whole_border((0, 0)) {
                best.1 = (0, 0);
            }
            // A large region may not move its sources where two other large
            // regions copy the exemplar already (the verbatim measure's
            // repeats).
            if best.1 != (0, 0) && own >= large {
                let texel = |x: i64, y: i64| (y * ew + x) as usize;
                for &i in region {
                    let t = src[i as usize];
                    cover[texel(t.x as i64, t.y as i64)] -= 1;
                }
                let fits = region.iter().all(|&i| {
                    let t = src[i as usize];
                    shifted(t.x as i64 + best.1.0, t.y as i64 + best.1.1)
                        .is_some_and(|(x, y)| cover[texel(x, y)] < 2)
                });
                if !fits {
                    best.1 = (0, 0);
                }
                for &i in region {
                    let t = src[i as usize];
                    let (x, y) = shifted(t.x as i64 + best.1.0, t.y as i64 + best.1.1)
                        .unwrap_or((t.x as i64, t.y as i64));
                    cover[texel(x, y)] += 1;
                }
            }
            if best.1 != (0, 0) {
                moved += 1;
                for &i in region {
                    next_dirty[i as usize] = true;
                }
                let (dx, dy) = best.1;
                let new_offset = moved_by(offset[root as usize], (dx, dy));
                offset[root as usize] = new_offset;
                offset[own_group as usize] = new_offset;
                for &g in &near {
                    if offset[g as usize] == new_offset
                        && find(&mut group, own_group) != find(&mut group, g)
                    {
                        let lo = join(&mut group, &mut area, own_group, g);
                        offset[lo as usize] = new_offset;
                    }
                }
                for &i in region {
                    let t = src[i as usize];
                    if let Some((x, y)) = shifted(t.x as i64 + dx, t.y as i64 + dy) {
                        src[i as usize] = TexelCoord {
                            x: x as u32,
                            y: y as u32,
                        };
                    }
                }
            }
        }
        report.shifted.push(moved);
        dirty = next_dirty;
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

    /// A `size`² exemplar of horizontal boards: a dark line every 8 rows,
    /// grain varying along x and between boards.
    fn boards(size: u32) -> Image {
        let mut img = Image::new(size, size, 3);
        for y in 0..size {
            for x in 0..size {
                let line = if y % 8 == 0 { 0.1 } else { 0.6 };
                let grain = 0.2 * ((x as f32 * 0.37 + (y / 8) as f32 * 1.3).sin());
                img.pixel_mut(x, y)
                    .copy_from_slice(&[line + grain, line, 0.5 + 0.01 * y as f32]);
            }
        }
        img
    }

    /// A `w × h` output: the left half copies the exemplar from `(0, 8)`,
    /// the right half continues it but two rows down (a board edge off by
    /// two pixels at the seam).
    fn misaligned(w: u32, h: u32, ex: &Image) -> SourceMap {
        map_of(w, h, ex, |x, y| TexelCoord {
            x: x + 4,
            y: y + if x < w / 2 { 8 } else { 10 },
        })
    }

    /// A `w × h` source map over `ex` with `source(x, y)` at each pixel.
    fn map_of(w: u32, h: u32, ex: &Image, source: impl Fn(u32, u32) -> TexelCoord) -> SourceMap {
        SourceMap {
            width: w,
            height: h,
            exemplar_width: ex.width,
            exemplar_height: ex.height,
            texels: (0..w * h).map(|i| source(i % w, i / w)).collect(),
        }
    }

    #[test]
    fn a_misaligned_region_is_moved_to_continue_its_neighbour() {
        let ex = boards(64);
        let mut s = misaligned(32, 32, &ex);
        let report = align_regions(&mut s, &ex, false, ALIGN_SWEEPS, &Progress::hidden());
        assert_eq!(report.regions, 2, "{report:?}");
        assert!(report.shifted[0] >= 1, "{report:?}");
        // Every pair across the seam now continues: one copied piece.
        for y in 0..32usize {
            let (a, b) = (s.texels[y * 32 + 15], s.texels[y * 32 + 16]);
            assert_eq!((b.x, b.y), (a.x + 1, a.y), "row {y}");
        }
    }

    #[test]
    fn alignment_never_joins_a_copy_of_a_third_of_the_exemplar() {
        // The same two halves (512 pixels each) over a 36² exemplar: joined
        // they would copy 1 024 pixels, more than a third of its 1 296.
        let ex = boards(36);
        let mut s = misaligned(32, 16, &ex);
        let before = s.texels.clone();
        let report = align_regions(&mut s, &ex, false, ALIGN_SWEEPS, &Progress::hidden());
        assert_eq!(report.regions, 2, "{report:?}");
        let seam_continues = (0..16usize).all(|y| {
            let (a, b) = (s.texels[y * 32 + 15], s.texels[y * 32 + 16]);
            (b.x, b.y) == (a.x + 1, a.y)
        });
        assert!(!seam_continues, "the halves were joined: {report:?}");
        // Any shift it made still lowered the border cost, so the output
        // differs from the start only where a half moved as a whole.
        let moved: Vec<bool> = s.texels.iter().zip(&before).map(|(a, b)| a != b).collect();
        for half in [0usize, 16] {
            let m: Vec<bool> = (0..16)
                .flat_map(|y| (half..half + 16).map(move |x| y * 32 + x))
                .map(|i| moved[i])
                .collect();
            assert!(m.iter().all(|&v| v == m[0]), "a half moved in part");
        }
    }

    /// Copied regions of `s` (4-connected pixels whose sources continue
    /// each other), as their areas, largest first.
    fn region_areas(s: &SourceMap) -> Vec<usize> {
        let (w, h) = (s.width as usize, s.height as usize);
        let mut parent: Vec<u32> = (0..(w * h) as u32).collect();
        for y in 0..h {
            for x in 0..w {
                let i = y * w + x;
                for (j, dx, dy) in [(i + 1, 1, 0), (i + w, 0, 1)] {
                    if (dx == 1 && x + 1 == w) || (dy == 1 && y + 1 == h) {
                        continue;
                    }
                    let (a, b) = (s.texels[i], s.texels[j]);
                    if (b.x, b.y) == (a.x + dx, a.y + dy) {
                        let (ra, rb) = (find(&mut parent, i as u32), find(&mut parent, j as u32));
                        parent[ra.max(rb) as usize] = ra.min(rb);
                    }
                }
            }
        }
        let mut area = vec![0usize; w * h];
        for i in 0..w * h {
            area[find(&mut parent, i as u32) as usize] += 1;
        }
        area.retain(|&a| a > 0);
        area.sort_unstable_by(|a, b| b.cmp(a));
        area
    }

    /// Two pieces of 15 × `h` pixels copying one 36² exemplar at one
    /// offset, with a column of pixels from elsewhere between them: each
    /// column pixel's best candidate is the pieces' continuation (it matches
    /// both sides exactly), which joins them.
    fn split_by_a_column(h: u32, ex: &Image) -> SourceMap {
        map_of(31, h, ex, |x, y| {
            if x == 15 {
                TexelCoord {
                    x: 30,
                    y: (y * 7) % 30,
                }
            } else {
                TexelCoord { x: x + 2, y: y + 4 }
            }
        })
    }

    #[test]
    fn seam_passes_never_join_pieces_into_a_copy_of_a_third_of_the_exemplar() {
        let ex = boards(36);
        let large = (36usize * 36).div_ceil(3);
        // 8 rows: joined they copy 248 pixels, under a third of 1 296, and
        // the passes join them (the column takes the continuation).
        let mut small = split_by_a_column(8, &ex);
        refine_seams(&mut small, &ex, false, 3, 2, &Progress::hidden());
        assert_eq!(region_areas(&small), vec![31 * 8], "not joined");
        // 20 rows: joined they would copy 620 pixels, a third or more; the
        // guard keeps them apart.
        let mut tall = split_by_a_column(20, &ex);
        refine_seams(&mut tall, &ex, false, 3, 2, &Progress::hidden());
        let areas = region_areas(&tall);
        assert!(areas[0] < large, "a copy of {} pixels: {areas:?}", areas[0]);
    }

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
