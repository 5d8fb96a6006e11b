//! Region alignment of a pixel source map (an extension): whole copied
//! pieces of the exemplar shifted by a few pixels so they continue their
//! neighbours. [`align_regions`] runs sweeps; each sweep labels the copied
//! regions ([`Regions`]), and each region searches its shifts
//! ([`Sweep::align`]) on the seam cost of its border ([`Palette`]).

use super::super::map::TexelCoord;
use super::super::sources::SourceMap;
use super::copied_regions;
use crate::image::Image;
use crate::mesh::{union_find_join as join, union_find_root as find};
use crate::progress::Progress;

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

/// The outside half of a border pair in [`align_regions`]: `q`'s colour,
/// and the colours `k` pixels on (ahead) and `k + 1` back (behind) from
/// `q`'s source, `None` outside an inset exemplar. No shift of the region
/// changes it.
struct OutsideHalf {
    cq: [f32; 4],
    ahead: [Option<[f32; 4]>; ALIGN_DEPTH],
    behind: [Option<[f32; 4]>; ALIGN_DEPTH],
}

/// Squared difference of two padded colours.
#[inline]
fn diff(a: [f32; 4], b: [f32; 4]) -> f32 {
    (a[0] - b[0]) * (a[0] - b[0])
        + (a[1] - b[1]) * (a[1] - b[1])
        + (a[2] - b[2]) * (a[2] - b[2])
        + (a[3] - b[3]) * (a[3] - b[3])
}

/// The exemplar as the shift search reads it: colours padded to four
/// channels (fixed-size differences), addressed with or without wrap.
struct Palette {
    padded: Vec<[f32; 4]>,
    ew: i64,
    eh: i64,
    toroidal: bool,
}

impl Palette {
    fn new(exemplar: &Image, toroidal: bool) -> Self {
        let c = (exemplar.channels as usize).min(4);
        let padded = exemplar
            .data
            .chunks_exact(exemplar.channels.max(1) as usize)
            .map(|px| {
                let mut out = [0.0; 4];
                out[..c].copy_from_slice(&px[..c]);
                out
            })
            .collect();
        Self {
            padded,
            ew: exemplar.width as i64,
            eh: exemplar.height as i64,
            toroidal,
        }
    }

    #[inline]
    fn colour(&self, x: i64, y: i64) -> [f32; 4] {
        self.padded[(y * self.ew + x) as usize]
    }

    /// The exemplar address `t + d` (wrapped when toroidal), if it exists.
    #[inline]
    fn shifted(&self, tx: i64, ty: i64) -> Option<(i64, i64)> {
        if self.toroidal {
            Some((tx.rem_euclid(self.ew), ty.rem_euclid(self.eh)))
        } else {
            (tx >= 0 && ty >= 0 && tx < self.ew && ty < self.eh).then_some((tx, ty))
        }
    }

    /// An offset (source minus pixel) moved by `d`, wrapped when toroidal.
    #[inline]
    fn moved_by(&self, o: (i64, i64), d: (i64, i64)) -> (i64, i64) {
        let (ox, oy) = (o.0 + d.0, o.1 + d.1);
        if self.toroidal {
            (ox.rem_euclid(self.ew), oy.rem_euclid(self.eh))
        } else {
            (ox, oy)
        }
    }

    /// The outside half of a border pair whose outside pixel copies `sq`.
    fn outside(&self, sq: TexelCoord, step: (i64, i64)) -> OutsideHalf {
        let (qx, qy) = (sq.x as i64, sq.y as i64);
        let mut half = OutsideHalf {
            cq: self.colour(qx, qy),
            ahead: [None; ALIGN_DEPTH],
            behind: [None; ALIGN_DEPTH],
        };
        for k in 0..ALIGN_DEPTH {
            let k1 = k as i64;
            half.ahead[k] = self
                .shifted(qx + k1 * step.0, qy + k1 * step.1)
                .map(|(x, y)| self.colour(x, y));
            half.behind[k] = self
                .shifted(qx - (k1 + 1) * step.0, qy - (k1 + 1) * step.1)
                .map(|(x, y)| self.colour(x, y));
        }
        half
    }

    /// The seam cost of one pair with `p`'s source `sp` moved by `d`: p's
    /// continuation k + 1 pixels on against q's source k on, and the other
    /// way round, k < depth; the plain colour difference where a
    /// continuation leaves an inset exemplar.
    #[inline]
    fn pair_cost(
        &self,
        sp: TexelCoord,
        q: &OutsideHalf,
        d: (i64, i64),
        step: (i64, i64),
        depth: usize,
    ) -> f32 {
        let (px, py) = match self.shifted(sp.x as i64 + d.0, sp.y as i64 + d.1) {
            Some(t) => t,
            None => return f32::INFINITY,
        };
        let cp = self.colour(px, py);
        // Every continuation inside the exemplar (most pairs): the same
        // sums without a bounds test per pixel.
        let (fx, fy) = (px + depth as i64 * step.0, py + depth as i64 * step.1);
        let (bx, by) = (
            px - (depth as i64 - 1) * step.0,
            py - (depth as i64 - 1) * step.1,
        );
        let inside = |x: i64, y: i64| x >= 0 && y >= 0 && x < self.ew && y < self.eh;
        if self.toroidal || depth == 0 || !inside(fx, fy) || !inside(bx, by) {
            return self.pair_cost_checked((px, py), cp, q, step, depth);
        }
        let at = py * self.ew + px;
        let stride = step.1 * self.ew + step.0;
        let mut total = 0.0;
        for k in 0..depth {
            let k1 = k as i64;
            let ahead = match q.ahead[k] {
                Some(b) => diff(self.padded[(at + (k1 + 1) * stride) as usize], b),
                None => diff(cp, q.cq),
            };
            let behind = match q.behind[k] {
                Some(a) => diff(a, self.padded[(at - k1 * stride) as usize]),
                None => diff(cp, q.cq),
            };
            total += ahead + behind;
        }
        total
    }

    /// [`Self::pair_cost`] with `p`'s moved source at `(px, py)` (colour
    /// `cp`), every continuation's address tested.
    fn pair_cost_checked(
        &self,
        (px, py): (i64, i64),
        cp: [f32; 4],
        q: &OutsideHalf,
        step: (i64, i64),
        depth: usize,
    ) -> f32 {
        let mut total = 0.0;
        for k in 0..depth {
            let k1 = k as i64;
            let ahead = match (
                self.shifted(px + (k1 + 1) * step.0, py + (k1 + 1) * step.1),
                q.ahead[k],
            ) {
                (Some((x, y)), Some(b)) => diff(self.colour(x, y), b),
                _ => diff(cp, q.cq),
            };
            let behind = match (
                q.behind[k],
                self.shifted(px - k1 * step.0, py - k1 * step.1),
            ) {
                (Some(a), Some((u, v))) => diff(a, self.colour(u, v)),
                _ => diff(cp, q.cq),
            };
            total += ahead + behind;
        }
        total
    }
}

/// The copied regions of one sweep: each pixel's region label (its root,
/// the region's first pixel), and the pixels of each label in raster order
/// (`pixels[start[l]..start[l + 1]]`, a counting sort by label).
struct Regions {
    label: Vec<u32>,
    start: Vec<u32>,
    pixels: Vec<u32>,
}

impl Regions {
    fn of(src: &[TexelCoord], (w, h): (i64, i64), palette: &Palette) -> Self {
        let n = (w * h) as usize;
        let (mut parent, mut sizes) = (Vec::new(), Vec::new());
        copied_regions(
            src,
            (w, h),
            (palette.ew, palette.eh),
            palette.toroidal,
            &mut parent,
            &mut sizes,
        );
        let label: Vec<u32> = (0..n as u32).map(|i| find(&mut parent, i)).collect();
        drop((parent, sizes));
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
        Self {
            label,
            start,
            pixels,
        }
    }

    /// Pixels of region `l`.
    fn area(&self, l: usize) -> u32 {
        self.start[l + 1] - self.start[l]
    }

    /// The pixels of region `l`, in raster order.
    fn pixels_of(&self, l: u32) -> &[u32] {
        &self.pixels[self.start[l as usize] as usize..self.start[l as usize + 1] as usize]
    }
}

/// A shift's index in the `(2 · ALIGN_SHIFT + 1)²` grid, row by row: the
/// order ties are broken in.
#[inline]
fn shift_index(d: (i64, i64)) -> usize {
    ((d.1 + ALIGN_SHIFT) * (2 * ALIGN_SHIFT + 1) + d.0 + ALIGN_SHIFT) as usize
}

/// The state of one sweep of [`align_regions`] and the search buffers it
/// reuses from region to region.
struct Sweep<'a> {
    palette: &'a Palette,
    regions: Regions,
    /// Output size.
    w: i64,
    h: i64,
    /// Regions of at least this area count as large in the verbatim-copy
    /// measure (`kernels::metrics::quality`): a shift may not make one by
    /// joining its region to its neighbours.
    large: usize,
    /// Per region (by label): the group it has joined by a shift in this
    /// sweep (union–find over labels), its area, and its offset.
    group: Vec<u32>,
    area: Vec<u32>,
    offset: Vec<(i64, i64)>,
    /// Every shift but none, nearest first (ties in raster order).
    nearest_first: &'a [(i64, i64)],
    order: Vec<(i64, i64)>,
    tried: Vec<bool>,
    kept: Vec<(f32, usize, (i64, i64))>,
    border: Vec<(u32, u32, (i64, i64))>,
    halves: Vec<(u32, (i64, i64), OutsideHalf)>,
    near: Vec<u32>,
}

impl Sweep<'_> {
    /// The region `root`'s border pairs (inside, outside, step).
    fn collect_border(&mut self, root: u32) {
        self.border.clear();
        let (w, h) = (self.w, self.h);
        for &i in self.regions.pixels_of(root) {
            let (x, y) = (i as i64 % w, i as i64 / w);
            for (dx, dy) in [(1i64, 0i64), (-1, 0), (0, 1), (0, -1)] {
                let (qx, qy) = (x + dx, y + dy);
                if qx >= 0 && qy >= 0 && qx < w && qy < h {
                    let j = (qy * w + qx) as u32;
                    if self.regions.label[j as usize] != root {
                        self.border.push((i, j, (dx, dy)));
                    }
                }
            }
        }
    }

    /// The order shifts are tried in: those that join a neighbouring group
    /// first, then the rest nearest first (a cheap shift found early bounds
    /// the others' sums sooner). Ties go to the shift first in raster
    /// order, so the order does not change the result.
    fn order_shifts(&mut self, root: u32) {
        let (ew, eh) = (self.palette.ew, self.palette.eh);
        self.order.clear();
        self.kept.clear();
        self.tried.iter_mut().for_each(|t| *t = false);
        self.tried[shift_index((0, 0))] = true;
        for &g in &self.near {
            let (ox, oy) = self.offset[g as usize];
            let (rx, ry) = self.offset[root as usize];
            let mut d = (ox - rx, oy - ry);
            if self.palette.toroidal {
                // The nearest representative of the wrapped difference.
                d.0 = (d.0 + ew / 2).rem_euclid(ew) - ew / 2;
                d.1 = (d.1 + eh / 2).rem_euclid(eh) - eh / 2;
            }
            if d.0.abs() <= ALIGN_SHIFT && d.1.abs() <= ALIGN_SHIFT && !self.tried[shift_index(d)] {
                self.tried[shift_index(d)] = true;
                self.order.push(d);
            }
        }
        let tried = &self.tried;
        self.order.extend(
            self.nearest_first
                .iter()
                .filter(|&&d| !tried[shift_index(d)]),
        );
    }

    /// The best shift of region `root` (`(0, 0)`: stay): screened on the
    /// shallow cost over a sample of its border pairs, the cheapest few
    /// compared deep, the winner checked on the whole border and against
    /// the verbatim measure's repeats (`cover`).
    fn best_shift(&mut self, root: u32, src: &[TexelCoord], cover: &mut [u16]) -> (i64, i64) {
        let palette = self.palette;
        let (ew, eh) = (palette.ew, palette.eh);
        let toroidal = palette.toroidal;
        let own_group = find(&mut self.group, root);
        // The groups of the regions across the border.
        self.near.clear();
        for &(_, j, _) in &self.border {
            let g = find(&mut self.group, self.regions.label[j as usize]);
            if g != own_group && !self.near.contains(&g) {
                self.near.push(g);
            }
        }
        // The search compares shifts on at most `ALIGN_SEARCH_PAIRS`
        // pairs spread along the border; the winner must then be
        // cheaper than staying on the whole border.
        let stride = self.border.len().div_ceil(ALIGN_SEARCH_PAIRS).max(1);
        self.halves.clear();
        self.halves.extend(
            self.border
                .iter()
                .step_by(stride)
                .map(|&(i, j, step)| (i, step, palette.outside(src[j as usize], step))),
        );
        self.order_shifts(root);
        let region = self.regions.pixels_of(root);
        let halves = &self.halves;
        // The cost on every `every`-th search pair, given up above `bound`.
        let cost_on = |every: usize, depth: usize, d: (i64, i64), bound: f32| -> f32 {
            let mut e = 0.0f32;
            for (i, step, q) in halves.iter().step_by(every) {
                e += palette.pair_cost(src[*i as usize], q, d, *step, depth);
                if e > bound {
                    return e;
                }
            }
            e
        };
        let border = &self.border;
        let whole_border = |d: (i64, i64)| -> f32 {
            let mut e = 0.0f32;
            for &(i, j, step) in border {
                e += palette.pair_cost(
                    src[i as usize],
                    &palette.outside(src[j as usize], step),
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
        let own = self.area[own_group as usize] as usize;
        let large = self.large;
        for &(dx, dy) in &self.order {
            if !toroidal && (lo.0 + dx < 0 || lo.1 + dy < 0 || hi.0 + dx >= ew || hi.1 + dy >= eh) {
                continue;
            }
            let shifted_offset = palette.moved_by(self.offset[root as usize], (dx, dy));
            let joined: usize = self
                .near
                .iter()
                .filter(|&&g| self.offset[g as usize] == shifted_offset)
                .map(|&g| self.area[g as usize] as usize)
                .sum();
            if joined > 0 && own + joined >= large {
                continue;
            }
            // Screened on the shallow cost: the `ALIGN_SCREEN_KEEP`
            // cheapest (ties to the first in raster order) go on.
            let kept = &mut self.kept;
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
        for &(_, _, d) in &self.kept {
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
                palette
                    .shifted(t.x as i64 + best.1.0, t.y as i64 + best.1.1)
                    .is_some_and(|(x, y)| cover[texel(x, y)] < 2)
            });
            if !fits {
                best.1 = (0, 0);
            }
            for &i in region {
                let t = src[i as usize];
                let (x, y) = palette
                    .shifted(t.x as i64 + best.1.0, t.y as i64 + best.1.1)
                    .unwrap_or((t.x as i64, t.y as i64));
                cover[texel(x, y)] += 1;
            }
        }
        best.1
    }

    /// Moves region `root`'s sources by `(dx, dy)` and joins it to the
    /// neighbouring groups it now continues.
    fn apply(&mut self, root: u32, (dx, dy): (i64, i64), src: &mut [TexelCoord]) {
        let palette = self.palette;
        let own_group = find(&mut self.group, root);
        let new_offset = palette.moved_by(self.offset[root as usize], (dx, dy));
        self.offset[root as usize] = new_offset;
        self.offset[own_group as usize] = new_offset;
        for &g in &self.near {
            if self.offset[g as usize] == new_offset
                && find(&mut self.group, own_group) != find(&mut self.group, g)
            {
                let lo = join(&mut self.group, &mut self.area, own_group, g);
                self.offset[lo as usize] = new_offset;
            }
        }
        for &i in self.regions.pixels_of(root) {
            let t = src[i as usize];
            if let Some((x, y)) = palette.shifted(t.x as i64 + dx, t.y as i64 + dy) {
                src[i as usize] = TexelCoord {
                    x: x as u32,
                    y: y as u32,
                };
            }
        }
    }
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
    let n = (w * h) as usize;
    let mut nearest_first: Vec<(i64, i64)> = (-ALIGN_SHIFT..=ALIGN_SHIFT)
        .flat_map(|dy| (-ALIGN_SHIFT..=ALIGN_SHIFT).map(move |dx| (dx, dy)))
        .filter(|&d| d != (0, 0))
        .collect();
    let shift_count = nearest_first.len();
    nearest_first.sort_by_key(|&(dx, dy)| (dx * dx + dy * dy, shift_index((dx, dy))));
    let mut report = AlignReport::default();
    if n == 0 || ew == 0 || eh == 0 {
        return report;
    }
    let palette = Palette::new(exemplar, toroidal);
    let src = &mut sources.texels;
    let large = ((ew * eh) as usize).div_ceil(3);
    let offset_of = |i: usize, t: TexelCoord| -> (i64, i64) {
        let (x, y) = ((i as i64) % w, (i as i64) / w);
        palette.moved_by((t.x as i64 - x, t.y as i64 - y), (0, 0))
    };
    let mut dirty = vec![true; n];
    let mut cover = vec![0u16; (ew * eh) as usize];
    let mut buffers = (
        Vec::with_capacity(shift_count),
        vec![false; shift_count + 1],
        Vec::with_capacity(ALIGN_SCREEN_KEEP + 1),
        Vec::new(),
        Vec::new(),
        Vec::new(),
    );
    for _ in 0..sweeps {
        let mut moved = 0;
        let mut next_dirty = vec![false; n];
        let regions = Regions::of(src, (w, h), &palette);
        let roots: Vec<u32> = (0..n as u32)
            .filter(|&r| regions.area(r as usize) as usize >= ALIGN_MIN_PIXELS)
            .collect();
        report.regions = report.regions.max(roots.len());
        progress.set_length(u64::from(sweeps) * roots.len() as u64);
        progress.set_position(report.shifted.len() as u64 * roots.len() as u64);
        // Per exemplar pixel, how many pixels of large regions copy it.
        cover.iter_mut().for_each(|c| *c = 0);
        for (i, &l) in regions.label.iter().enumerate() {
            if regions.area(l as usize) as usize >= large {
                let t = src[i];
                cover[(t.y as i64 * ew + t.x as i64) as usize] += 1;
            }
        }
        let area: Vec<u32> = (0..n).map(|l| regions.area(l)).collect();
        let mut offset: Vec<(i64, i64)> = vec![(0, 0); n];
        for (l, o) in offset.iter_mut().enumerate() {
            if regions.area(l) > 0 {
                let i = regions.pixels[regions.start[l] as usize] as usize;
                *o = offset_of(i, src[i]);
            }
        }
        let (order, tried, kept, border, halves, near) = buffers;
        let mut sweep = Sweep {
            palette: &palette,
            regions,
            w,
            h,
            large,
            group: (0..n as u32).collect(),
            area,
            offset,
            nearest_first: &nearest_first,
            order,
            tried,
            kept,
            border,
            halves,
            near,
        };
        for &root in &roots {
            progress.inc(1);
            sweep.collect_border(root);
            if sweep.border.is_empty() {
                continue;
            }
            // Only regions that moved, or border a region that moved, in
            // the previous sweep can find a cheaper shift.
            if !sweep
                .regions
                .pixels_of(root)
                .iter()
                .any(|&i| dirty[i as usize])
                && !sweep.border.iter().any(|&(_, j, _)| dirty[j as usize])
            {
                continue;
            }
            let best = sweep.best_shift(root, src, &mut cover);
            if best != (0, 0) {
                moved += 1;
                for &i in sweep.regions.pixels_of(root) {
                    next_dirty[i as usize] = true;
                }
                sweep.apply(root, best, src);
            }
        }
        buffers = (
            sweep.order,
            sweep.tried,
            sweep.kept,
            sweep.border,
            sweep.halves,
            sweep.near,
        );
        report.shifted.push(moved);
        dirty = next_dirty;
        if moved == 0 {
            break;
        }
    }
    report
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The unchecked sum of a pair whose continuations all lie inside an
    /// inset exemplar equals the checked one bit for bit, over every
    /// source, step direction and depth of a noise exemplar.
    #[test]
    fn pair_costs_inside_equal_the_checked_sums() {
        let (w, h) = (23u32, 17u32);
        let mut s = 7u32;
        let data = (0..w * h * 3)
            .map(|_| {
                s = s.wrapping_mul(1664525).wrapping_add(1013904223);
                (s >> 8) as f32 / (1u32 << 24) as f32
            })
            .collect();
        let img = Image::from_data(w, h, 3, data).unwrap();
        let palette = Palette::new(&img, false);
        let (mut fast, mut checked) = (0, 0);
        for step in [(1, 0), (-1, 0), (0, 1), (0, -1)] {
            let q = palette.outside(TexelCoord { x: 9, y: 8 }, step);
            for depth in 0..=ALIGN_DEPTH {
                for y in 0..h as i64 {
                    for x in 0..w as i64 {
                        let sp = TexelCoord {
                            x: x as u32,
                            y: y as u32,
                        };
                        let cost = palette.pair_cost(sp, &q, (0, 0), step, depth);
                        let plain = palette.pair_cost_checked(
                            (x, y),
                            palette.colour(x, y),
                            &q,
                            step,
                            depth,
                        );
                        assert_eq!(
                            cost.to_bits(),
                            plain.to_bits(),
                            "({x}, {y}) {step:?} {depth}"
                        );
                        let d = depth as i64;
                        let inside =
                            |x: i64, y: i64| x >= 0 && y >= 0 && x < w as i64 && y < h as i64;
                        if depth > 0
                            && inside(x + d * step.0, y + d * step.1)
                            && inside(x - (d - 1) * step.0, y - (d - 1) * step.1)
                        {
                            fast += 1;
                        } else {
                            checked += 1;
                        }
                    }
                }
            }
        }
        assert!(fast > 1000 && checked > 1000, "{fast} {checked}");
    }
}
