//! Texel-level work on atlas triangles: overlap tests, barycentric
//! coordinates, rasterising faces to texel centres, and dilating chart
//! texels into the gutters.

use glam::Vec2;
use rayon::prelude::*;
use std::collections::HashMap;

/// Twice the signed area of a 2-D triangle (positive counter-clockwise in a
/// y-up frame).
#[inline]
pub fn signed_area2(t: &[Vec2; 3]) -> f32 {
    (t[1] - t[0]).perp_dot(t[2] - t[0])
}

/// Barycentric coordinates of `p` in the 2-D triangle `t` (not clamped).
#[inline]
pub fn barycentric(t: &[Vec2; 3], p: Vec2) -> [f32; 3] {
    let inv = 1.0 / signed_area2(t);
    let b0 = (t[1] - p).perp_dot(t[2] - p) * inv;
    let b1 = (t[2] - p).perp_dot(t[0] - p) * inv;
    [b0, b1, 1.0 - b0 - b1]
}

/// Whether two triangles' interiors overlap (separating axes, after
/// shrinking both slightly so that shared edges and corners do not count).
pub fn triangles_overlap(a: &[Vec2; 3], b: &[Vec2; 3]) -> bool {
    let shrink = |t: &[Vec2; 3]| {
        let c = (t[0] + t[1] + t[2]) / 3.0;
        t.map(|p| c + (p - c) * (1.0 - 1e-4))
    };
    let (a, b) = (shrink(a), shrink(b));
    for tri in [&a, &b] {
        for i in 0..3 {
            let axis = (tri[(i + 1) % 3] - tri[i]).perp();
            let project = |t: &[Vec2; 3]| {
                t.iter()
                    .map(|p| p.dot(axis))
                    .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), v| {
                        (lo.min(v), hi.max(v))
                    })
            };
            let (a0, a1) = project(&a);
            let (b0, b1) = project(&b);
            if a1 <= b0 || b1 <= a0 {
                return false;
            }
        }
    }
    true
}

/// A uniform-grid spatial hash of 2-D triangles.
pub struct TriangleHash {
    cell: f32,
    cells: HashMap<(i32, i32), Vec<u32>>,
    tris: Vec<[Vec2; 3]>,
    seen: Vec<u32>,
    stamp: u32,
}

impl TriangleHash {
    /// An empty hash with square cells of side `cell`.
    pub fn new(cell: f32) -> Self {
        Self {
            cell: if cell.is_finite() {
                cell.max(1e-12)
            } else {
                1.0
            },
            cells: HashMap::new(),
            tris: Vec::new(),
            seen: Vec::new(),
            stamp: 0,
        }
    }

    fn cell_range(&self, t: &[Vec2; 3]) -> (i32, i32, i32, i32) {
        let lo = t[0].min(t[1]).min(t[2]) / self.cell;
        let hi = t[0].max(t[1]).max(t[2]) / self.cell;
        (
            lo.x.floor() as i32,
            lo.y.floor() as i32,
            hi.x.floor() as i32,
            hi.y.floor() as i32,
        )
    }

    /// The side of a cell.
    pub fn cell(&self) -> f32 {
        self.cell
    }

    /// Whether `t` overlaps a triangle in the hash.
    pub fn overlaps(&mut self, t: &[Vec2; 3]) -> bool {
        let (x0, y0, x1, y1) = self.cell_range(t);
        // Triangles are at most a few cells across; a degenerate huge one is
        // refused rather than scanned.
        if (x1 as i64 - x0 as i64) * (y1 as i64 - y0 as i64) > 4096 {
            return true;
        }
        self.stamp += 1;
        for y in y0..=y1 {
            for x in x0..=x1 {
                let Some(list) = self.cells.get(&(x, y)) else {
                    continue;
                };
                for &i in list {
                    if self.seen[i as usize] == self.stamp {
                        continue;
                    }
                    self.seen[i as usize] = self.stamp;
                    if triangles_overlap(t, &self.tris[i as usize]) {
                        return true;
                    }
                }
            }
        }
        false
    }

    /// Adds `t`.
    pub fn insert(&mut self, t: [Vec2; 3]) {
        let i = self.tris.len() as u32;
        let (x0, y0, x1, y1) = self.cell_range(&t);
        if (x1 as i64 - x0 as i64) * (y1 as i64 - y0 as i64) <= 4096 {
            for y in y0..=y1 {
                for x in x0..=x1 {
                    self.cells.entry((x, y)).or_default().push(i);
                }
            }
        }
        self.tris.push(t);
        self.seen.push(0);
    }
}

/// The cells `(x0, y0, x1, y1)` (inclusive) of side `cell` that the
/// bounding box of `t` touches.
#[inline]
fn cells_of(cell: f32, t: &[Vec2; 3]) -> (i32, i32, i32, i32) {
    let lo = t[0].min(t[1]).min(t[2]) / cell;
    let hi = t[0].max(t[1]).max(t[2]) / cell;
    (
        lo.x.floor() as i32,
        lo.y.floor() as i32,
        hi.x.floor() as i32,
        hi.y.floor() as i32,
    )
}

/// Whether a cell range spans too many cells to be listed (a degenerate,
/// huge triangle): [`TriangleHash`] refuses such a query and never lists
/// such a triangle.
#[inline]
fn too_many_cells((x0, y0, x1, y1): (i32, i32, i32, i32)) -> bool {
    (x1 as i64 - x0 as i64) * (y1 as i64 - y0 as i64) > 4096
}

/// A [`TriangleHash`] built once over triangles held elsewhere (by index
/// into a caller's slice, e.g. a chart's corner coordinates): the same
/// cells and the same answers, in sorted arrays (about 30 bytes per
/// triangle instead of ~110 for a map of vectors and a copy of the
/// corners), so a whole mesh's worth of them fits beside the mesh.
pub struct FrozenTriangleGrid {
    cell: f32,
    /// Occupied cells `(y, x)`, sorted.
    keys: Vec<(i32, i32)>,
    /// CSR offsets into `items` per key.
    start: Vec<u32>,
    /// Triangle indices (into the caller's slice), per cell.
    items: Vec<u32>,
}

impl FrozenTriangleGrid {
    /// The grid of cells of side `cell` (as [`TriangleHash::new`]) over the
    /// triangles `ids` of `tris`.
    pub fn new(cell: f32, tris: &[[Vec2; 3]], ids: impl Iterator<Item = u32>) -> Self {
        let cell = if cell.is_finite() {
            cell.max(1e-12)
        } else {
            1.0
        };
        let mut pairs: Vec<((i32, i32), u32)> = Vec::new();
        for i in ids {
            let r = cells_of(cell, &tris[i as usize]);
            if too_many_cells(r) {
                continue;
            }
            for y in r.1..=r.3 {
                for x in r.0..=r.2 {
                    pairs.push(((y, x), i));
                }
            }
        }
        pairs.sort_unstable();
        let mut keys = Vec::new();
        let mut start = Vec::new();
        let mut items = Vec::with_capacity(pairs.len());
        for (k, i) in pairs {
            if keys.last() != Some(&k) {
                keys.push(k);
                start.push(items.len() as u32);
            }
            items.push(i);
        }
        start.push(items.len() as u32);
        keys.shrink_to_fit();
        start.shrink_to_fit();
        Self {
            cell,
            keys,
            start,
            items,
        }
    }

    /// The side of a cell.
    pub fn cell(&self) -> f32 {
        self.cell
    }

    /// Whether `t` overlaps one of the grid's triangles (`tris` the slice
    /// the grid was built over), as [`TriangleHash::overlaps`] answers.
    pub fn overlaps(&self, t: &[Vec2; 3], tris: &[[Vec2; 3]]) -> bool {
        let q = cells_of(self.cell, t);
        if too_many_cells(q) {
            return true;
        }
        for y in q.1..=q.3 {
            // The keys of row y from column q.0 on.
            let mut k = self.keys.partition_point(|&key| key < (y, q.0));
            while k < self.keys.len() && self.keys[k].0 == y && self.keys[k].1 <= q.2 {
                let x = self.keys[k].1;
                for &i in &self.items[self.start[k] as usize..self.start[k + 1] as usize] {
                    let other = &tris[i as usize];
                    // Test each triangle once: in the first cell its range
                    // shares with the query's.
                    let r = cells_of(self.cell, other);
                    if (x, y) != (r.0.max(q.0), r.1.max(q.1)) {
                        continue;
                    }
                    if triangles_overlap(t, other) {
                        return true;
                    }
                }
                k += 1;
            }
        }
        false
    }
}

/// Whether the triangles (those with `skip[i]` false) are all
/// counter-clockwise and pairwise disjoint.
pub fn flat_and_disjoint(tris: &[[Vec2; 3]], skip: &[bool], cell: f32) -> bool {
    let mut hash = TriangleHash::new(cell);
    for (t, &s) in tris.iter().zip(skip) {
        if s {
            continue;
        }
        let area = signed_area2(t);
        if area.is_nan() || area <= 0.0 || hash.overlaps(t) {
            return false;
        }
        hash.insert(*t);
    }
    true
}

/// Which face covers each texel centre of a `size × size` atlas
/// (`u32::MAX` for none; the first face in face order wins a shared edge).
pub fn rasterise_faces(corner_uvs: &[[Vec2; 3]], size: u32) -> Vec<u32> {
    let _span = tracing::debug_span!("rasterise_faces", size).entered();
    let s = size as usize;
    let mut id = vec![u32::MAX; s * s];
    for (f, uv) in corner_uvs.iter().enumerate() {
        let t = uv.map(|p| p * size as f32);
        if signed_area2(&t).abs() < 1e-12 || !t.iter().all(|p| p.is_finite()) {
            continue;
        }
        let lo = t[0].min(t[1]).min(t[2]);
        let hi = t[0].max(t[1]).max(t[2]);
        let (x0, y0) = (
            (lo.x - 0.5).ceil().max(0.0) as usize,
            (lo.y - 0.5).ceil().max(0.0) as usize,
        );
        let x1 = ((hi.x - 0.5).floor() as i64).min(s as i64 - 1);
        let y1 = ((hi.y - 0.5).floor() as i64).min(s as i64 - 1);
        for y in y0 as i64..=y1 {
            for x in x0 as i64..=x1 {
                let p = Vec2::new(x as f32 + 0.5, y as f32 + 0.5);
                let b = barycentric(&t, p);
                if b.iter().all(|&v| v >= -1e-5) {
                    let cell = &mut id[y as usize * s + x as usize];
                    if *cell == u32::MAX {
                        *cell = f as u32;
                    }
                }
            }
        }
    }
    id
}

/// Grows the filled texels of a `size × size` image with `channels` values
/// per texel outwards by `passes` texels: each pass, every unfilled texel
/// with filled 4-neighbours takes their mean. `filled` is updated. Rows are
/// read in parallel and only the new texels are stored between passes (no
/// copy of the image); the result does not depend on the thread count.
pub fn dilate(data: &mut [f32], channels: usize, size: u32, filled: &mut [bool], passes: u32) {
    let _span = tracing::debug_span!("dilate", passes).entered();
    let s = size as usize;
    let c = channels;
    for _ in 0..passes {
        let (src, mask) = (&*data, &*filled);
        // Per row: the texels this pass fills and their values, flat.
        let grown: Vec<(Vec<usize>, Vec<f32>)> = (0..s)
            .into_par_iter()
            .map(|y| {
                let (mut at, mut values) = (Vec::new(), Vec::new());
                let mut sum = vec![0.0f32; c];
                for x in 0..s {
                    if mask[y * s + x] {
                        continue;
                    }
                    sum.fill(0.0);
                    let mut n = 0.0f32;
                    for (dx, dy) in [(-1i64, 0i64), (1, 0), (0, -1), (0, 1)] {
                        let (nx, ny) = (x as i64 + dx, y as i64 + dy);
                        if nx < 0 || ny < 0 || nx >= s as i64 || ny >= s as i64 {
                            continue;
                        }
                        let j = ny as usize * s + nx as usize;
                        if mask[j] {
                            for (acc, v) in sum.iter_mut().zip(&src[c * j..c * j + c]) {
                                *acc += v;
                            }
                            n += 1.0;
                        }
                    }
                    if n > 0.0 {
                        at.push(y * s + x);
                        values.extend(sum.iter().map(|v| v / n));
                    }
                }
                (at, values)
            })
            .collect();
        if grown.iter().all(|r| r.0.is_empty()) {
            break;
        }
        for (at, values) in grown {
            for (&i, v) in at.iter().zip(values.chunks_exact(c.max(1))) {
                data[c * i..c * i + c].copy_from_slice(v);
                filled[i] = true;
            }
        }
    }
}
