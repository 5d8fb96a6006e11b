//! k-regions and their texture-space coordinates (Bangay & Morkel 2006
//! §3.3.1, Fig. 7) and the region size `k` from a size in texels (§3.3.2).

use crate::kernels::surface::frames::TangentFrame;
use crate::mesh::Topology;
use glam::{DVec2, Vec2, Vec3};
use rayon::prelude::*;

/// The real `k` whose diamond holds `side²` vertices: the positive root of
/// `(k + 1)² + k² = side²` (§3.3.2), i.e. `k = (√(2·side² − 1) − 1) / 2`.
/// `side` is the edge of the square in edge lengths; below `1/√2` there is
/// no real root and the result is 0.
pub fn k_for_side(side_in_edges: f32) -> f32 {
    let s2 = side_in_edges as f64 * side_in_edges as f64;
    let disc = 2.0 * s2 - 1.0;
    if disc.is_nan() || disc <= 1.0 {
        return 0.0;
    }
    ((disc.sqrt() - 1.0) / 2.0) as f32
}

/// The integer region size of Bangay & Morkel §3.3.2: `k` with
/// `(k + 1)² + k² = (aᵐ · n / (r_scale · ē))²`, rounded to the nearest
/// integer and clamped to `k_min..=k_max`.
///
/// * `side_texels` — `n`, the edge of the square neighbourhood in texels of
///   the matched image level;
/// * `level_factor` — `aᵐ`: 1 for a Gaussian stack, `2ᵐ` for level `m` of a
///   pyramid (one texel of level `m` spans `2ᵐ` texels of level 0);
/// * `r_scale` — texels (of level 0) per world unit;
/// * `mean_edge` — `ē`, the vertex's mean edge length in world units.
///
/// The paper writes `aᵐn / r_scale`, a length in world units; dividing by
/// the edge length `ē` turns it into the number of edges across the
/// square, which is what `k` counts (with Table 1's `r_scale = 30`,
/// `1/ē = 110` and a 3×3 neighbourhood this gives `k = 7`: 113 vertices,
/// in line with the 86 comparisons per vertex the table reports).
pub fn region_k(
    side_texels: f32,
    level_factor: f32,
    r_scale: f32,
    mean_edge: f32,
    k_min: u32,
    k_max: u32,
) -> u32 {
    let side = level_factor * side_texels / (r_scale * mean_edge);
    let k = k_for_side(side);
    let k = if k.is_finite() {
        k.round() as u32
    } else {
        k_max
    };
    k.clamp(k_min, k_max.max(k_min))
}

/// Mean length of the edges from each vertex to its one-ring (`ē` of
/// §3.3.4), world units; 0 for an isolated vertex.
pub fn mean_edge_lengths(positions: &[Vec3], topo: &Topology) -> Vec<f32> {
    (0..positions.len() as u32)
        .into_par_iter()
        .map(|v| {
            let nb = topo.neighbours(v);
            if nb.is_empty() {
                return 0.0;
            }
            let p = positions[v as usize];
            nb.iter()
                .map(|&w| (positions[w as usize] - p).length())
                .sum::<f32>()
                / nb.len() as f32
        })
        .collect()
}

/// A k-region around a centre vertex: the vertices at most `k` edges away
/// (Fig. 7), in breadth-first order (the centre first), with their
/// texture-space offsets from the centre.
#[derive(Clone, Debug, Default)]
pub struct KRegion {
    /// The `k` the region was grown to.
    pub k: u32,
    /// Vertex ids; `vertices[0]` is the centre.
    pub vertices: Vec<u32>,
    /// Edge distance of each vertex from the centre (0 for the centre).
    pub depth: Vec<u32>,
    /// Texel offset of each vertex from the centre (x right, y down; see
    /// [`TangentFrame::texel_offset`]), averaged over all shortest paths.
    pub offset: Vec<Vec2>,
    /// Mesh edges between region vertices, as pairs of positions in
    /// `vertices` (filled only when asked for).
    pub edges: Vec<[u32; 2]>,
}

impl KRegion {
    /// Number of vertices.
    pub fn len(&self) -> usize {
        self.vertices.len()
    }

    /// True when the region holds no vertex.
    pub fn is_empty(&self) -> bool {
        self.vertices.is_empty()
    }

    fn clear(&mut self) {
        self.vertices.clear();
        self.depth.clear();
        self.offset.clear();
        self.edges.clear();
    }
}

/// Reusable per-vertex buffers of [`k_region`], one per thread.
#[derive(Clone, Debug, Default)]
pub struct RegionScratch {
    stamp: Vec<u32>,
    local: Vec<u32>,
    generation: u32,
    paths: Vec<f64>,
    sum: Vec<DVec2>,
}

impl RegionScratch {
    /// Empty buffers; they grow on first use.
    pub fn new() -> Self {
        Self::default()
    }

    fn begin(&mut self, vertices: usize) {
        if self.stamp.len() != vertices {
            self.stamp.clear();
            self.stamp.resize(vertices, 0);
            self.local.resize(vertices, 0);
            self.generation = 0;
        }
        self.generation = self.generation.wrapping_add(1);
        if self.generation == 0 {
            self.stamp.fill(0);
            self.generation = 1;
        }
        self.paths.clear();
        self.sum.clear();
    }

    #[inline]
    fn local_of(&self, v: u32) -> Option<u32> {
        (self.stamp[v as usize] == self.generation).then(|| self.local[v as usize])
    }
}

/// The texel step from `a` to `b` seen in `a`'s tangent frame: the edge
/// projected onto `a`'s tangent plane, in `(s, −t)` pixel axes, stretched
/// back to the edge's 3D length (so the unfolding keeps edge lengths on
/// curved surfaces), times `px_per_unit`.
#[inline]
fn step(positions: &[Vec3], frames: &[TangentFrame], a: u32, b: u32, px_per_unit: f32) -> Vec2 {
    let d = positions[b as usize] - positions[a as usize];
    let f = &frames[a as usize];
    let flat = f.texel_offset(d, 1.0);
    let flat_len = flat.length();
    let len = d.length();
    if flat_len > 1e-6 * len.max(f32::MIN_POSITIVE) {
        flat * (len / flat_len * px_per_unit)
    } else {
        flat * px_per_unit
    }
}

/// Grows the `k`-region around `centre` (Bangay & Morkel 2006 §3.3.1) into
/// `out`, with each vertex's texture coordinates relative to the centre.
///
/// A neighbour's coordinates are its edge projected onto the centre's
/// tangent plane (§3.3.1); a vertex further away gets the sum of the steps
/// along a shortest edge path from the centre, each step seen in the frame
/// of the vertex it leaves ("calculated incrementally relative to each
/// successive vertex on a path"), averaged over *all* shortest paths. The
/// average is exact and linear in the region size: with `N(w)` the number
/// of shortest paths to `w` and `U(w)` their mean end point,
/// `N(w) = Σ N(p)` and `U(w) = Σ N(p)·(U(p) + step(p, w)) / N(w)` over the
/// neighbours `p` one layer closer. Each step keeps the edge's 3D length.
///
/// `px_per_unit` converts world units into texels of the matched level
/// (`r_scale / aᵐ`). With `with_edges`, [`KRegion::edges`] lists the mesh
/// edges between region vertices (the graph of §3.4).
///
/// On a regular quad grid (every vertex 4-connected) the region holds
/// `(k + 1)² + k²` vertices.
///
/// Preconditions: `topo` was built for the mesh of `positions`;
/// `frames.len() == positions.len()`; `centre` is a vertex.
#[allow(clippy::too_many_arguments)]
pub fn k_region(
    positions: &[Vec3],
    topo: &Topology,
    frames: &[TangentFrame],
    centre: u32,
    k: u32,
    px_per_unit: f32,
    with_edges: bool,
    scratch: &mut RegionScratch,
    out: &mut KRegion,
) {
    out.clear();
    out.k = k;
    scratch.begin(positions.len());
    let generation = scratch.generation;
    scratch.stamp[centre as usize] = generation;
    scratch.local[centre as usize] = 0;
    out.vertices.push(centre);
    out.depth.push(0);
    out.offset.push(Vec2::ZERO);
    scratch.paths.push(1.0);
    scratch.sum.push(DVec2::ZERO);
    let mut head = 0;
    while head < out.vertices.len() {
        let p = out.vertices[head];
        let dp = out.depth[head];
        // Every path to `p` comes from the previous layer, all of which was
        // expanded before `p`: its mean coordinate is final now.
        if head > 0 {
            let u = scratch.sum[head] / scratch.paths[head];
            out.offset[head] = u.as_vec2();
        }
        let up = out.offset[head];
        let np = scratch.paths[head];
        head += 1;
        if dp >= k {
            continue;
        }
        for &w in topo.neighbours(p) {
            let li = match scratch.local_of(w) {
                Some(li) => li as usize,
                None => {
                    let li = out.vertices.len();
                    scratch.stamp[w as usize] = generation;
                    scratch.local[w as usize] = li as u32;
                    out.vertices.push(w);
                    out.depth.push(dp + 1);
                    out.offset.push(Vec2::ZERO);
                    scratch.paths.push(0.0);
                    scratch.sum.push(DVec2::ZERO);
                    li
                }
            };
            if out.depth[li] == dp + 1 {
                let s = step(positions, frames, p, w, px_per_unit);
                scratch.paths[li] += np;
                scratch.sum[li] += (up + s).as_dvec2() * np;
            }
        }
    }
    if with_edges {
        for (a, &v) in out.vertices.iter().enumerate() {
            for &w in topo.neighbours(v) {
                if let Some(b) = scratch.local_of(w)
                    && (a as u32) < b
                {
                    out.edges.push([a as u32, b]);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::PolyMesh;

    fn grid(n: usize, spacing: f32) -> PolyMesh {
        let p = (0..n * n)
            .map(|i| Vec3::new((i % n) as f32, (i / n) as f32, 0.0) * spacing)
            .collect();
        let mut faces = Vec::new();
        for y in 0..n - 1 {
            for x in 0..n - 1 {
                let i = (y * n + x) as u32;
                faces.push([i, i + 1, i + n as u32 + 1, i + n as u32]);
            }
        }
        PolyMesh::from_polygons(p, faces.iter().map(|f| &f[..]))
    }

    #[test]
    fn k_solves_the_diamond_count() {
        for k in 0..10u32 {
            let side = (((k + 1) * (k + 1) + k * k) as f32).sqrt();
            assert!((k_for_side(side) - k as f32).abs() < 1e-4, "k = {k}");
        }
        // Table 1, donkey: r_scale 30, 1/ē = 110, 3×3 texels.
        assert_eq!(region_k(3.0, 1.0, 30.0, 1.0 / 110.0, 1, 32), 7);
    }

    #[test]
    fn offsets_on_a_flat_grid_are_exact() {
        let m = grid(9, 0.5);
        let t = Topology::build(&m);
        let frames = vec![TangentFrame::from_up(Vec3::Z, Vec3::Y); m.vertex_count()];
        let mut s = RegionScratch::new();
        let mut r = KRegion::default();
        let c = 4 * 9 + 4;
        k_region(&m.positions, &t, &frames, c, 3, 4.0, true, &mut s, &mut r);
        assert_eq!(r.len(), 25);
        for (i, &v) in r.vertices.iter().enumerate() {
            let d = m.positions[v as usize] - m.positions[c as usize];
            let want = Vec2::new(d.x, -d.y) * 4.0;
            assert!(
                (r.offset[i] - want).length() < 1e-4,
                "{v}: {:?}",
                r.offset[i]
            );
        }
        // Diamond of radius 3: 2·3·4 inner edges … count by brute force.
        let inside: std::collections::HashSet<u32> = r.vertices.iter().copied().collect();
        let brute = t
            .edges
            .iter()
            .filter(|e| inside.contains(&e[0]) && inside.contains(&e[1]))
            .count();
        assert_eq!(r.edges.len(), brute);
    }
}
