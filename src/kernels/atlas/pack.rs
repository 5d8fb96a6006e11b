//! Packing charts into a square atlas: each chart turned to its
//! minimum-area bounding rectangle lying flat, then placed by its outline
//! (the texel rows of each texel column it and its gutter reserve, in the
//! best of four quarter turns), tallest first; a bisection finds the
//! largest common scale (texels per world unit) at which all fit with the
//! gutter. Packing bounding rectangles ([`skyline_pack`]) left the corners
//! of every disc-shaped chart empty: 41 % filled on a 400 k-vertex scan.
//!
//! The bisection runs in two phases. First on a column skyline (each chart
//! rests on the highest chart in its columns: fast, 0.494 filled on that
//! scan, 2048², 4 px gutters), to 1 % of the scale. Then [`GAP_ROUNDS`]
//! rounds towards the area bound with the gap packer
//! ([`profile_pack`] with gaps): each column keeps its taken rows as intervals,
//! so a chart also settles into a gap under another's outline or inside a
//! ring-shaped chart around a scan's hole (0.626 on that scan; 0.632 with
//! a full bisection). Each gap pack costs several skyline packs, hence the
//! two phases.

use super::Charts;
use glam::{DVec2, Vec2};
use rayon::prelude::*;

/// Counter-clockwise convex hull (Andrew's monotone chain).
fn convex_hull(mut pts: Vec<DVec2>) -> Vec<DVec2> {
    pts.sort_by(|a, b| a.x.total_cmp(&b.x).then(a.y.total_cmp(&b.y)));
    pts.dedup();
    if pts.len() < 3 {
        return pts;
    }
    let mut hull: Vec<DVec2> = Vec::with_capacity(2 * pts.len());
    for pass in 0..2 {
        let start = hull.len();
        let iter: Box<dyn Iterator<Item = &DVec2>> = if pass == 0 {
            Box::new(pts.iter())
        } else {
            Box::new(pts.iter().rev())
        };
        for &p in iter {
            while hull.len() >= start + 2
                && (hull[hull.len() - 1] - hull[hull.len() - 2]).perp_dot(p - hull[hull.len() - 2])
                    <= 0.0
            {
                hull.pop();
            }
            hull.push(p);
        }
        hull.pop();
    }
    hull
}

/// The rotation (cos, sin) that turns `pts` to their minimum-area bounding
/// rectangle lying flat (width ≥ height).
fn flat_min_area_rotation(pts: &[DVec2]) -> DVec2 {
    let hull = convex_hull(pts.to_vec());
    let extent = |rot: DVec2| {
        let (mut lo, mut hi) = (DVec2::splat(f64::INFINITY), DVec2::splat(f64::NEG_INFINITY));
        for p in &hull {
            let q = DVec2::new(rot.x * p.x - rot.y * p.y, rot.y * p.x + rot.x * p.y);
            lo = lo.min(q);
            hi = hi.max(q);
        }
        hi - lo
    };
    let mut best = (f64::INFINITY, DVec2::X);
    for i in 0..hull.len() {
        let e = hull[(i + 1) % hull.len()] - hull[i];
        let Some(dir) = e.try_normalize() else {
            continue;
        };
        // Rotate the edge onto the x axis.
        let rot = DVec2::new(dir.x, -dir.y);
        let size = extent(rot);
        // Relative tie margin: chart extents are in the mesh's own units.
        if size.x * size.y < best.0 * (1.0 - 1e-12) {
            best = (size.x * size.y, rot);
        }
    }
    let rot = best.1;
    let size = extent(rot);
    if size.y > size.x {
        // A further quarter turn lays it flat.
        DVec2::new(-rot.y, rot.x)
    } else {
        rot
    }
}

/// Bottom-left skyline packing of `rects` (width, height) into a square of
/// side `size`, in the given order. Returns top-left positions (y down), or
/// `None` when they do not fit.
pub fn skyline_pack(rects: &[(u32, u32)], size: u32) -> Option<Vec<(u32, u32)>> {
    // Segments (x, y, width): the height reached over [x, x + width).
    let mut sky: Vec<(u32, u32, u32)> = vec![(0, 0, size)];
    let mut out = Vec::with_capacity(rects.len());
    for &(w, h) in rects {
        if w > size || h > size {
            return None;
        }
        let mut best: Option<(u32, u32)> = None;
        for i in 0..sky.len() {
            let x = sky[i].0;
            if x + w > size {
                break;
            }
            let mut y = 0;
            for seg in &sky[i..] {
                if seg.0 >= x + w {
                    break;
                }
                y = y.max(seg.1);
            }
            if y + h > size {
                continue;
            }
            if best.is_none_or(|(bx, by)| (y, x) < (by, bx)) {
                best = Some((x, y));
            }
        }
        let (x, y) = best?;
        out.push((x, y));
        // Raise the skyline over [x, x + w).
        let mut next: Vec<(u32, u32, u32)> = Vec::with_capacity(sky.len() + 2);
        for &(sx, sy, sw) in &sky {
            let end = sx + sw;
            if end <= x || sx >= x + w {
                next.push((sx, sy, sw));
                continue;
            }
            if sx < x {
                next.push((sx, sy, x - sx));
            }
            if end > x + w {
                next.push((x + w, sy, end - (x + w)));
            }
        }
        next.push((x, y + h, w));
        next.sort_unstable();
        sky.clear();
        for seg in next {
            match sky.last_mut() {
                Some(last) if last.1 == seg.1 && last.0 + last.2 == seg.0 => last.2 += seg.2,
                _ => sky.push(seg),
            }
        }
    }
    Some(out)
}

/// One chart's footprint at a scale: per block column, the block rows
/// `[top, bottom)` its faces and gutter reserve (`top ≥ bottom` for a
/// column it leaves free), and its width in blocks.
#[derive(Clone, Debug)]
struct Footprint {
    top: Vec<u32>,
    bottom: Vec<u32>,
}

/// The rows `[lo, hi)` of the texel column `[x, x + 1)` that the triangle
/// `t` (texel coordinates, y down) reaches, if any.
fn column_rows(t: &[DVec2; 3], x: f64) -> Option<(f64, f64)> {
    let (x0, x1) = (x, x + 1.0);
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for k in 0..3 {
        let (p, q) = (t[k], t[(k + 1) % 3]);
        if (x0..=x1).contains(&p.x) {
            lo = lo.min(p.y);
            hi = hi.max(p.y);
        }
        for line in [x0, x1] {
            if (p.x - line) * (q.x - line) < 0.0 {
                let y = p.y + (q.y - p.y) * (line - p.x) / (q.x - p.x);
                lo = lo.min(y);
                hi = hi.max(y);
            }
        }
    }
    (lo <= hi).then_some((lo, hi))
}

/// The footprint of a chart whose faces, in texel coordinates of its
/// `width × height`-texel box, are `tris`: per texel column the rows its
/// faces touch, grown by `pad` texels every way (its gutter), then
/// coarsened to `block`-texel blocks.
fn footprint(tris: &[[DVec2; 3]], width: u32, height: u32, pad: u32, block: u32) -> Footprint {
    let (w, pad) = (width as usize, pad as i64);
    let mut lo = vec![i64::MAX; w];
    let mut hi = vec![i64::MIN; w];
    for t in tris {
        let x_lo = t[0].x.min(t[1].x).min(t[2].x).floor().max(0.0) as usize;
        let x_hi = (t[0].x.max(t[1].x).max(t[2].x).floor() as usize).min(w - 1);
        for x in x_lo..=x_hi {
            if let Some((a, b)) = column_rows(t, x as f64) {
                lo[x] = lo[x].min(a.floor() as i64);
                hi[x] = hi[x].max(b.floor() as i64 + 1);
            }
        }
    }
    // Grow by the gutter: columns within `pad`, rows within `pad`.
    let (mut glo, mut ghi) = (vec![i64::MAX; w], vec![i64::MIN; w]);
    for x in 0..w {
        if lo[x] > hi[x] {
            continue;
        }
        let (a, b) = ((x as i64 - pad).max(0) as usize, (x as i64 + pad) as usize);
        for g in a..=b.min(w - 1) {
            glo[g] = glo[g].min(lo[x] - pad);
            ghi[g] = ghi[g].max(hi[x] + pad);
        }
    }
    let cols = width.div_ceil(block) as usize;
    let rows = height.div_ceil(block) as i64;
    let (mut top, mut bottom) = (vec![u32::MAX; cols], vec![0u32; cols]);
    for x in 0..w {
        if glo[x] > ghi[x] {
            continue;
        }
        let j = x / block as usize;
        let t = glo[x].max(0).div_euclid(block as i64);
        let b = (ghi[x].min(height as i64) + block as i64 - 1).div_euclid(block as i64);
        top[j] = top[j].min(t.clamp(0, rows) as u32);
        bottom[j] = bottom[j].max(b.clamp(0, rows) as u32);
    }
    Footprint { top, bottom }
}

/// Places charts (in the given order, each as one of its footprints: its
/// turns) in an atlas of `cols` block columns and `rows` block rows: each
/// goes where it sits highest (then leftmost, then first turn) without
/// touching a block another chart reserved. Each column keeps the block
/// rows taken as sorted intervals, so a chart may settle into a gap left
/// under another chart's outline or inside a ring-shaped chart (a scan's
/// holes), not only on top of the highest chart in its columns (a
/// skyline, where every chart goes with `gaps` false: cheaper, and its
/// profile still nests into the charts below). Returns block positions and
/// turns, or `None` when one does not fit.
fn profile_pack(
    prints: &[[Footprint; 4]],
    cols: usize,
    rows: u32,
    gaps: bool,
) -> Option<Vec<(u32, u32, u8)>> {
    let mut taken: Vec<Vec<(u32, u32)>> = vec![Vec::new(); cols];
    // Per column, where its first gap of at least 2^k free rows starts:
    // a footprint column of h rows sits no lower than the gap of class
    // ⌊log₂ h⌋, so most positions are ruled out without a search.
    let mut fit = vec![[0u32; FIT_CLASSES]; cols];
    // No footprint fits a gap shorter than its shortest column: such gaps
    // are closed as they form, so the search never walks them.
    let min_gap = prints
        .iter()
        .flatten()
        .flat_map(|fp| {
            fp.top
                .iter()
                .zip(&fp.bottom)
                .filter(|(t, b)| t < b)
                .map(|(t, b)| b - t)
        })
        .min()
        .unwrap_or(1);
    let mut out = Vec::with_capacity(prints.len());
    // (lower bound, x, turn) of every position, packed to sort.
    let mut cands: Vec<u64> = Vec::new();
    for turns in prints {
        // The skyline's answer: on top of everything, always free.
        let mut sky: Option<(u32, usize, u8)> = None;
        for (o, fp) in turns.iter().enumerate() {
            let w = fp.top.len();
            if w > cols {
                return None;
            }
            let height = fp.bottom.iter().copied().max().unwrap_or(0);
            if height > rows {
                continue;
            }
            for x in 0..=cols - w {
                let below = sky.map_or(rows - height + 1, |(by, _, _)| by.min(rows - height + 1));
                if let Some(y) = fit_bound_class(&fit[x..x + w], fp, below, Some(FIT_CLASSES - 1)) {
                    sky = Some((y, x, o as u8));
                }
            }
        }
        let mut best: Option<(u32, usize, u8)> = sky;
        if gaps {
            place_in_gaps(turns, &taken, &fit, rows, &mut cands, &mut best);
        }
        let (y, x, o) = best?;
        let fp = &turns[o as usize];
        for j in 0..fp.top.len() {
            if fp.top[j] < fp.bottom[j] {
                let col = &mut taken[x + j];
                take(col, y + fp.top[j], y + fp.bottom[j], min_gap);
                fit[x + j] = gap_starts(col);
            }
        }
        out.push((x as u32, y, o));
    }
    Some(out)
}

/// The branch and bound of [`profile_pack`] below the skyline's answer
/// `best`: every position's lower bound first (cheap, from `fit`), then
/// the full search in increasing bound order, until the bound passes the
/// best row found; `best` ends as the lowest, then leftmost, then first
/// turn. `cands` is scratch.
fn place_in_gaps(
    turns: &[Footprint; 4],
    taken: &[Vec<(u32, u32)>],
    fit: &[[u32; FIT_CLASSES]],
    rows: u32,
    cands: &mut Vec<u64>,
    best: &mut Option<(u32, usize, u8)>,
) {
    let cols = taken.len();
    let sky = *best;
    cands.clear();
    for (o, fp) in turns.iter().enumerate() {
        let w = fp.top.len();
        let height = fp.bottom.iter().copied().max().unwrap_or(0);
        if height > rows {
            continue;
        }
        // Ties with the skyline's row may still be further left.
        let below = sky.map_or(rows - height + 1, |(by, _, _)| {
            (by + 1).min(rows - height + 1)
        });
        for x in 0..=cols - w {
            if let Some(b) = fit_bound_class(&fit[x..x + w], fp, below, None) {
                cands.push(u64::from(b) << 32 | (x as u64) << 2 | o as u64);
            }
        }
    }
    cands.sort_unstable();
    for &c in cands.iter() {
        let (bound, x, o) = (
            (c >> 32) as u32,
            ((c >> 2) & 0x3FFF_FFFF) as usize,
            (c & 3) as u8,
        );
        if best.is_some_and(|(by, _, _)| bound > by) {
            break;
        }
        let fp = &turns[o as usize];
        let w = fp.top.len();
        let height = fp.bottom.iter().copied().max().unwrap_or(0);
        let below = best.map_or(rows - height + 1, |(by, _, _)| {
            (by + 1).min(rows - height + 1)
        });
        if let Some(y) = lowest_fit(&taken[x..x + w], fp, bound, below)
            && best.is_none_or(|b| (y, x, o) < b)
        {
            *best = Some((y, x, o));
        }
    }
}

/// Rounds of the scale search with [`profile_pack`] with gaps after the
/// skyline's, two packs each (the interval shrinks to a third a round): on
/// a 400 k-vertex messy scan (1,586 charts, 2048², 4 px gutters) the
/// skyline fills 0.494 of the atlas and the gaps 0.62, at about 1.3 s a
/// pack there (the skyline's are 0.3 s).
const GAP_ROUNDS: usize = 3;

/// Classes of gap height (powers of two) a column indexes.
const FIT_CLASSES: usize = 16;

/// The class of a footprint column `h` rows tall: `⌊log₂ h⌋`.
fn fit_class(h: u32) -> usize {
    ((31 - h.max(1).leading_zeros()) as usize).min(FIT_CLASSES - 1)
}

/// Per class `k`, where the first gap of at least `2^k` free rows of a
/// column (its taken rows `col`) starts; the rows above the last taken
/// ones are one unbounded gap.
fn gap_starts(col: &[(u32, u32)]) -> [u32; FIT_CLASSES] {
    let mut out = [u32::MAX; FIT_CLASSES];
    let mut free_from = 0u32;
    for &(start, end) in col {
        let gap = start - free_from;
        for (k, o) in out.iter_mut().enumerate() {
            if *o == u32::MAX && gap >= 1 << k {
                *o = free_from;
            }
        }
        free_from = end;
    }
    for o in &mut out {
        if *o == u32::MAX {
            *o = free_from;
        }
    }
    out
}

/// The lowest row at which footprint `fp` could sit in columns whose
/// [`gap_starts`] are `fit` (each of its columns no lower than the first
/// gap tall enough for it, or of gap class `class` if given), if below
/// `below`.
fn fit_bound_class(
    fit: &[[u32; FIT_CLASSES]],
    fp: &Footprint,
    below: u32,
    class: Option<usize>,
) -> Option<u32> {
    let mut y = 0u32;
    for ((f, &top), &bottom) in fit.iter().zip(&fp.top).zip(&fp.bottom) {
        if top < bottom {
            let k = class.unwrap_or_else(|| fit_class(bottom - top));
            y = y.max(f[k].saturating_sub(top));
            if y >= below {
                return None;
            }
        }
    }
    Some(y)
}

/// The lowest row from `from` and below `below` at which footprint `fp`
/// fits in the columns `taken` (each its taken rows, sorted and disjoint),
/// if any: whenever one of its columns meets a taken interval it moves
/// down to just past that interval, until every column is free.
fn lowest_fit(taken: &[Vec<(u32, u32)>], fp: &Footprint, from: u32, below: u32) -> Option<u32> {
    let w = taken.len();
    let mut y = from;
    // Columns are checked round the footprint from the last one that moved
    // it, until all `w` in a row are clear at the current row.
    let (mut j, mut clear) = (0usize, 0usize);
    while clear < w {
        if y >= below {
            return None;
        }
        let (top, bottom) = (fp.top[j], fp.bottom[j]);
        let col = &taken[j];
        if top < bottom {
            let (a, b) = (y + top, y + bottom);
            let i = col.partition_point(|iv| iv.1 <= a);
            if let Some(&(start, end)) = col.get(i)
                && start < b
            {
                // Strictly lower: `end > a = y + top`.
                y = end - top;
                clear = 0;
                continue;
            }
        }
        clear += 1;
        j = if j + 1 == w { 0 } else { j + 1 };
    }
    (y < below).then_some(y)
}

/// Marks rows `[a, b)` of a column taken (intervals sorted and disjoint);
/// a gap of fewer than `min_gap` rows left to a neighbouring interval (or
/// to row 0) is taken with it, since nothing fits there.
fn take(col: &mut Vec<(u32, u32)>, a: u32, b: u32, min_gap: u32) {
    let (mut lo, mut hi) = (a, b);
    if lo < min_gap {
        lo = 0;
    }
    let i = col.partition_point(|iv| iv.1 + min_gap <= lo);
    let mut k = i;
    while k < col.len() && col[k].0 < hi + min_gap {
        lo = lo.min(col[k].0);
        hi = hi.max(col[k].1);
        k += 1;
    }
    col.splice(i..k, [(lo, hi)]);
}

/// Packs the charts into a `size × size` atlas (step 4 of the module docs):
/// returns per-face corner atlas coordinates and the scale in texels per
/// world unit. `None` when even the gutters alone do not fit.
///
/// Each chart is turned to its minimum-area rectangle lying flat; at a
/// trial scale its footprint (the texel rows each texel column of its
/// faces touches, grown by `padding_px` texels of gutter every way) is
/// placed, tallest first, in blocks of `size / 4096` texels (at least 1).
/// Charts rest on each other's actual outlines rather than on bounding
/// rectangles, so a disc-shaped chart leaves its corners to the next. A
/// bisection finds the largest scale at which all fit: on the skyline,
/// then a few steps further with charts settling into gaps (module docs).
pub fn pack_charts(charts: &Charts, size: u32, padding_px: u32) -> Option<(Vec<[Vec2; 3]>, f32)> {
    let _span = tracing::debug_span!("pack_charts", charts = charts.count).entered();
    let n = charts.count;
    let mut faces_of: Vec<Vec<u32>> = vec![Vec::new(); n];
    for f in 0..charts.corner_st.len() {
        faces_of[charts.chart_of_face[f] as usize].push(f as u32);
    }
    // Turn every chart flat and move it to the origin. One chart's corners
    // at a time (all of them at once, in f64, were 48 bytes per face).
    let mut placed: Vec<(DVec2, DVec2, DVec2)> = Vec::with_capacity(n); // (rot, min, size)
    let mut pts: Vec<DVec2> = Vec::new();
    for faces in &faces_of {
        pts.clear();
        pts.extend(
            faces
                .iter()
                .flat_map(|&f| charts.corner_st[f as usize].map(|p| p.as_dvec2())),
        );
        let rot = flat_min_area_rotation(&pts);
        let (mut lo, mut hi) = (DVec2::splat(f64::INFINITY), DVec2::splat(f64::NEG_INFINITY));
        for p in &pts {
            let q = DVec2::new(rot.x * p.x - rot.y * p.y, rot.y * p.x + rot.x * p.y);
            lo = lo.min(q);
            hi = hi.max(q);
        }
        placed.push((rot, lo, (hi - lo).max(DVec2::ZERO)));
    }
    drop(pts);
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&a, &b| {
        placed[b]
            .2
            .y
            .total_cmp(&placed[a].2.y)
            .then(placed[b].2.x.total_cmp(&placed[a].2.x))
            .then(a.cmp(&b))
    });
    let pad = padding_px as f64;
    // A chart's box at a scale, texels.
    let box_at = |c: usize, scale: f64| {
        let s = placed[c].2 * scale;
        (
            s.x.ceil() as u32 + 2 * padding_px + 1,
            s.y.ceil() as u32 + 2 * padding_px + 1,
        )
    };
    // Where a chart point lands in its box, in texels (y down), turned by
    // half a turn for `turn` 1.
    let local = |c: usize, p: Vec2, scale: f64, turn: u8| {
        let (rot, min, extent) = placed[c];
        let p = p.as_dvec2();
        let q = DVec2::new(rot.x * p.x - rot.y * p.y, rot.y * p.x + rot.x * p.y) - min;
        // t up in the chart is up in the image (y down).
        let l = DVec2::new(
            pad + 0.5 + q.x * scale,
            pad + 0.5 + (extent.y - q.y) * scale,
        );
        let (w, h) = box_at(c, scale);
        let (w, h) = (w as f64, h as f64);
        match turn {
            0 => l,
            1 => DVec2::new(w - l.x, h - l.y),
            2 => DVec2::new(l.y, w - l.x),
            _ => DVec2::new(h - l.y, l.x),
        }
    };
    let block = (size / 4096).max(1);
    let (cols, rows) = (size.div_ceil(block) as usize, size / block);
    let pack_at = |scale: f64, gaps: bool| -> Option<Vec<(u32, u32, u8)>> {
        let prints: Vec<[Footprint; 4]> = order
            .par_iter()
            .map(|&c| {
                [0, 1, 2, 3].map(|turn| {
                    let (w, h) = box_at(c, scale);
                    let (w, h) = if turn < 2 { (w, h) } else { (h, w) };
                    let tris: Vec<[DVec2; 3]> = faces_of[c]
                        .iter()
                        .map(|&f| charts.corner_st[f as usize].map(|p| local(c, p, scale, turn)))
                        .collect();
                    footprint(&tris, w, h, padding_px, block)
                })
            })
            .collect();
        profile_pack(&prints, cols, rows, gaps)
    };
    let largest = placed
        .iter()
        .map(|p| p.2.x.max(p.2.y))
        .fold(0.0f64, f64::max)
        .max(1e-12);
    // Charts cannot cover more than the atlas: an upper bound on the scale.
    let area: f64 = charts
        .corner_st
        .iter()
        .map(|t| 0.5 * super::raster::signed_area2(t).abs() as f64)
        .sum();
    let mut hi = size as f64 / largest;
    if area > 0.0 {
        hi = hi.min(size as f64 / area.sqrt());
    }
    let mut lo = 0.0f64;
    let mut best = pack_at(lo, false).map(|p| (lo, p))?;
    // On the skyline, to 1 % of the scale (the gap steps refine it).
    let top = hi;
    while hi - lo > 1e-2 * hi {
        let mid = 0.5 * (lo + hi);
        match pack_at(mid, false) {
            Some(p) => {
                lo = mid;
                best = (mid, p);
            }
            None => hi = mid,
        }
    }
    // Then larger scales, with charts also settling into gaps, between the
    // skyline's scale and the bound: each round packs at a third and two
    // thirds of the interval at once (each pack is sequential and costs
    // more than the whole skyline search) and keeps the largest that fits.
    // The same scales are tried at any thread count.
    let mut hi = top;
    for _ in 0..GAP_ROUNDS {
        let (a, b) = (lo + (hi - lo) / 3.0, lo + 2.0 * (hi - lo) / 3.0);
        let (pa, pb) = rayon::join(|| pack_at(a, true), || pack_at(b, true));
        match (pa, pb) {
            (_, Some(p)) => {
                lo = b;
                best = (b, p);
            }
            (Some(p), None) => {
                (lo, hi) = (a, b);
                best = (a, p);
            }
            (None, None) => hi = a,
        }
    }
    let (scale, positions) = best;
    let mut corner = vec![(DVec2::ZERO, 0u8); n];
    for (k, &c) in order.iter().enumerate() {
        let (x, y, turn) = positions[k];
        corner[c] = (DVec2::new((x * block) as f64, (y * block) as f64), turn);
    }
    let inv = 1.0 / size as f64;
    let uvs = charts
        .corner_st
        .iter()
        .enumerate()
        .map(|(f, st)| {
            let c = charts.chart_of_face[f] as usize;
            st.map(|p| {
                let q = corner[c].0 + local(c, p, scale, corner[c].1);
                Vec2::new((q.x * inv) as f32, (q.y * inv) as f32)
            })
        })
        .collect();
    Some((uvs, scale as f32))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn skyline_places_without_overlap() {
        let rects = [(50, 40), (30, 30), (30, 20), (60, 10), (10, 10), (20, 5)];
        let pos = skyline_pack(&rects, 100).unwrap();
        for i in 0..rects.len() {
            let (xi, yi) = pos[i];
            assert!(xi + rects[i].0 <= 100 && yi + rects[i].1 <= 100);
            for j in i + 1..rects.len() {
                let (xj, yj) = pos[j];
                let apart = xi + rects[i].0 <= xj
                    || xj + rects[j].0 <= xi
                    || yi + rects[i].1 <= yj
                    || yj + rects[j].1 <= yi;
                assert!(apart, "{i} and {j} overlap");
            }
        }
        assert!(skyline_pack(&[(60, 60), (60, 60)], 100).is_none());
    }

    /// A footprint of `w × h` blocks with the rows `[hole_top, hole_bottom)`
    /// of its middle columns left free (a ring, seen column by column: a
    /// U open at the top).
    fn cup(w: u32, h: u32, wall: u32, floor: u32) -> Footprint {
        let top = (0..w)
            .map(|x| {
                if x < wall || x >= w - wall {
                    0
                } else {
                    h - floor
                }
            })
            .collect();
        Footprint {
            top,
            bottom: vec![h; w as usize],
        }
    }

    fn block(w: u32, h: u32) -> Footprint {
        Footprint {
            top: vec![0; w as usize],
            bottom: vec![h; w as usize],
        }
    }

    fn four(f: impl Fn() -> Footprint) -> [Footprint; 4] {
        [f(), f(), f(), f()]
    }

    #[test]
    fn gaps_under_outlines_are_filled() {
        // An upside-down cup (its columns' rows cover the top, and the
        // walls reach down) leaves a gap under its middle: an 8 × 8 atlas
        // holds the cup (8 wide, walls 1, roof 2) and then a 6 × 6 block
        // beneath the roof only if the gap is used.
        let roof = Footprint {
            top: vec![0; 8],
            bottom: (0..8)
                .map(|x| if x == 0 || x == 7 { 8 } else { 2 })
                .collect(),
        };
        let prints = [
            [roof.clone(), roof.clone(), roof.clone(), roof.clone()],
            four(|| block(6, 6)),
        ];
        let placed = profile_pack(&prints, 8, 8, true).expect("both fit");
        assert_eq!(placed[0], (0, 0, 0));
        assert_eq!(placed[1], (1, 2, 0), "{placed:?}");
        // A U settles its contents inside.
        let prints = [four(|| cup(8, 8, 1, 1)), four(|| block(6, 7))];
        let placed = profile_pack(&prints, 8, 8, true).expect("both fit");
        assert_eq!(placed[1], (1, 0, 0), "{placed:?}");
        // Taken blocks never overlap, and a full atlas refuses.
        assert!(profile_pack(&[four(|| block(8, 8)), four(|| block(1, 1))], 8, 8, true).is_none());
    }

    #[test]
    fn taken_intervals_merge() {
        let mut col = Vec::new();
        take(&mut col, 4, 6, 1);
        take(&mut col, 0, 2, 1);
        take(&mut col, 8, 9, 1);
        assert_eq!(col, [(0, 2), (4, 6), (8, 9)]);
        take(&mut col, 2, 4, 1);
        assert_eq!(col, [(0, 6), (8, 9)]);
        take(&mut col, 5, 12, 1);
        assert_eq!(col, [(0, 12)]);
        // Gaps shorter than 3 rows are closed, also down to row 0.
        let mut col = Vec::new();
        take(&mut col, 2, 4, 3);
        assert_eq!(col, [(0, 4)]);
        take(&mut col, 6, 8, 3);
        assert_eq!(col, [(0, 8)]);
        take(&mut col, 11, 12, 3);
        take(&mut col, 20, 22, 3);
        assert_eq!(col, [(0, 8), (11, 12), (20, 22)]);
        take(&mut col, 14, 18, 3);
        assert_eq!(col, [(0, 8), (11, 22)]);
        // Gaps: 3 rows at 8, then unbounded from 22.
        let g = gap_starts(&col);
        assert_eq!(&g[..3], &[8, 8, 22]);
        assert_eq!(gap_starts(&[]), [0; FIT_CLASSES]);
        assert_eq!(fit_class(1), 0);
        assert_eq!(fit_class(9), 3);
    }
}
