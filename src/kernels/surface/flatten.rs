//! Flattening the surface patch around a point into a tangent frame, and the
//! interpolation stencil of a square template laid over it: the mesh
//! neighbourhood of Wei & Levoy 2001 §3.3 (Fig. 5), with the growth and
//! vertex-placement heuristic of Praun et al. 2000 §3.3 after Maillot et al.
//! 1993 §3.1.4.
//!
//! The template follows the convention of [`crate::kernels::surface::surface_sample`]:
//! point `(i, j)` (column `i`, row `j`, both in `0..size`) lies at the offset
//! `(i − size/2) · spacing` along `+s` and `(j − size/2) · spacing` along `−t`
//! from the patch origin, so `i` runs like image x and `j` like image y
//! (downwards); stencils are stored row-major, `j` then `i`.
//!
//! Flattening and resampling are split: [`flatten_stencil`] depends only on
//! geometry and the frame and records, for each template point, the three
//! vertices and barycentric weights of the flattened triangle containing it;
//! [`resample_stencil`] then reads any per-vertex signal through it. A
//! synthesis that changes colours but not geometry flattens each vertex once.

use std::cmp::Reverse;
use std::collections::BinaryHeap;

use glam::{Vec2, Vec3};

use crate::kernels::surface::frames::TangentFrame;
use crate::kernels::{ceil_i, floor_i};
use crate::mesh::PolyMesh;

/// "No triangle" in adjacency arrays, and "no vertex" in stencils.
pub const NONE: u32 = u32::MAX;

/// A fan-triangulated view of a [`PolyMesh`] with triangle adjacency: what
/// flattening walks over. Quads and larger polygons become fans, so their
/// diagonals are ordinary interior edges.
#[derive(Clone, Debug, Default)]
pub struct TriangleAdjacency {
    /// Vertex ids of each triangle, in the face's (counter-clockwise) order.
    pub tris: Vec<[u32; 3]>,
    /// The face each triangle came from.
    pub face_of: Vec<u32>,
    /// Per triangle, the triangle across edge `k` (from corner `k` to corner
    /// `k + 1`), or [`NONE`] on a boundary. On a non-manifold edge the
    /// triangles are paired in index order and any extra ones are left out.
    pub across: Vec<[u32; 3]>,
    /// CSR offsets into `vertex_tri_list`; `vertex_count + 1` entries.
    pub vertex_tri_start: Vec<u32>,
    /// The triangles around each vertex, in increasing order.
    pub vertex_tri_list: Vec<u32>,
}

impl TriangleAdjacency {
    /// Fan-triangulates `mesh` and links triangles across shared edges.
    /// O(corners · log corners).
    pub fn new(mesh: &PolyMesh) -> Self {
        let mut tris = Vec::with_capacity(mesh.corner_count());
        let mut face_of = Vec::with_capacity(mesh.corner_count());
        for (f, face) in mesh.faces().enumerate() {
            for k in 1..face.len() - 1 {
                tris.push([face[0], face[k], face[k + 1]]);
                face_of.push(f as u32);
            }
        }
        // Sides keyed by their undirected edge, then paired.
        let mut sides: Vec<(u64, u32)> = Vec::with_capacity(tris.len() * 3);
        for (t, tri) in tris.iter().enumerate() {
            for k in 0..3 {
                let (a, b) = (tri[k], tri[(k + 1) % 3]);
                sides.push((crate::mesh::edge_key(a, b), (t as u32) * 3 + k as u32));
            }
        }
        sides.sort_unstable();
        let mut across = vec![[NONE; 3]; tris.len()];
        let mut i = 0;
        while i < sides.len() {
            let mut j = i + 1;
            while j < sides.len() && sides[j].0 == sides[i].0 {
                j += 1;
            }
            if j - i >= 2 {
                let (s0, s1) = (sides[i].1, sides[i + 1].1);
                across[(s0 / 3) as usize][(s0 % 3) as usize] = s1 / 3;
                across[(s1 / 3) as usize][(s1 % 3) as usize] = s0 / 3;
            }
            i = j;
        }
        let nv = mesh.vertex_count();
        let mut vertex_tri_start = vec![0u32; nv + 1];
        for tri in &tris {
            for &v in tri {
                vertex_tri_start[v as usize + 1] += 1;
            }
        }
        for v in 0..nv {
            vertex_tri_start[v + 1] += vertex_tri_start[v];
        }
        let mut fill = vertex_tri_start.clone();
        let mut vertex_tri_list = vec![0u32; vertex_tri_start[nv] as usize];
        for (t, tri) in tris.iter().enumerate() {
            for &v in tri {
                // A degenerate triangle may name a vertex twice; list it once.
                let s = vertex_tri_start[v as usize] as usize;
                let f = fill[v as usize] as usize;
                if vertex_tri_list[s..f].last() != Some(&(t as u32)) {
                    vertex_tri_list[f] = t as u32;
                    fill[v as usize] += 1;
                }
            }
        }
        // Compact away the slots left by degenerate triangles.
        let mut out_start = vec![0u32; nv + 1];
        let mut out_list = Vec::with_capacity(vertex_tri_list.len());
        for v in 0..nv {
            let s = vertex_tri_start[v] as usize;
            out_list.extend_from_slice(&vertex_tri_list[s..fill[v] as usize]);
            out_start[v + 1] = out_list.len() as u32;
        }
        Self {
            tris,
            face_of,
            across,
            vertex_tri_start: out_start,
            vertex_tri_list: out_list,
        }
    }

    /// Number of triangles.
    #[inline]
    pub fn len(&self) -> usize {
        self.tris.len()
    }

    /// True when there are no triangles.
    #[inline]
    pub fn is_empty(&self) -> bool {
        self.tris.is_empty()
    }

    /// Triangles around vertex `v`.
    #[inline]
    pub fn vertex_tris(&self, v: u32) -> &[u32] {
        let v = v as usize;
        &self.vertex_tri_list
            [self.vertex_tri_start[v] as usize..self.vertex_tri_start[v + 1] as usize]
    }

    /// Mean triangle area over `positions` (0 without triangles): the `A` of
    /// Wei & Levoy's template spacing `d = √(2A)`.
    pub fn mean_triangle_area(&self, positions: &[Vec3]) -> f32 {
        mean_area(self.tris.iter().copied(), positions)
    }
}

/// The mean area of `mesh`'s fan triangles, exactly
/// [`TriangleAdjacency::mean_triangle_area`] of its adjacency (same
/// triangles, same order) without building the adjacency (about 200 bytes
/// per vertex at its peak, for one number).
pub fn mean_fan_triangle_area(mesh: &PolyMesh) -> f32 {
    let fans = mesh.faces().flat_map(|face| {
        (1..face.len().saturating_sub(1)).map(move |k| [face[0], face[k], face[k + 1]])
    });
    mean_area(fans, &mesh.positions)
}

/// Mean area of `tris` over `positions` (0 without triangles), summed in
/// order in f64.
fn mean_area(tris: impl Iterator<Item = [u32; 3]>, positions: &[Vec3]) -> f32 {
    let (mut sum, mut n) = (0.0f64, 0usize);
    for t in tris {
        let [a, b, c] = t.map(|v| positions[v as usize]);
        sum += 0.5 * (b - a).cross(c - a).length() as f64;
        n += 1;
    }
    if n == 0 { 0.0 } else { (sum / n as f64) as f32 }
}

/// Wei & Levoy's template spacing `d = √(2A)` for a mesh whose mean
/// (fan-)triangle area is `mean_area` (§3.3, footnote 1: on a regular grid of
/// squares split into triangles, `d` is the grid spacing).
#[inline]
pub fn template_spacing(mean_area: f32) -> f32 {
    (2.0 * mean_area).sqrt()
}

/// Where a patch starts.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum PatchSeed {
    /// At a vertex: the triangles around it are the seed triangles and the
    /// vertex is the template centre.
    Vertex(u32),
    /// At a point on a triangle (a parent face hit by a normal, §3.3): that
    /// triangle is the seed and the point is the template centre.
    Point {
        /// The seed triangle.
        tri: u32,
        /// The template centre, on (or near) the triangle.
        at: Vec3,
    },
}

/// A square template: `size`×`size` points `spacing` world units apart.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Template {
    /// Points per side (odd sizes have a centre point).
    pub size: u32,
    /// World units between neighbouring points.
    pub spacing: f32,
}

impl Template {
    /// Number of template points.
    #[inline]
    pub fn points(&self) -> usize {
        (self.size * self.size) as usize
    }

    /// Flattened-plane position of point `(i, j)`: x right (`+s`), y down (`−t`).
    #[inline]
    fn point(&self, i: usize, j: usize) -> Vec2 {
        let half = (self.size / 2) as f32;
        Vec2::new(
            (i as f32 - half) * self.spacing,
            (j as f32 - half) * self.spacing,
        )
    }
}

/// How one template point reads a per-vertex signal: the weighted sum of
/// three vertices, or nothing (uncovered: the default value).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StencilPoint {
    /// Vertex ids; `vertices[0] == NONE` when the point is uncovered.
    pub vertices: [u32; 3],
    /// Barycentric weights, summing to 1.
    pub weights: [f32; 3],
}

impl StencilPoint {
    /// The uncovered point.
    pub const UNCOVERED: Self = Self {
        vertices: [NONE; 3],
        weights: [0.0; 3],
    };

    /// Whether a triangle covers the point.
    #[inline]
    pub fn is_covered(&self) -> bool {
        self.vertices[0] != NONE
    }
}

/// What a flattening did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct FlattenReport {
    /// Template points covered by a flattened triangle.
    pub covered: usize,
    /// Triangles in the flattened patch.
    pub triangles: usize,
    /// Triangles refused because they flipped (growth stops there).
    pub flipped: usize,
}

/// Reusable buffers of [`flatten_stencil`], one per thread.
#[derive(Clone, Debug, Default)]
pub struct FlattenScratch {
    generation: u32,
    /// Per vertex: flattened position, valid when `vstamp == generation`.
    uv: Vec<Vec2>,
    vstamp: Vec<u32>,
    /// Per triangle: `generation` once queued, added or refused.
    tstamp: Vec<u32>,
    heap: BinaryHeap<Reverse<(u32, u32)>>,
}

impl FlattenScratch {
    /// Empty buffers; they grow on first use.
    pub fn new() -> Self {
        Self::default()
    }

    fn begin(&mut self, vertices: usize, tris: usize) {
        if self.vstamp.len() != vertices || self.tstamp.len() != tris {
            self.uv.clear();
            self.uv.resize(vertices, Vec2::ZERO);
            self.vstamp.clear();
            self.vstamp.resize(vertices, 0);
            self.tstamp.clear();
            self.tstamp.resize(tris, 0);
            self.generation = 0;
        }
        self.generation = self.generation.wrapping_add(1);
        if self.generation == 0 {
            self.vstamp.fill(0);
            self.tstamp.fill(0);
            self.generation = 1;
        }
        self.heap.clear();
    }
}

/// Scratches of [`flatten_stencil`] shared by the chunks of a parallel loop
/// ([`Pool`]).
pub type ScratchPool = Pool<FlattenScratch>;

/// Mesh-sized scratches shared by the tasks of a parallel loop: a task takes
/// one (or makes one when all are in use) and gives it back, so there are at
/// most as many as threads and each keeps its mesh-sized buffers from task
/// to task. A scratch per task (rayon's `map_init`, which makes one per
/// split) clears a mesh-sized buffer per task: on a million-vertex mesh
/// that was gigabytes of zeroing. Dropped with the pool.
#[derive(Debug)]
pub struct Pool<T>(std::sync::Mutex<Vec<T>>);

impl<T> Default for Pool<T> {
    fn default() -> Self {
        Self(std::sync::Mutex::new(Vec::new()))
    }
}

impl<T: Default> Pool<T> {
    /// An empty pool.
    pub fn new() -> Self {
        Self::default()
    }

    /// Runs `f` with a scratch of the pool.
    pub fn with<R>(&self, f: impl FnOnce(&mut T) -> R) -> R {
        let taken = self.0.lock().map(|mut p| p.pop()).unwrap_or_default();
        let mut scratch = taken.unwrap_or_default();
        let r = f(&mut scratch);
        if let Ok(mut p) = self.0.lock() {
            p.push(scratch);
        }
        r
    }
}

/// Tolerance on barycentric weights, so template points on shared edges and
/// vertices are found.
const INSIDE_EPS: f32 = 1e-5;

/// A triangle counts as flipped when its flattened signed area, relative to
/// its 3D area, is below this (it turned over or collapsed).
const FLIP_RATIO: f32 = 1e-3;

/// Flattens the patch around `seed` into `frame` and records in `out` how each
/// point of `template` interpolates the vertices (Wei & Levoy 2001 §3.3).
///
/// 1. The seed triangles (around the seed vertex, or the seed triangle) are
///    projected orthographically: vertex `x` goes to `((x−o)·s, −(x−o)·t)`,
///    `o` the seed vertex or point. Seed triangles that project flipped are
///    left out.
/// 2. The patch grows one triangle at a time across the edges of triangles
///    already in it, nearest first (3D distance from `o` to the triangle
///    centroid; ties by triangle id), and only across edges whose flattened
///    bounding box reaches the template square. A
///    triangle with one unplaced vertex places it by the heuristic of Maillot
///    et al. as Praun et al. §3.3 state it: every triangle around that vertex
///    with its other two vertices placed predicts it by unfolding a triangle
///    similar to its 3D shape across that edge, and the vertex takes the
///    centroid of the predictions.
/// 3. A triangle that would lie flipped (or collapsed) is refused and the
///    patch does not grow past it; the vertex it would have placed stays
///    unplaced. Growth ends when every template point is covered or no
///    triangle can be added.
///
/// Each template point takes the first added triangle containing it (up to a
/// small tolerance), so where a patch overlaps itself the nearer part wins.
/// Uncovered points get [`StencilPoint::UNCOVERED`].
///
/// Preconditions: `adjacency` was built for a mesh with these `positions`;
/// the seed names an existing vertex or triangle; `frame` is orthonormal;
/// `template.spacing > 0`; `out.len() == template.points()`.
pub fn flatten_stencil(
    adjacency: &TriangleAdjacency,
    positions: &[Vec3],
    seed: PatchSeed,
    frame: &TangentFrame,
    template: Template,
    out: &mut [StencilPoint],
    scratch: &mut FlattenScratch,
) -> FlattenReport {
    let n = template.size as usize;
    assert_eq!(out.len(), n * n, "stencil buffer size");
    out.fill(StencilPoint::UNCOVERED);
    scratch.begin(positions.len(), adjacency.len());
    let generation = scratch.generation;
    let mut report = FlattenReport::default();

    let origin = match seed {
        PatchSeed::Vertex(v) => positions[v as usize],
        PatchSeed::Point { at, .. } => at,
    };
    let half = (template.size / 2) as f32;
    // The template square, widened a little for rounding. Triangles that
    // meet a convex region are connected through edges that meet it, so
    // growing only across such edges still reaches every template point.
    let lo = -(half + 0.01) * template.spacing;
    let hi = ((n as f32 - 1.0 - half) + 0.01) * template.spacing;
    let project = |x: Vec3| -> Vec2 {
        let d = x - origin;
        Vec2::new(d.dot(frame.s), -d.dot(frame.t))
    };
    let key = |t: u32| -> u32 {
        let c = adjacency.tris[t as usize].map(|v| positions[v as usize]);
        let centroid = (c[0] + c[1] + c[2]) / 3.0;
        // Non-negative floats order like their bit patterns.
        (centroid - origin).length().to_bits()
    };

    let FlattenScratch {
        uv,
        vstamp,
        tstamp,
        heap,
        ..
    } = scratch;

    // Seed triangles, projected.
    let seeds: &[u32] = match &seed {
        PatchSeed::Vertex(v) => adjacency.vertex_tris(*v),
        PatchSeed::Point { tri, .. } => std::slice::from_ref(tri),
    };
    for &t in seeds {
        tstamp[t as usize] = generation;
        let tri = adjacency.tris[t as usize];
        let p = tri.map(|v| project(positions[v as usize]));
        if is_flipped(p, tri.map(|v| positions[v as usize])) {
            report.flipped += 1;
            continue;
        }
        for (k, &v) in tri.iter().enumerate() {
            if vstamp[v as usize] != generation {
                vstamp[v as usize] = generation;
                uv[v as usize] = p[k];
            }
        }
        let done = add_triangle(t, p, adjacency, template, out, &mut report);
        if done {
            return report;
        }
        push_neighbours(t, p, adjacency, tstamp, generation, heap, lo, hi, &key);
    }

    while let Some(Reverse((_, t))) = heap.pop() {
        let tri = adjacency.tris[t as usize];
        let placed: [bool; 3] = tri.map(|v| vstamp[v as usize] == generation);
        let unplaced = placed.iter().filter(|&&b| !b).count();
        let p = match unplaced {
            0 => tri.map(|v| uv[v as usize]),
            1 => {
                let k = placed.iter().position(|&b| !b).unwrap_or(0);
                let c = tri[k];
                let Some(pc) = predict_vertex(c, adjacency, positions, uv, vstamp, generation)
                else {
                    continue;
                };
                let mut p = tri.map(|v| uv[v as usize]);
                p[k] = pc;
                if is_flipped(p, tri.map(|v| positions[v as usize])) {
                    report.flipped += 1;
                    continue;
                }
                vstamp[c as usize] = generation;
                uv[c as usize] = pc;
                p
            }
            // Reached across an edge whose ends are placed: cannot happen.
            _ => continue,
        };
        if unplaced == 0 && is_flipped(p, tri.map(|v| positions[v as usize])) {
            report.flipped += 1;
            continue;
        }
        if add_triangle(t, p, adjacency, template, out, &mut report) {
            return report;
        }
        push_neighbours(t, p, adjacency, tstamp, generation, heap, lo, hi, &key);
    }
    report
}

/// Whether the flattened triangle `p` (of 3D corners `x`) is flipped or
/// collapsed. Counter-clockwise faces turn clockwise in (x right, y down)
/// coordinates, so a front face has negative signed area.
#[inline]
fn is_flipped(p: [Vec2; 3], x: [Vec3; 3]) -> bool {
    let area2 = (p[1] - p[0]).perp_dot(p[2] - p[0]);
    let area3 = (x[1] - x[0]).cross(x[2] - x[0]).length();
    // Written so that a NaN area counts as flipped.
    let front = -area2 > FLIP_RATIO * area3;
    !front || area3 == 0.0
}

/// The Maillot/Praun prediction of vertex `c`'s flattened position: the
/// centroid over the triangles around `c` whose two other vertices are placed
/// of the apex of a triangle similar to the 3D one, erected on the placed
/// edge on the side that keeps the triangle front-facing.
fn predict_vertex(
    c: u32,
    adjacency: &TriangleAdjacency,
    positions: &[Vec3],
    uv: &[Vec2],
    vstamp: &[u32],
    generation: u32,
) -> Option<Vec2> {
    let mut sum = Vec2::ZERO;
    let mut count = 0u32;
    for &t in adjacency.vertex_tris(c) {
        let tri = adjacency.tris[t as usize];
        let Some(k) = tri.iter().position(|&v| v == c) else {
            continue;
        };
        // Rotate so the face reads (a, b, c) counter-clockwise.
        let (a, b) = (tri[(k + 1) % 3], tri[(k + 2) % 3]);
        if a == c || b == c || vstamp[a as usize] != generation || vstamp[b as usize] != generation
        {
            continue;
        }
        let (pa, pb) = (uv[a as usize], uv[b as usize]);
        let (xa, xb, xc) = (
            positions[a as usize],
            positions[b as usize],
            positions[c as usize],
        );
        let e = xb - xa;
        let len3 = e.length();
        let len2 = (pb - pa).length();
        if len3 <= 0.0 || len2 <= 0.0 {
            continue;
        }
        let along = (xc - xa).dot(e) / len3;
        let off = ((xc - xa) - e * (along / len3)).length();
        let u = (pb - pa) / len2;
        // For (a, b, c) in order the signed area must be negative: the apex
        // lies on the side of −perp(u).
        let w = -u.perp();
        let scale = len2 / len3;
        sum += pa + (u * along + w * off) * scale;
        count += 1;
    }
    (count > 0).then(|| sum / count as f32)
}

/// Rasterises the flattened triangle `t` (corners `p`) into the uncovered
/// template points. Returns true once every point is covered.
fn add_triangle(
    t: u32,
    p: [Vec2; 3],
    adjacency: &TriangleAdjacency,
    template: Template,
    out: &mut [StencilPoint],
    report: &mut FlattenReport,
) -> bool {
    report.triangles += 1;
    let n = template.size as usize;
    let half = (template.size / 2) as f32;
    let to_index = |x: f32| x / template.spacing + half;
    let [a, b, c] = p;
    let mn = a.min(b).min(c);
    let mx = a.max(b).max(c);
    // Points a hair outside the bounding box may still pass the inside
    // tolerance; farther ones cannot.
    const SLACK: f32 = 1e-3;
    let last = n as i32 - 1;
    let i0 = ceil_i(to_index(mn.x) - SLACK).max(0);
    let i1 = floor_i(to_index(mx.x) + SLACK).min(last);
    let j0 = ceil_i(to_index(mn.y) - SLACK).max(0);
    let j1 = floor_i(to_index(mx.y) + SLACK).min(last);
    if i0 > i1 || j0 > j1 {
        return false;
    }
    let inv = 1.0 / (b - a).perp_dot(c - a);
    let verts = adjacency.tris[t as usize];
    for j in j0 as usize..=j1 as usize {
        for i in i0 as usize..=i1 as usize {
            let slot = &mut out[j * n + i];
            if slot.is_covered() {
                continue;
            }
            let q = template.point(i, j);
            let w1 = (q - a).perp_dot(c - a) * inv;
            let w2 = (b - a).perp_dot(q - a) * inv;
            let w0 = 1.0 - w1 - w2;
            if w0.min(w1).min(w2) < -INSIDE_EPS {
                continue;
            }
            *slot = StencilPoint {
                vertices: verts,
                weights: [w0, w1, w2],
            };
            report.covered += 1;
        }
    }
    report.covered == n * n
}

/// Queues the unvisited triangles across the edges of `t` whose flattened
/// bounding box reaches the template square `[lo, hi]²`.
#[allow(clippy::too_many_arguments)]
#[inline]
fn push_neighbours(
    t: u32,
    p: [Vec2; 3],
    adjacency: &TriangleAdjacency,
    tstamp: &mut [u32],
    generation: u32,
    heap: &mut BinaryHeap<Reverse<(u32, u32)>>,
    lo: f32,
    hi: f32,
    key: &impl Fn(u32) -> u32,
) {
    for k in 0..3 {
        let g = adjacency.across[t as usize][k];
        if g == NONE || tstamp[g as usize] == generation {
            continue;
        }
        let (e0, e1) = (p[k], p[(k + 1) % 3]);
        let (mn, mx) = (e0.min(e1), e0.max(e1));
        if mx.x < lo || mn.x > hi || mx.y < lo || mn.y > hi {
            continue;
        }
        tstamp[g as usize] = generation;
        heap.push(Reverse((key(g), g)));
    }
}

/// Reads a per-vertex signal through a stencil: template point `k` gets
/// `Σ weights · values[vertex]` (channels interleaved, `out[k·channels + c]`),
/// or `default` when uncovered.
///
/// Preconditions: `values.len()` is `channels` per vertex and covers every
/// stencil vertex; `default.len() == channels`;
/// `out.len() == stencil.len() · channels`.
#[inline]
pub fn resample_stencil(
    stencil: &[StencilPoint],
    values: &[f32],
    channels: usize,
    default: &[f32],
    out: &mut [f32],
) {
    debug_assert_eq!(out.len(), stencil.len() * channels);
    for (s, dst) in stencil.iter().zip(out.chunks_exact_mut(channels)) {
        if !s.is_covered() {
            dst.copy_from_slice(default);
            continue;
        }
        dst.fill(0.0);
        for k in 0..3 {
            let v = s.vertices[k] as usize;
            let w = s.weights[k];
            for (o, x) in dst
                .iter_mut()
                .zip(&values[v * channels..(v + 1) * channels])
            {
                *o += w * x;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::builtin::{BuiltinOptions, builtin_mesh};

    #[test]
    fn the_fan_mean_area_is_the_adjacencys_bit_for_bit() {
        // Triangles, a quad and a pentagon (fan-triangulated), and a sphere.
        let mut m = PolyMesh::new();
        m.positions = vec![
            Vec3::ZERO,
            Vec3::new(1.0, 0.1, 0.0),
            Vec3::new(1.3, 1.0, 0.2),
            Vec3::new(0.0, 1.2, 0.0),
            Vec3::new(-0.7, 0.5, 0.3),
        ];
        m.push_face(&[0, 1, 2]);
        m.push_face(&[0, 2, 3, 4]);
        m.push_face(&[0, 1, 2, 3, 4]);
        let sphere = builtin_mesh("icosphere", &BuiltinOptions::default()).unwrap();
        for mesh in [&m, &sphere] {
            let adj = TriangleAdjacency::new(mesh).mean_triangle_area(&mesh.positions);
            assert_eq!(mean_fan_triangle_area(mesh).to_bits(), adj.to_bits());
        }
        assert_eq!(mean_fan_triangle_area(&PolyMesh::new()), 0.0);
    }

    /// A planar grid with vertex `(x, y)` at `(x·h, −y·h, 0)` (rows run down
    /// like an image), counter-clockwise about +Z; quads or split triangles.
    fn grid(w: u32, h: u32, spacing: f32, quads: bool) -> PolyMesh {
        let positions = (0..h)
            .flat_map(|y| {
                (0..w).map(move |x| Vec3::new(x as f32 * spacing, -(y as f32) * spacing, 0.0))
            })
            .collect();
        let mut mesh = PolyMesh::from_polygons(positions, std::iter::empty::<&[u32]>());
        for y in 0..h - 1 {
            for x in 0..w - 1 {
                let v = y * w + x;
                let q = [v, v + w, v + w + 1, v + 1];
                if quads {
                    mesh.push_face(&q);
                } else {
                    mesh.push_face(&[q[0], q[1], q[2]]);
                    mesh.push_face(&[q[0], q[2], q[3]]);
                }
            }
        }
        mesh
    }

    fn frame() -> TangentFrame {
        TangentFrame::from_direction(Vec3::Z, Vec3::X)
    }

    #[test]
    fn footnote_1_template_aligns_with_grid_vertices() {
        for quads in [false, true] {
            let (w, h, step) = (15u32, 13u32, 0.37f32);
            let mesh = grid(w, h, step, quads);
            let adj = TriangleAdjacency::new(&mesh);
            let d = template_spacing(adj.mean_triangle_area(&mesh.positions));
            assert!((d - step).abs() < 1e-5, "d = √(2A) = {d}, grid step {step}");
            let values: Vec<f32> = (0..w * h)
                .flat_map(|v| [(v % w) as f32, (v / w) as f32 * 100.0])
                .collect();
            let template = Template {
                size: 7,
                spacing: d,
            };
            let mut st = vec![StencilPoint::UNCOVERED; 49];
            let mut scratch = FlattenScratch::new();
            let mut out = vec![0.0; 98];
            let (cx, cy) = (6u32, 5u32);
            let r = flatten_stencil(
                &adj,
                &mesh.positions,
                PatchSeed::Vertex(cy * w + cx),
                &frame(),
                template,
                &mut st,
                &mut scratch,
            );
            assert_eq!((r.covered, r.flipped), (49, 0), "quads {quads}");
            resample_stencil(&st, &values, 2, &[-1.0, -1.0], &mut out);
            for j in 0..7u32 {
                for i in 0..7u32 {
                    let k = ((j * 7 + i) * 2) as usize;
                    let (x, y) = (cx + i - 3, cy + j - 3);
                    assert!((out[k] - x as f32).abs() < 1e-4, "x at ({i}, {j})");
                    assert!(
                        (out[k + 1] - y as f32 * 100.0).abs() < 1e-2,
                        "y at ({i}, {j})"
                    );
                }
            }
        }
    }

    #[test]
    fn point_seed_centres_the_template_on_the_point() {
        let mesh = grid(9, 9, 1.0, false);
        let adj = TriangleAdjacency::new(&mesh);
        let values: Vec<f32> = mesh.positions.iter().flat_map(|p| [p.x, p.y]).collect();
        let at = Vec3::new(4.3, -3.6, 0.0);
        let tri = (0..adj.len() as u32)
            .find(|&t| {
                let [a, b, c] = adj.tris[t as usize].map(|v| mesh.positions[v as usize]);
                let inside = |p: Vec3, q: Vec3| (q - p).cross(at - p).z >= 0.0;
                inside(a, b) && inside(b, c) && inside(c, a)
            })
            .unwrap();
        let mut st = vec![StencilPoint::UNCOVERED; 9];
        let r = flatten_stencil(
            &adj,
            &mesh.positions,
            PatchSeed::Point { tri, at },
            &frame(),
            Template {
                size: 3,
                spacing: 0.5,
            },
            &mut st,
            &mut FlattenScratch::new(),
        );
        assert_eq!(r.covered, 9);
        let mut out = vec![0.0; 18];
        resample_stencil(&st, &values, 2, &[0.0, 0.0], &mut out);
        for j in 0..3 {
            for i in 0..3 {
                let k = (j * 3 + i) * 2;
                let expect = (at.x + (i as f32 - 1.0) * 0.5, at.y - (j as f32 - 1.0) * 0.5);
                assert!((out[k] - expect.0).abs() < 1e-5 && (out[k + 1] - expect.1).abs() < 1e-5);
            }
        }
    }

    #[test]
    fn unfolding_a_bent_sheet_preserves_lengths_across_the_fold() {
        // Fold the grid by 60° along x = 4: a template that reaches past the
        // fold must see the far part unrolled (lengths kept), not projected.
        let (w, h) = (12u32, 9u32);
        let mut mesh = grid(w, h, 1.0, false);
        let angle = 60f32.to_radians();
        for p in &mut mesh.positions {
            if p.x > 4.0 {
                let r = p.x - 4.0;
                *p = Vec3::new(4.0 + r * angle.cos(), p.y, r * angle.sin());
            }
        }
        let adj = TriangleAdjacency::new(&mesh);
        // The intrinsic x coordinate as the signal.
        let values: Vec<f32> = (0..w * h).map(|v| (v % w) as f32).collect();
        let mut st = vec![StencilPoint::UNCOVERED; 49];
        let c = 4 * w + 3;
        let r = flatten_stencil(
            &adj,
            &mesh.positions,
            PatchSeed::Vertex(c),
            &frame(),
            Template {
                size: 7,
                spacing: 1.0,
            },
            &mut st,
            &mut FlattenScratch::new(),
        );
        assert_eq!((r.covered, r.flipped), (49, 0));
        let mut out = vec![0.0; 49];
        resample_stencil(&st, &values, 1, &[-1.0], &mut out);
        for j in 0..7 {
            for i in 0..7 {
                // Template column i sits at intrinsic x = 3 + (i − 3) = i.
                let expect = i as f32;
                assert!(
                    (out[j * 7 + i] - expect).abs() < 1e-3,
                    "({i}, {j}): {} vs {expect}",
                    out[j * 7 + i]
                );
            }
        }
    }

    #[test]
    fn flipped_faces_stop_growth_and_leave_points_uncovered() {
        // Reverse every face: all seeds project flipped, nothing is covered.
        let mesh = grid(6, 6, 1.0, true);
        let reversed: Vec<Vec<u32>> = mesh
            .faces()
            .map(|f| f.iter().rev().copied().collect())
            .collect();
        let flipped =
            PolyMesh::from_polygons(mesh.positions.clone(), reversed.iter().map(|f| &f[..]));
        let adj = TriangleAdjacency::new(&flipped);
        let mut st = vec![StencilPoint::UNCOVERED; 9];
        let r = flatten_stencil(
            &adj,
            &flipped.positions,
            PatchSeed::Vertex(14),
            &frame(),
            Template {
                size: 3,
                spacing: 1.0,
            },
            &mut st,
            &mut FlattenScratch::new(),
        );
        assert_eq!(r.covered, 0);
        assert!(r.flipped > 0);
        let mut out = vec![0.0; 9];
        resample_stencil(&st, &[1.0; 36], 1, &[0.25], &mut out);
        assert!(out.iter().all(|&v| v == 0.25));
    }

    #[test]
    fn corner_vertex_covers_one_quadrant() {
        let mesh = grid(5, 5, 1.0, false);
        let adj = TriangleAdjacency::new(&mesh);
        let mut st = vec![StencilPoint::UNCOVERED; 25];
        let r = flatten_stencil(
            &adj,
            &mesh.positions,
            PatchSeed::Vertex(0),
            &frame(),
            Template {
                size: 5,
                spacing: 1.0,
            },
            &mut st,
            &mut FlattenScratch::new(),
        );
        assert_eq!(r.covered, 9);
        for j in 0..5 {
            for i in 0..5 {
                assert_eq!(st[j * 5 + i].is_covered(), i >= 2 && j >= 2, "({i}, {j})");
            }
        }
    }

    #[test]
    fn sphere_patches_are_fully_covered_and_close_to_projection() {
        let mesh = builtin_mesh(
            "icosphere",
            &BuiltinOptions {
                subdivisions: 4,
                ..Default::default()
            },
        )
        .unwrap();
        let adj = TriangleAdjacency::new(&mesh);
        let d = template_spacing(adj.mean_triangle_area(&mesh.positions));
        let normals = mesh.vertex_normals();
        let mut scratch = FlattenScratch::new();
        let mut st = vec![StencilPoint::UNCOVERED; 49];
        for v in (0..mesh.vertex_count() as u32).step_by(97) {
            let f = TangentFrame::from_direction(normals[v as usize], Vec3::Z);
            let r = flatten_stencil(
                &adj,
                &mesh.positions,
                PatchSeed::Vertex(v),
                &f,
                Template {
                    size: 7,
                    spacing: d,
                },
                &mut st,
                &mut scratch,
            );
            assert_eq!((r.covered, r.flipped), (49, 0), "vertex {v}");
            // The interpolated 3D point of template (i, j) lies about
            // (i−3)·d along s and (j−3)·d along −t from the vertex.
            let p0 = mesh.positions[v as usize];
            for j in 0..7 {
                for i in 0..7 {
                    let s = st[j * 7 + i];
                    let x: Vec3 = (0..3)
                        .map(|k| mesh.positions[s.vertices[k] as usize] * s.weights[k])
                        .sum();
                    let got = Vec2::new((x - p0).dot(f.s), -(x - p0).dot(f.t));
                    let want = Vec2::new((i as f32 - 3.0) * d, (j as f32 - 3.0) * d);
                    assert!(
                        (got - want).length() < 0.1 * d,
                        "{v} ({i},{j}) {got} {want}"
                    );
                }
            }
        }
    }
}
