//! The polygonal hull of a texture patch (Praun et al. 2000 §3.3, Fig. 4):
//! a polygon through the boundary pixels of the mask, conservatively
//! simplified (it may only grow) by prioritised edge collapses, so that
//! "does this mesh edge still reach into the texture patch?" is a cheap
//! segment-polygon test during patch growth.
//!
//! The initial polygon is the outline of the union of the inside pixels'
//! squares (so it contains every visible pixel entirely, not just its
//! centre). An edge collapse replaces the edge `b c` of the chain `a b c d`
//! by one vertex `p` that lies on the outer side of the three lines `a b`,
//! `b c` and `c d` (the 2-D form of the progressive hull constraints of
//! Sander et al. 2000): `p` is the meeting point of the extended neighbours
//! (`a b` ∩ `c d`), or `b` or `c` itself (the three cases of Fig. 4), whichever
//! is feasible and adds the least area. Collapses are applied cheapest first;
//! one that would make the polygon self-intersect is skipped.

use super::mask::Mask;
use glam::{DVec2, Vec2};

/// A simple counter-clockwise polygon, in patch units around the patch
/// centre (`s` right, `t` up).
#[derive(Clone, Debug, PartialEq)]
pub struct Hull {
    /// Vertices, counter-clockwise.
    pub vertices: Vec<Vec2>,
    /// Axis-aligned bounds `(min, max)`, for quick rejection.
    pub bounds: (Vec2, Vec2),
}

impl Hull {
    /// A hull from counter-clockwise vertices.
    pub fn new(vertices: Vec<Vec2>) -> Self {
        let lo = vertices
            .iter()
            .copied()
            .fold(Vec2::splat(f32::INFINITY), Vec2::min);
        let hi = vertices
            .iter()
            .copied()
            .fold(Vec2::splat(f32::NEG_INFINITY), Vec2::max);
        Self {
            vertices,
            bounds: (lo, hi),
        }
    }

    /// Enclosed area.
    pub fn area(&self) -> f32 {
        let v = &self.vertices;
        let n = v.len();
        0.5 * (0..n).map(|i| v[i].perp_dot(v[(i + 1) % n])).sum::<f32>()
    }

    /// Whether `p` is inside (points on the boundary may go either way).
    pub fn contains(&self, p: Vec2) -> bool {
        let (lo, hi) = self.bounds;
        if p.x < lo.x || p.y < lo.y || p.x > hi.x || p.y > hi.y {
            return false;
        }
        let v = &self.vertices;
        let n = v.len();
        let mut inside = false;
        let mut j = n - 1;
        for i in 0..n {
            let (a, b) = (v[i], v[j]);
            if (a.y > p.y) != (b.y > p.y) && p.x < (b.x - a.x) * (p.y - a.y) / (b.y - a.y) + a.x {
                inside = !inside;
            }
            j = i;
        }
        inside
    }

    /// Whether the segment `a b` reaches into the hull: an endpoint inside,
    /// or a crossing with the boundary (touching counts, conservatively).
    pub fn segment_intersects(&self, a: Vec2, b: Vec2) -> bool {
        let (lo, hi) = self.bounds;
        if a.x.max(b.x) < lo.x || a.y.max(b.y) < lo.y || a.x.min(b.x) > hi.x || a.y.min(b.y) > hi.y
        {
            return false;
        }
        if self.contains(a) || self.contains(b) {
            return true;
        }
        let v = &self.vertices;
        let n = v.len();
        (0..n).any(|i| {
            segments_touch(
                a.as_dvec2(),
                b.as_dvec2(),
                v[i].as_dvec2(),
                v[(i + 1) % n].as_dvec2(),
            )
        })
    }
}

/// The outlines of the pixel squares of `mask`'s inside pixels, in pixel
/// corner coordinates (x right, y down): outer loops run clockwise on
/// screen (positive shoelace area in these coordinates), holes the other
/// way. Diagonal-only contacts separate loops (4-connectivity). Collinear
/// corners are removed.
pub fn pixel_outlines(mask: &Mask) -> Vec<Vec<[i64; 2]>> {
    const DIRS: [[i64; 2]; 4] = [[1, 0], [0, 1], [-1, 0], [0, -1]];
    let (w, h) = (mask.width as i64, mask.height as i64);
    let cw = (w + 1) as usize;
    let corner = |x: i64, y: i64| (y as usize) * cw + x as usize;
    // Outgoing boundary edges per corner, one bit per direction.
    let mut out = vec![0u8; cw * (h + 1) as usize];
    for y in 0..h {
        for x in 0..w {
            if !mask.at(x, y) {
                continue;
            }
            if !mask.at(x, y - 1) {
                out[corner(x, y)] |= 1 << 0; // top side, going right
            }
            if !mask.at(x + 1, y) {
                out[corner(x + 1, y)] |= 1 << 1; // right side, going down
            }
            if !mask.at(x, y + 1) {
                out[corner(x + 1, y + 1)] |= 1 << 2; // bottom side, going left
            }
            if !mask.at(x - 1, y) {
                out[corner(x, y + 1)] |= 1 << 3; // left side, going up
            }
        }
    }
    let mut loops = Vec::new();
    // Start at corners with a single outgoing edge first: every loop has
    // one (its convex corners), and starting at a diagonal contact could
    // join two pieces there.
    for pass in 0..2 {
        for start in 0..out.len() {
            while out[start] != 0 && (pass == 1 || out[start].count_ones() == 1) {
                let (sx, sy) = ((start % cw) as i64, (start / cw) as i64);
                let mut d = out[start].trailing_zeros() as usize;
                out[start] &= !(1 << d);
                let mut pts = vec![[sx, sy]];
                let (mut x, mut y) = (sx + DIRS[d][0], sy + DIRS[d][1]);
                while (x, y) != (sx, sy) {
                    let bits = out[corner(x, y)];
                    // Hug the same pixel at a diagonal contact: turn, then
                    // straight, then the other turn.
                    let Some(next) = [(d + 1) % 4, d, (d + 3) % 4]
                        .into_iter()
                        .find(|&k| bits & (1 << k) != 0)
                    else {
                        break;
                    };
                    out[corner(x, y)] &= !(1 << next);
                    if next != d {
                        pts.push([x, y]);
                    }
                    d = next;
                    x += DIRS[d][0];
                    y += DIRS[d][1];
                }
                loops.push(remove_collinear(pts));
            }
        }
    }
    loops
}

fn remove_collinear(pts: Vec<[i64; 2]>) -> Vec<[i64; 2]> {
    let n = pts.len();
    if n < 3 {
        return pts;
    }
    (0..n)
        .filter(|&i| {
            let a = pts[(i + n - 1) % n];
            let b = pts[i];
            let c = pts[(i + 1) % n];
            (b[0] - a[0]) * (c[1] - b[1]) - (b[1] - a[1]) * (c[0] - b[0]) != 0
        })
        .map(|i| pts[i])
        .collect()
}

fn shoelace(pts: &[DVec2]) -> f64 {
    let n = pts.len();
    0.5 * (0..n)
        .map(|i| pts[i].perp_dot(pts[(i + 1) % n]))
        .sum::<f64>()
}

/// Counter-clockwise convex hull (Andrew's monotone chain).
fn convex_hull(mut pts: Vec<DVec2>) -> Vec<DVec2> {
    pts.sort_by(|a, b| a.x.total_cmp(&b.x).then(a.y.total_cmp(&b.y)));
    pts.dedup();
    if pts.len() < 3 {
        return pts;
    }
    let mut lower: Vec<DVec2> = Vec::new();
    for &p in &pts {
        while lower.len() >= 2
            && (lower[lower.len() - 1] - lower[lower.len() - 2])
                .perp_dot(p - lower[lower.len() - 2])
                <= 0.0
        {
            lower.pop();
        }
        lower.push(p);
    }
    let mut upper: Vec<DVec2> = Vec::new();
    for &p in pts.iter().rev() {
        while upper.len() >= 2
            && (upper[upper.len() - 1] - upper[upper.len() - 2])
                .perp_dot(p - upper[upper.len() - 2])
                <= 0.0
        {
            upper.pop();
        }
        upper.push(p);
    }
    lower.pop();
    upper.pop();
    lower.extend(upper);
    lower
}

/// The hull of `mask` (visible pixels inside) in patch units: centred on
/// `centre_px`, `unit_px` pixels per unit, `t` up, simplified to at most
/// `max_vertices` (at least 3) vertices. A mask of several pieces gets the
/// convex hull of all of them (still conservative).
///
/// # Panics
/// When the mask has no inside pixel.
pub fn mask_hull(mask: &Mask, centre_px: Vec2, unit_px: f32, max_vertices: usize) -> Hull {
    let loops = pixel_outlines(mask);
    let to_st = |p: &[i64; 2]| {
        DVec2::new(
            (p[0] as f64 - centre_px.x as f64) / unit_px as f64,
            (centre_px.y as f64 - p[1] as f64) / unit_px as f64,
        )
    };
    // Outer loops have positive area in pixel coordinates (y down).
    let outer: Vec<&Vec<[i64; 2]>> = loops
        .iter()
        .filter(|l| {
            let p: Vec<DVec2> = l
                .iter()
                .map(|q| DVec2::new(q[0] as f64, q[1] as f64))
                .collect();
            shoelace(&p) > 0.0
        })
        .collect();
    assert!(!outer.is_empty(), "mask_hull: the mask has no inside pixel");
    let mut poly: Vec<DVec2> = if outer.len() == 1 {
        outer[0].iter().map(to_st).collect()
    } else {
        convex_hull(outer.iter().flat_map(|l| l.iter().map(to_st)).collect())
    };
    if shoelace(&poly) < 0.0 {
        poly.reverse();
    }
    let simplified = simplify_conservative(poly, max_vertices);
    Hull::new(simplified.iter().map(|p| p.as_vec2()).collect())
}

/// The best collapse of edge `(i, i + 1)` of the counter-clockwise polygon
/// `p`: `(added area, new vertex)`, or `None` when no feasible vertex exists.
fn collapse(p: &[DVec2], i: usize) -> Option<(f64, DVec2)> {
    let n = p.len();
    let a = p[(i + n - 1) % n];
    let b = p[i];
    let c = p[(i + 1) % n];
    let d = p[(i + 2) % n];
    let scale = (c - b).length().max((b - a).length()).max((d - c).length());
    let eps = 1e-9 * scale * scale.max(1e-300);
    let outside = |x: DVec2| {
        (b - a).perp_dot(x - a) <= eps
            && (c - b).perp_dot(x - b) <= eps
            && (d - c).perp_dot(x - c) <= eps
    };
    let old = a.perp_dot(b) + b.perp_dot(c) + c.perp_dot(d);
    let added = |x: DVec2| 0.5 * (a.perp_dot(x) + x.perp_dot(d) - old);
    let mut candidates = vec![b, c];
    let (u, v) = (b - a, d - c);
    let denom = u.perp_dot(v);
    if denom.abs() > 1e-12 * u.length() * v.length() {
        let s = (c - a).perp_dot(v) / denom;
        candidates.push(a + u * s);
    }
    candidates
        .into_iter()
        .filter(|&x| x.is_finite() && outside(x))
        .map(|x| (added(x), x))
        .filter(|&(cost, _)| cost >= -eps)
        .min_by(|x, y| x.0.total_cmp(&y.0))
}

/// Whether the closed segments `a b` and `c d` share a point.
fn segments_touch(a: DVec2, b: DVec2, c: DVec2, d: DVec2) -> bool {
    let o1 = (b - a).perp_dot(c - a);
    let o2 = (b - a).perp_dot(d - a);
    let o3 = (d - c).perp_dot(a - c);
    let o4 = (d - c).perp_dot(b - c);
    let on = |p: DVec2, q: DVec2, r: DVec2| {
        r.x >= p.x.min(q.x) && r.x <= p.x.max(q.x) && r.y >= p.y.min(q.y) && r.y <= p.y.max(q.y)
    };
    if ((o1 > 0.0 && o2 < 0.0) || (o1 < 0.0 && o2 > 0.0))
        && ((o3 > 0.0 && o4 < 0.0) || (o3 < 0.0 && o4 > 0.0))
    {
        return true;
    }
    (o1 == 0.0 && on(a, b, c))
        || (o2 == 0.0 && on(a, b, d))
        || (o3 == 0.0 && on(c, d, a))
        || (o4 == 0.0 && on(c, d, b))
}

/// Whether replacing edge `(i, i + 1)` of `p` by vertex `x` keeps the
/// polygon simple: the new edges `a x` and `x d` touch no other edge.
fn collapse_is_simple(p: &[DVec2], i: usize, x: DVec2) -> bool {
    let n = p.len();
    let ia = (i + n - 1) % n;
    let id = (i + 2) % n;
    let (a, d) = (p[ia], p[id]);
    for j in 0..n {
        let (e0, e1) = (j, (j + 1) % n);
        // Edges being replaced.
        if e0 == ia || e0 == i || e0 == (i + 1) % n {
            continue;
        }
        let (q0, q1) = (p[e0], p[e1]);
        // The edge ending at `a` may touch `a x` at `a` only; likewise at `d`.
        let touches_ax = if e1 == ia {
            segments_touch(a, x, q0, q1) && (x - a).perp_dot(q0 - a) == 0.0 && {
                // Collinear and overlapping beyond the shared endpoint.
                (x - a).dot(q0 - a) > 0.0
            }
        } else {
            segments_touch(a, x, q0, q1)
        };
        let touches_xd = if e0 == id {
            segments_touch(x, d, q0, q1) && (x - d).perp_dot(q1 - d) == 0.0 && {
                (x - d).dot(q1 - d) > 0.0
            }
        } else {
            segments_touch(x, d, q0, q1)
        };
        if touches_ax || touches_xd {
            return false;
        }
    }
    true
}

/// Conservative simplification of a simple counter-clockwise polygon to at
/// most `max_vertices` (at least 3) vertices: cheapest feasible collapse
/// first, never self-intersecting. Stops early when no collapse is feasible.
pub fn simplify_conservative(mut p: Vec<DVec2>, max_vertices: usize) -> Vec<DVec2> {
    let target = max_vertices.max(3);
    // Each edge's best collapse, kept up to date: a collapse changes only
    // the four options whose edge windows hold the moved vertex.
    let mut options: Vec<Option<(f64, DVec2)>> = (0..p.len()).map(|i| collapse(&p, i)).collect();
    let mut order: Vec<(f64, usize, DVec2)> = Vec::new();
    while p.len() > target {
        // The cheapest option (ties to the lower index); the others in
        // order only when it would make the polygon self-intersect.
        let first = options
            .iter()
            .enumerate()
            .filter_map(|(i, o)| o.map(|(cost, x)| (cost, i, x)))
            .min_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)));
        let Some(first) = first else {
            break;
        };
        let chosen = if collapse_is_simple(&p, first.1, first.2) {
            Some(first)
        } else {
            order.clear();
            order.extend(
                options
                    .iter()
                    .enumerate()
                    .filter_map(|(i, o)| o.map(|(cost, x)| (cost, i, x))),
            );
            order.sort_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)));
            order
                .iter()
                .skip(1)
                .find(|&&(_, i, x)| collapse_is_simple(&p, i, x))
                .copied()
        };
        let Some((_, i, x)) = chosen else {
            break;
        };
        let n = p.len();
        let removed = (i + 1) % n;
        p[i] = x;
        p.remove(removed);
        options.remove(removed);
        let m = p.len();
        let moved = if removed < i { i - 1 } else { i };
        for d in 0..4 {
            let j = (moved + m + d - 2) % m;
            options[j] = collapse(&p, j);
        }
    }
    p
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kernels::lapped::mask::{circle_mask, splotch_mask};

    fn corners_inside(mask: &Mask, hull: &Hull, centre: Vec2, unit: f32) -> bool {
        // Every corner of every inside pixel square is inside or on the hull.
        let tol = 1e-4;
        for y in 0..mask.height as i64 {
            for x in 0..mask.width as i64 {
                if !mask.at(x, y) {
                    continue;
                }
                for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                    let p = Vec2::new(
                        ((x + dx) as f32 - centre.x) / unit,
                        (centre.y - (y + dy) as f32) / unit,
                    );
                    let nudged = [Vec2::ZERO, Vec2::X, Vec2::Y, -Vec2::X, -Vec2::Y]
                        .iter()
                        .any(|d| hull.contains(p + *d * tol));
                    if !nudged {
                        return false;
                    }
                }
            }
        }
        true
    }

    #[test]
    fn outline_of_two_pixels_and_a_diagonal_pair() {
        let m = Mask {
            width: 3,
            height: 2,
            inside: vec![true, true, false, false, false, true],
        };
        let loops = pixel_outlines(&m);
        // The 2x1 bar and the diagonal pixel are separate loops (4-connected).
        assert_eq!(loops.len(), 2, "{loops:?}");
        assert!(loops.iter().all(|l| l.len() == 4), "{loops:?}");
    }

    #[test]
    fn simplified_hulls_contain_the_mask_and_are_small() {
        for (name, mask) in [
            ("circle", circle_mask(64)),
            ("splotch", splotch_mask(64, 9)),
            ("splotch2", splotch_mask(128, 4)),
        ] {
            let centre = Vec2::new(mask.width as f32 / 2.0, mask.height as f32 / 2.0);
            let unit = mask.width as f32;
            let hull = mask_hull(&mask, centre, unit, 16);
            assert!(hull.vertices.len() <= 16, "{name}: {}", hull.vertices.len());
            assert!(hull.area() > 0.0, "{name}: counter-clockwise");
            assert!(corners_inside(&mask, &hull, centre, unit), "{name}");
            let mask_area = mask.count() as f32 / (unit * unit);
            assert!(
                hull.area() < 1.35 * mask_area,
                "{name}: hull area {} vs mask {mask_area}",
                hull.area()
            );
            // Still simple: no two non-adjacent edges touch.
            let v: Vec<DVec2> = hull.vertices.iter().map(|p| p.as_dvec2()).collect();
            let n = v.len();
            for i in 0..n {
                for j in i + 2..n {
                    if i == 0 && j == n - 1 {
                        continue;
                    }
                    assert!(
                        !segments_touch(v[i], v[(i + 1) % n], v[j], v[(j + 1) % n]),
                        "{name}: edges {i} and {j} intersect"
                    );
                }
            }
        }
    }

    #[test]
    fn segment_test() {
        let h = Hull::new(vec![
            Vec2::new(-1.0, -1.0),
            Vec2::new(1.0, -1.0),
            Vec2::new(1.0, 1.0),
            Vec2::new(-1.0, 1.0),
        ]);
        assert!(h.segment_intersects(Vec2::new(-2.0, 0.0), Vec2::new(2.0, 0.0)));
        assert!(h.segment_intersects(Vec2::new(0.0, 0.0), Vec2::new(5.0, 5.0)));
        assert!(!h.segment_intersects(Vec2::new(-2.0, 1.5), Vec2::new(2.0, 1.5)));
        assert!(!h.segment_intersects(Vec2::new(2.0, -3.0), Vec2::new(3.0, 3.0)));
    }
}
