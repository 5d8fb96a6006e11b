//! Triangle setup, binning into horizontal strips and z-buffer rasterisation.
//!
//! Vertices are snapped to a fixed-point grid with [`SUBPIXEL`] steps per
//! pixel and edge functions are evaluated exactly in `i64`, with the top-left
//! fill rule: a sample on an edge shared by two triangles belongs to exactly
//! one of them, so there are neither cracks nor double hits between
//! triangles. Depth is `1 / view depth`, which is affine in screen space.

use super::camera::Camera;
use glam::Vec3;
use rayon::prelude::*;

/// Fixed-point sub-pixel steps per pixel.
pub(crate) const SUBPIXEL: i64 = 256;
const HALF: i64 = SUBPIXEL / 2;
/// Snapped coordinates beyond this magnitude are rejected so the edge
/// functions (products of two coordinates) cannot overflow.
const LIMIT: f32 = (1u32 << 26) as f32;

/// A triangle ready for rasterisation, oriented so that its screen-space
/// edge functions are non-negative inside.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Tri {
    /// Snapped vertex x coordinates (pixels × [`SUBPIXEL`]).
    pub x: [i32; 3],
    /// Snapped vertex y coordinates (pixels × [`SUBPIXEL`], downward).
    pub y: [i32; 3],
    /// `1 / view depth` at each vertex.
    pub inv_w: [f32; 3],
    /// Mesh corners of the three vertices, in the order above.
    pub corners: [u32; 3],
    /// Index into the mesh's fan triangulation (for its face).
    pub source: u32,
    /// True when the triangle's own winding faces away from the camera, so
    /// its normal must be flipped for two-sided lighting.
    pub back: bool,
    /// Inclusive pixel bounds of the covered sample centres: x0, y0, x1, y1.
    pub bounds: [i32; 4],
}

/// The exact edge function of `a → b` at `p` (twice the signed area).
#[inline]
fn edge(ax: i64, ay: i64, bx: i64, by: i64, px: i64, py: i64) -> i64 {
    (bx - ax) * (py - ay) - (by - ay) * (px - ax)
}

/// Top-left rule as a tie-break on the edge direction: exactly one of the two
/// opposite directions of a shared edge owns the samples lying on it.
#[inline]
fn owns_boundary(dx: i64, dy: i64) -> bool {
    dy < 0 || (dy == 0 && dx > 0)
}

impl Tri {
    /// The three edge functions at sample `(px, py)` (pixel indices), the
    /// `i`-th being zero on the edge opposite vertex `i`. Their sum is twice
    /// the triangle's area.
    #[inline]
    pub fn weights(&self, px: i32, py: i32) -> [i64; 3] {
        let sx = px as i64 * SUBPIXEL + HALF;
        let sy = py as i64 * SUBPIXEL + HALF;
        let (x, y) = (self.x.map(i64::from), self.y.map(i64::from));
        [
            edge(x[1], y[1], x[2], y[2], sx, sy),
            edge(x[2], y[2], x[0], y[0], sx, sy),
            edge(x[0], y[0], x[1], y[1], sx, sy),
        ]
    }
}

/// A vertex projected to the screen: sub-pixel x, y and `1 / view depth`;
/// `None` behind the camera or too far off-screen to snap.
pub(crate) type Projected = Option<(f32, f32, f32)>;

/// Projects every vertex for [`setup`] (16 bytes per vertex, one view).
pub(crate) fn project(positions: &[Vec3], camera: &Camera) -> Vec<Projected> {
    positions
        .par_iter()
        .map(|&p| {
            camera.project(p).filter(|&(x, y, _)| {
                (x * SUBPIXEL as f32).abs() < LIMIT && (y * SUBPIXEL as f32).abs() < LIMIT
            })
        })
        .collect()
}

/// Sets up triangle `t` of the fan triangulation (`corners`, mesh corners)
/// when it is in front of the camera, not degenerate on screen and covers at
/// least one sample of a `width`×`height` grid. `projected` comes from
/// [`project`]. Deterministic, so a triangle can be set up again where it is
/// drawn instead of being kept between binning and drawing.
#[allow(clippy::too_many_arguments)]
pub(crate) fn setup(
    t: u32,
    corners: [u32; 3],
    projected: &[Projected],
    positions: &[Vec3],
    corner_vertex: &[u32],
    camera: &Camera,
    width: u32,
    height: u32,
) -> Option<Tri> {
    let v = corners.map(|c| corner_vertex[c as usize] as usize);
    let p = [projected[v[0]]?, projected[v[1]]?, projected[v[2]]?];
    let snap = |f: f32| (f * SUBPIXEL as f32).round() as i32;
    let mut x = p.map(|q| snap(q.0));
    let mut y = p.map(|q| snap(q.1));
    let mut inv_w = p.map(|q| q.2);
    let mut corners = corners;
    let area = edge(
        x[0] as i64,
        y[0] as i64,
        x[1] as i64,
        y[1] as i64,
        x[2] as i64,
        y[2] as i64,
    );
    if area == 0 {
        return None;
    }
    if area < 0 {
        x.swap(1, 2);
        y.swap(1, 2);
        inv_w.swap(1, 2);
        corners.swap(1, 2);
    }
    // Pixels whose sample centre lies in the snapped bounding box.
    let lo = |m: i32| (m as i64 - HALF + SUBPIXEL - 1).div_euclid(SUBPIXEL) as i32;
    let hi = |m: i32| (m as i64 - HALF).div_euclid(SUBPIXEL) as i32;
    let (xmin, xmax) = (x.iter().min()?, x.iter().max()?);
    let (ymin, ymax) = (y.iter().min()?, y.iter().max()?);
    let bounds = [
        lo(*xmin).max(0),
        lo(*ymin).max(0),
        hi(*xmax).min(width as i32 - 1),
        hi(*ymax).min(height as i32 - 1),
    ];
    if bounds[0] > bounds[2] || bounds[1] > bounds[3] {
        return None;
    }
    let world = v.map(|i| positions[i]);
    let normal = (world[1] - world[0]).cross(world[2] - world[0]);
    let back = normal.dot(camera.eye - world[0]) < 0.0;
    Some(Tri {
        x,
        y,
        inv_w,
        corners,
        source: t,
        back,
        bounds,
    })
}

/// Triangles per strip of `strip_rows` rows, each list in triangle order:
/// CSR offsets (`strips + 1` entries) and triangle indices (into the fan
/// triangulation, not set-up data: `rows(t)` gives the inclusive pixel rows
/// of triangle `t`, `None` when it is not drawn). `count` triangles.
pub(crate) fn bin_strips(
    count: usize,
    rows: impl Fn(u32) -> Option<(i32, i32)> + Sync,
    strip_rows: i32,
    strips: usize,
) -> (Vec<u32>, Vec<u32>) {
    // First and last strip of each triangle (8 bytes per triangle, dropped
    // before the strips are drawn); an empty range when it is not drawn.
    let ranges: Vec<[u32; 2]> = (0..count as u32)
        .into_par_iter()
        .map(|t| match rows(t) {
            Some((y0, y1)) => [
                (y0 / strip_rows) as u32,
                ((y1 / strip_rows) as u32).min(strips as u32 - 1),
            ],
            None => [1, 0],
        })
        .collect();
    let mut start = vec![0u32; strips + 1];
    for r in &ranges {
        for s in r[0]..=r[1] {
            start[s as usize + 1] += 1;
        }
    }
    for s in 0..strips {
        start[s + 1] += start[s];
    }
    let mut fill = start.clone();
    let mut items = vec![0u32; start[strips] as usize];
    for (i, r) in ranges.iter().enumerate() {
        for s in r[0]..=r[1] {
            items[fill[s as usize] as usize] = i as u32;
            fill[s as usize] += 1;
        }
    }
    (start, items)
}

/// Rasterises `tris` (in that order) into the rows `row0..row0 + rows` of a `width`-wide z-buffer: `depth`
/// holds `1 / view depth` (0 = empty, larger is nearer) and `id` the index of
/// the nearest triangle in `tris` (`u32::MAX` = empty). Equal depths keep
/// the earlier triangle, so the result depends only on the order of `tris`.
pub(crate) fn raster_strip(
    tris: &[Tri],
    row0: i32,
    rows: i32,
    width: usize,
    depth: &mut [f32],
    id: &mut [u32],
) {
    depth.fill(0.0);
    id.fill(u32::MAX);
    for (ti, t) in tris.iter().enumerate() {
        let y_lo = t.bounds[1].max(row0);
        let y_hi = t.bounds[3].min(row0 + rows - 1);
        if y_lo > y_hi {
            continue;
        }
        let (x_lo, x_hi) = (t.bounds[0], t.bounds[2]);
        let (x, y) = (t.x.map(i64::from), t.y.map(i64::from));
        // Edge i runs from vertex i+1 to vertex i+2 (opposite vertex i).
        let mut step_x = [0i64; 3];
        let mut step_y = [0i64; 3];
        let mut bias = [0i64; 3];
        for i in 0..3 {
            let (a, b) = ((i + 1) % 3, (i + 2) % 3);
            let (dx, dy) = (x[b] - x[a], y[b] - y[a]);
            step_x[i] = -dy * SUBPIXEL;
            step_y[i] = dx * SUBPIXEL;
            bias[i] = if owns_boundary(dx, dy) { 0 } else { -1 };
        }
        let w0 = t.weights(x_lo, y_lo);
        let mut row_e = [w0[0] + bias[0], w0[1] + bias[1], w0[2] + bias[2]];
        let area = (w0[0] + w0[1] + w0[2]) as f32;
        let k = t.inv_w.map(|iw| iw / area);
        let t_id = ti as u32;
        for py in y_lo..=y_hi {
            let off = (py - row0) as usize * width;
            let drow = &mut depth[off..off + width];
            let irow = &mut id[off..off + width];
            let mut e = row_e;
            for px in x_lo..=x_hi {
                if (e[0] | e[1] | e[2]) >= 0 {
                    let z = e[0] as f32 * k[0] + e[1] as f32 * k[1] + e[2] as f32 * k[2];
                    let px = px as usize;
                    if z > drow[px] {
                        drow[px] = z;
                        irow[px] = t_id;
                    }
                }
                e[0] += step_x[0];
                e[1] += step_x[1];
                e[2] += step_x[2];
            }
            row_e[0] += step_y[0];
            row_e[1] += step_y[1];
            row_e[2] += step_y[2];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tri(x: [i32; 3], y: [i32; 3]) -> Tri {
        let s = SUBPIXEL as i32;
        Tri {
            x: x.map(|v| v * s),
            y: y.map(|v| v * s),
            inv_w: [1.0; 3],
            corners: [0, 1, 2],
            source: 0,
            back: false,
            bounds: [0, 0, 7, 7],
        }
    }

    /// Two triangles sharing a diagonal through sample centres cover every
    /// sample of a square exactly once.
    #[test]
    fn shared_edges_have_no_cracks_or_overlaps() {
        // Vertices at half-pixel offsets put the diagonal through centres.
        let h = HALF as i32;
        let mut a = tri([0, 8, 8], [0, 0, 8]);
        let mut b = tri([0, 8, 0], [0, 8, 8]);
        for t in [&mut a, &mut b] {
            t.x = t.x.map(|v| v + h);
            t.y = t.y.map(|v| v + h);
            // Orient positively, as `setup` does.
            let area = edge(
                t.x[0] as i64,
                t.y[0] as i64,
                t.x[1] as i64,
                t.y[1] as i64,
                t.x[2] as i64,
                t.y[2] as i64,
            );
            if area < 0 {
                t.x.swap(1, 2);
                t.y.swap(1, 2);
            }
        }
        let tris = [a, b];
        let mut count = [0u32; 64];
        for i in 0..tris.len() {
            let mut depth = [0.0f32; 64];
            let mut id = [0u32; 64];
            raster_strip(&tris[i..i + 1], 0, 8, 8, &mut depth, &mut id);
            for (c, &d) in count.iter_mut().zip(&id) {
                *c += (d != u32::MAX) as u32;
            }
        }
        // Samples 1..8 in each direction lie inside the square (0.5..8.5).
        for y in 1..8 {
            for x in 1..8 {
                assert_eq!(count[y * 8 + x], 1, "sample ({x}, {y})");
            }
        }
    }
}
