//! Packing charts into a square atlas: each chart turned to its
//! minimum-area bounding rectangle lying flat, rectangles sorted by height
//! and placed by a bottom-left skyline packer; a binary search finds the
//! largest common scale (texels per world unit) at which all fit with the
//! gutter.

use super::Charts;
use glam::{DVec2, Vec2};

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

/// Packs the charts into a `size × size` atlas (step 2 of the module docs):
/// returns per-face corner atlas coordinates and the scale in texels per
/// world unit. `None` when even the gutters alone do not fit.
pub fn pack_charts(charts: &Charts, size: u32, padding_px: u32) -> Option<(Vec<[Vec2; 3]>, f32)> {
    let _span = tracing::debug_span!("pack_charts", charts = charts.count).entered();
    let n = charts.count;
    let mut points: Vec<Vec<DVec2>> = vec![Vec::new(); n];
    for (f, st) in charts.corner_st.iter().enumerate() {
        let c = charts.chart_of_face[f] as usize;
        points[c].extend(st.iter().map(|p| p.as_dvec2()));
    }
    // Turn every chart flat and move it to the origin.
    let mut placed: Vec<(DVec2, DVec2, DVec2)> = Vec::with_capacity(n); // (rot, min, size)
    for pts in &points {
        let rot = flat_min_area_rotation(pts);
        let (mut lo, mut hi) = (DVec2::splat(f64::INFINITY), DVec2::splat(f64::NEG_INFINITY));
        for p in pts {
            let q = DVec2::new(rot.x * p.x - rot.y * p.y, rot.y * p.x + rot.x * p.y);
            lo = lo.min(q);
            hi = hi.max(q);
        }
        placed.push((rot, lo, (hi - lo).max(DVec2::ZERO)));
    }
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&a, &b| {
        placed[b]
            .2
            .y
            .total_cmp(&placed[a].2.y)
            .then(placed[b].2.x.total_cmp(&placed[a].2.x))
            .then(a.cmp(&b))
    });
    let pad = 2 * padding_px;
    let rects_at = |scale: f64| -> Vec<(u32, u32)> {
        order
            .iter()
            .map(|&c| {
                let s = placed[c].2 * scale;
                (s.x.ceil() as u32 + pad + 1, s.y.ceil() as u32 + pad + 1)
            })
            .collect()
    };
    let largest = placed
        .iter()
        .map(|p| p.2.x.max(p.2.y))
        .fold(0.0f64, f64::max)
        .max(1e-12);
    let (mut lo, mut hi) = (0.0f64, size as f64 / largest);
    let mut best = skyline_pack(&rects_at(lo), size).map(|p| (lo, p))?;
    for _ in 0..40 {
        let mid = 0.5 * (lo + hi);
        match skyline_pack(&rects_at(mid), size) {
            Some(p) => {
                lo = mid;
                best = (mid, p);
            }
            None => hi = mid,
        }
    }
    let (scale, positions) = best;
    let mut corner = vec![DVec2::ZERO; n];
    for (k, &c) in order.iter().enumerate() {
        corner[c] = DVec2::new(positions[k].0 as f64, positions[k].1 as f64);
    }
    let inv = 1.0 / size as f64;
    let uvs = charts
        .corner_st
        .iter()
        .enumerate()
        .map(|(f, st)| {
            let c = charts.chart_of_face[f] as usize;
            let (rot, min, extent) = placed[c];
            st.map(|p| {
                let p = p.as_dvec2();
                let q = DVec2::new(rot.x * p.x - rot.y * p.y, rot.y * p.x + rot.x * p.y) - min;
                // t up in the chart is up in the image (y down).
                let px = corner[c].x + padding_px as f64 + 0.5 + q.x * scale;
                let py = corner[c].y + padding_px as f64 + 0.5 + (extent.y - q.y) * scale;
                Vec2::new((px * inv) as f32, (py * inv) as f32)
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
