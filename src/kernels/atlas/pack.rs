//! Packing charts into a square atlas: each chart turned to its
//! minimum-area bounding rectangle lying flat, then placed by its outline
//! (the texel rows of each texel column it and its gutter reserve, in the
//! best of four quarter turns) on a column skyline, tallest first; a
//! bisection finds the largest common scale (texels per world unit) at
//! which all fit with the gutter. Packing bounding rectangles
//! ([`skyline_pack`]) left the corners of every disc-shaped chart empty:
//! 41 % filled on a 400 k-vertex scan where outlines reach 56 %.

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
/// turns) on a column skyline of `cols` block columns and `rows` block
/// rows: each goes where it sits highest (then leftmost, then first turn),
/// its top profile resting on the skyline, so charts nest into each
/// other's notches. Returns block positions and turns, or `None` when one
/// does not fit.
fn profile_pack(prints: &[[Footprint; 4]], cols: usize, rows: u32) -> Option<Vec<(u32, u32, u8)>> {
    let mut sky = vec![0u32; cols];
    let mut out = Vec::with_capacity(prints.len());
    for turns in prints {
        let mut best: Option<(u32, usize, u8)> = None;
        for (o, fp) in turns.iter().enumerate() {
            let w = fp.top.len();
            if w > cols {
                return None;
            }
            let height = fp.bottom.iter().copied().max().unwrap_or(0);
            for x in 0..=cols - w {
                let mut y = 0u32;
                let mut worse = false;
                for j in 0..w {
                    if fp.top[j] < fp.bottom[j] {
                        y = y.max(sky[x + j].saturating_sub(fp.top[j]));
                    }
                    if best.is_some_and(|(by, _, _)| y >= by) {
                        worse = true;
                        break;
                    }
                }
                if !worse && y + height <= rows {
                    best = Some((y, x, o as u8));
                }
            }
        }
        let (y, x, o) = best?;
        let fp = &turns[o as usize];
        for j in 0..fp.top.len() {
            if fp.top[j] < fp.bottom[j] {
                sky[x + j] = sky[x + j].max(y + fp.bottom[j]);
            }
        }
        out.push((x as u32, y, o));
    }
    Some(out)
}

/// Packs the charts into a `size × size` atlas (step 4 of the module docs):
/// returns per-face corner atlas coordinates and the scale in texels per
/// world unit. `None` when even the gutters alone do not fit.
///
/// Each chart is turned to its minimum-area rectangle lying flat; at a
/// trial scale its footprint (the texel rows each texel column of its
/// faces touches, grown by `padding_px` texels of gutter every way) is
/// placed, tallest first, on a column skyline in blocks of `size / 1024`
/// texels (at least 1). Charts rest on each other's actual outlines rather
/// than on bounding rectangles, so a disc-shaped chart leaves its corners
/// to the next. A bisection finds the largest scale at which all fit.
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
    let pack_at = |scale: f64| -> Option<Vec<(u32, u32, u8)>> {
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
        profile_pack(&prints, cols, rows)
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
    let mut best = pack_at(lo).map(|p| (lo, p))?;
    // To 0.1 % of the scale.
    while hi - lo > 1e-3 * hi {
        let mid = 0.5 * (lo + hi);
        match pack_at(mid) {
            Some(p) => {
                lo = mid;
                best = (mid, p);
            }
            None => hi = mid,
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
}
