//! Rasterising a mesh that lies flat in the xy plane into a pixel grid over
//! its xy bounding box: per pixel, the triangle whose interior contains the
//! pixel centre and the centre's barycentric weights. The `plane` output of
//! the `export` stage samples any result (vertex colours, corner UVs, lapped
//! pastes) through it, so every method's result becomes an image.
//!
//! Grid convention: pixel `(i, j)` (column `i`, row `j`, row 0 at the top)
//! has its centre at `x = min.x + i / (width − 1) · (max.x − min.x)`,
//! `y = max.y − j / (height − 1) · (max.y − min.y)`: the pixel centres span
//! the box from edge to edge, and image-up is `+y`, so a texture synthesised
//! with frames `s = +x`, `t = +y` appears upright. Centres on the box's
//! edges rather than half a pixel inside: on an `N × N`-vertex grid of side
//! `N − 1` every pixel centre is a vertex, so a pixel reads its vertex's
//! colour, or its vertex's texel centre through the corner UVs, instead of
//! an average of two vertices or of four texels (which a half-pixel inset
//! gives, a 2 × 2 blur of every result).

use glam::{Vec2, Vec3};

/// The pixel grid laid over an xy box.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlaneGrid {
    /// Columns.
    pub width: u32,
    /// Rows.
    pub height: u32,
    /// Lower-left corner of the box (world units).
    pub min: Vec2,
    /// Upper-right corner of the box (world units).
    pub max: Vec2,
}

impl PlaneGrid {
    /// The grid of `width × height` pixels over the xy bounding box of `positions`.
    pub fn over(positions: &[Vec3], width: u32, height: u32) -> Self {
        let mut min = Vec2::splat(f32::INFINITY);
        let mut max = Vec2::splat(f32::NEG_INFINITY);
        for p in positions {
            min = min.min(p.truncate());
            max = max.max(p.truncate());
        }
        if positions.is_empty() {
            (min, max) = (Vec2::ZERO, Vec2::ONE);
        }
        Self {
            width,
            height,
            min,
            max,
        }
    }

    /// The grid of `width × height` pixels `pixel` world units apart, pixel
    /// `(0, 0)` on the top-left corner of `positions`' xy bounding box
    /// (`min.x`, `max.y`): pixel `(i, j)` at `(min.x + i·pixel, max.y −
    /// j·pixel)`, whatever the box's size (pixels beyond the mesh are
    /// outside). On a grid of vertices `pixel` apart every pixel centre is a
    /// vertex, even where the box is not `(width − 1) · pixel` wide.
    /// `pixel ≤ 0` (or NaN) spans the box instead ([`PlaneGrid::over`]).
    pub fn at_spacing(positions: &[Vec3], width: u32, height: u32, pixel: f32) -> Self {
        let bounds = Self::over(positions, width, height);
        if pixel.is_nan() || pixel <= 0.0 {
            return bounds;
        }
        let span = |n: u32| n.saturating_sub(1).max(1) as f32 * pixel;
        Self {
            min: Vec2::new(bounds.min.x, bounds.max.y - span(height)),
            max: Vec2::new(bounds.min.x + span(width), bounds.max.y),
            ..bounds
        }
    }

    /// Pixel steps across the box (one pixel: the centre of the box).
    fn steps(&self) -> Vec2 {
        Vec2::new(
            self.width.saturating_sub(1).max(1) as f32,
            self.height.saturating_sub(1).max(1) as f32,
        )
    }

    /// The world xy position of pixel `(i, j)`'s centre.
    pub fn centre(&self, i: u32, j: u32) -> Vec2 {
        let e = self.max - self.min;
        let n = self.steps();
        let (fi, fj) = match (self.width, self.height) {
            (1, _) | (_, 1) => (0.5 * n.x, 0.5 * n.y),
            _ => (i as f32, j as f32),
        };
        Vec2::new(self.min.x + fi / n.x * e.x, self.max.y - fj / n.y * e.y)
    }

    /// A world xy point in continuous pixel coordinates (pixel `(i, j)`'s
    /// centre at `(i + 0.5, j + 0.5)`).
    fn pixel_of(&self, p: Vec2) -> Vec2 {
        let e = (self.max - self.min).max(Vec2::splat(f32::MIN_POSITIVE));
        let n = self.steps();
        // One pixel on an axis: its centre is the box's middle.
        let offset = |size: u32| if size == 1 { 0.0 } else { 0.5 };
        Vec2::new(
            (p.x - self.min.x) / e.x * n.x + offset(self.width),
            (self.max.y - p.y) / e.y * n.y + offset(self.height),
        )
    }
}

/// Where a pixel centre landed: the triangle (index into the caller's list)
/// and the barycentric weights of its three corners (summing to 1).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PixelHit {
    /// Triangle index.
    pub triangle: u32,
    /// Weights of the triangle's corners, in its corner order.
    pub weights: [f32; 3],
}

/// Why a mesh cannot be rasterised as a plane.
pub fn check_planar_xy(positions: &[Vec3]) -> Result<(), String> {
    if positions.is_empty() {
        return Err("it has no vertices".into());
    }
    let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
    for p in positions {
        lo = lo.min(*p);
        hi = hi.max(*p);
    }
    let e = hi - lo;
    let extent = e.x.min(e.y);
    if extent.is_nan() || extent <= 0.0 || !extent.is_finite() {
        return Err(format!(
            "its xy bounding box is degenerate ({} × {} world units)",
            e.x, e.y
        ));
    }
    // A relative tolerance: float noise of a computed plane is fine, a bump is not.
    if e.z > 1e-4 * e.x.max(e.y) {
        return Err(format!(
            "its z spans {} .. {} ({} world units against an xy extent of {} × {}); allowed: every z equal within 1e-4 of the larger xy extent",
            lo.z, hi.z, e.z, e.x, e.y
        ));
    }
    Ok(())
}

/// Per pixel of `grid` (row-major), the triangle containing its centre, or
/// `None` outside the mesh. Each triangle is rasterised over the pixels of
/// its own bounding box (no per-pixel search), so the cost is the number of
/// triangles plus the number of pixels. A centre on a shared edge goes to
/// the first triangle in `triangles` that contains it (a tolerance of 1e-5
/// of the triangle closes cracks from rounding), so the result does not
/// depend on thread count or order of evaluation. Triangles with zero xy
/// area are skipped. The mesh should be flat in xy ([`check_planar_xy`]);
/// z is ignored.
pub fn rasterise_xy(
    positions: &[Vec3],
    triangles: &[[u32; 3]],
    grid: &PlaneGrid,
) -> Vec<Option<PixelHit>> {
    let (w, h) = (grid.width as i64, grid.height as i64);
    let mut hits: Vec<Option<PixelHit>> = vec![None; (w * h).max(0) as usize];
    for (t, tri) in triangles.iter().enumerate() {
        let Some(corners) = tri
            .iter()
            .map(|&v| {
                positions
                    .get(v as usize)
                    .map(|p| grid.pixel_of(p.truncate()))
            })
            .collect::<Option<Vec<Vec2>>>()
        else {
            continue;
        };
        let [a, b, c] = [corners[0], corners[1], corners[2]];
        let area = (b - a).perp_dot(c - a);
        if area.abs() <= f32::EPSILON * (b - a).length_squared().max(1e-30) {
            continue;
        }
        let lo = a.min(b).min(c);
        let hi = a.max(b).max(c);
        // Pixel i's centre is at i + 0.5.
        let i0 = ((lo.x - 0.5).ceil() as i64).max(0);
        let i1 = ((hi.x - 0.5).floor() as i64).min(w - 1);
        let j0 = ((lo.y - 0.5).ceil() as i64).max(0);
        let j1 = ((hi.y - 0.5).floor() as i64).min(h - 1);
        let tol = -1e-5;
        for j in j0..=j1 {
            for i in i0..=i1 {
                let slot = &mut hits[(j * w + i) as usize];
                if slot.is_some() {
                    continue;
                }
                let p = Vec2::new(i as f32 + 0.5, j as f32 + 0.5);
                let wa = (b - p).perp_dot(c - p) / area;
                let wb = (c - p).perp_dot(a - p) / area;
                let wc = 1.0 - wa - wb;
                if wa >= tol && wb >= tol && wc >= tol {
                    *slot = Some(PixelHit {
                        triangle: t as u32,
                        weights: [wa, wb, wc],
                    });
                }
            }
        }
    }
    hits
}

/// Index of the largest of three weights (the nearest corner); ties go to the
/// first.
pub fn dominant_corner(w: [f32; 3]) -> usize {
    let mut best = 0;
    for k in 1..3 {
        if w[k] > w[best] {
            best = k;
        }
    }
    best
}

/// A source coordinate in exemplar pixels wrapped into `[0, size)` and
/// snapped to its pixel's centre (`floor + 0.5`); NaN stays NaN.
pub fn snap_source(p: Vec2, width: u32, height: u32) -> [f32; 2] {
    let snap = |v: f32, n: u32| {
        if !v.is_finite() {
            return f32::NAN;
        }
        let n = n.max(1) as f32;
        (v.rem_euclid(n).floor()).min(n - 1.0) + 0.5
    };
    [snap(p.x, width), snap(p.y, height)]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square() -> (Vec<Vec3>, Vec<[u32; 3]>) {
        (
            vec![
                Vec3::new(0.0, 0.0, 0.0),
                Vec3::new(2.0, 0.0, 0.0),
                Vec3::new(2.0, 1.0, 0.0),
                Vec3::new(0.0, 1.0, 0.0),
            ],
            vec![[0, 1, 2], [0, 2, 3]],
        )
    }

    #[test]
    fn every_pixel_of_a_square_is_covered_and_weights_reproduce_the_centre() {
        let (pos, tris) = square();
        let grid = PlaneGrid::over(&pos, 16, 8);
        let hits = rasterise_xy(&pos, &tris, &grid);
        for j in 0..8 {
            for i in 0..16 {
                let hit = hits[(j * 16 + i) as usize].expect("covered");
                let t = tris[hit.triangle as usize];
                let p: Vec2 = (0..3)
                    .map(|k| pos[t[k] as usize].truncate() * hit.weights[k])
                    .sum();
                assert!((p - grid.centre(i, j)).length() < 1e-5, "pixel {i},{j}");
            }
        }
        // Row 0 is the top (max y).
        assert!(grid.centre(0, 0).y > grid.centre(0, 7).y);
    }

    #[test]
    fn a_bump_in_z_is_refused_and_snapping_wraps() {
        let (mut pos, _) = square();
        assert!(check_planar_xy(&pos).is_ok());
        pos[2].z = 0.1;
        assert!(check_planar_xy(&pos).unwrap_err().contains("z spans"));
        assert_eq!(snap_source(Vec2::new(-0.5, 9.9), 8, 8), [7.5, 1.5]);
        assert_eq!(dominant_corner([0.2, 0.5, 0.3]), 1);
    }
}
